"""The one place arguments of nodes and annotations are checked and numbers are written.

Built-in and third-party operators use the same checks, so every message has
the same shape: *where* (the node or annotation at fault), *what was expected*,
*what was given*, and a hint where one helps (see :class:`specguard.InvalidSpec`).

Example:
    >>> from specguard.validation import check_weight, number_text
    >>> check_weight("All 'a', weight of 'b'", 2)
    2.0
    >>> number_text(0.1 + 0.2), number_text(1.0)
    ('0.30000000000000004', '1')
"""

from __future__ import annotations

import math
from collections.abc import Callable
from numbers import Integral, Real
from typing import Any

from specguard.error import InvalidSpec

__all__ = [
    "ANNOTATION_SEPARATOR",
    "PATH_SEPARATOR",
    "check_budget",
    "check_callable",
    "check_name",
    "check_positive",
    "check_weight",
    "function_text",
    "number_text",
]

PATH_SEPARATOR = "/"
ANNOTATION_SEPARATOR = ":"


def check_name(kind: str, name: object) -> str:
    """``name`` as a plain ``str`` usable in node paths.

    A ``str`` subclass is converted, since it could override ``__repr__`` or
    ``__format__``; the separators of paths and annotation keys are refused.

    Raises:
        InvalidSpec: ``name`` is not a non-empty string, or contains ``/`` or ``:``.
    """
    if not isinstance(name, str) or not name.strip():
        raise InvalidSpec(f"{kind} {name!r}", f"expected a non-empty string as name, got {name!r}")
    name = str.__str__(name)
    for sep in (PATH_SEPARATOR, ANNOTATION_SEPARATOR):
        if sep in name:
            raise InvalidSpec(
                f"{kind} {name!r}",
                f"a name may not contain {sep!r}, which separates node paths",
                hint="use '_' or '-' inside names",
            )
    return name


def check_weight(where: str, weight: object) -> float | None:
    """``None`` (the default weight) or a finite number ``>= 0`` as a float."""
    if weight is None:
        return None
    if isinstance(weight, bool) or not isinstance(weight, Real):
        raise InvalidSpec(where, f"expected weight to be a number, got {weight!r}")
    value = float(weight)
    if not math.isfinite(value) or value < 0:
        raise InvalidSpec(where, f"expected a finite weight >= 0, got {weight!r}")
    return value


def check_positive(where: str, argument: str, value: object, meaning: str = "") -> float:
    """A finite number ``> 0`` as a float; ``meaning`` says what it is for in the message."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise InvalidSpec(where, f"expected {argument} to be a number, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise InvalidSpec(
            where,
            f"expected {argument} > 0{f' ({meaning})' if meaning else ''}, got {value!r}",
            hint=f"{argument} must be a positive finite number",
        )
    return float(value)


def parse_count(text: str | int, meaning: str = "") -> int:
    """An integer ``>= 1`` from an option's text; ``meaning`` says what it is for in the message.

    Raises:
        ValueError: anything else, saying what was expected.
    """
    try:
        value = int(str(text).strip())
    except ValueError:
        value = 0
    if value < 1 or str(text).strip() != str(value):
        raise ValueError(f"expected an integer >= 1{f' ({meaning})' if meaning else ''}, got {str(text)!r}")
    return value


def check_budget(where: str, budget: object) -> int:
    """An integer ``>= 1``: the violations allowed per episode."""
    if isinstance(budget, bool) or not isinstance(budget, Integral) or budget < 1:
        raise InvalidSpec(
            where, f"expected budget to be an integer >= 1 (violations allowed per episode), got {budget!r}"
        )
    return int(budget)


def check_callable(where: str, fn: object, signature: str) -> Callable[..., Any]:
    """``fn`` if it is callable; ``signature`` says how it will be called (``"fn(s, a)"``)."""
    if not callable(fn):
        raise InvalidSpec(where, f"expected fn to be callable as {signature}, got {fn!r}")
    return fn


def number_text(x: float) -> str:
    """A number written exactly: the shortest text that reads back as the same float.

    Whole numbers drop their ``.0``; infinities read ``inf``/``-inf``. Used by
    every description, so printing, formulas and fingerprints never round.
    """
    text = float.__repr__(float(x))
    return text[:-2] if text.endswith(".0") else text


def function_text(fn: Callable[..., Any]) -> str:
    """A user function's name as descriptions show it: its qualified name without ``<locals>.``.

    Never ``repr(fn)``, which holds a memory address.
    """
    name = getattr(fn, "__qualname__", None) or getattr(fn, "__name__", None)
    if not isinstance(name, str):
        name = type(fn).__qualname__  # a callable object: its class
    return name.rsplit("<locals>.", 1)[-1]
