"""The one place arguments of nodes, annotations and specs are checked.

Built-in and third-party operators use the same checks, so every message has
the same shape: *where* (the node or annotation at fault), *what was expected*,
*what was given*, and a hint where one helps (see :class:`specguard.error.InvalidSpec`).
Each rule is one ``is_*`` predicate; its ``check_*`` raises that message, and
the doors read an option's text by the same predicate
(:mod:`specguard.utils.parsing`).

:func:`number_text` (from :mod:`specguard.utils.text`) is here too, the one way
an operator's ``describe()`` writes a number; node paths are built by
:mod:`specguard.utils.node_paths`.

Example:
    >>> from specguard.validation import check_weight, number_text
    >>> check_weight("All 'a', weight of 'b'", 2)
    2.0
    >>> number_text(0.1 + 0.2), number_text(1.0)
    ('0.30000000000000004', '1')
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Sequence
from numbers import Integral, Real
from typing import Any, TypeGuard

import numpy as np

from specguard.error import EvaluationError, InvalidSpec
from specguard.utils.node_paths import ANNOTATION_SEPARATOR, PATH_SEPARATOR
from specguard.utils.text import aside, elide, number_text

__all__ = [
    "check_budget",
    "check_callable",
    "check_choice",
    "check_count",
    "check_finite",
    "check_flag",
    "check_fraction",
    "check_name",
    "check_natural",
    "check_open_fraction",
    "check_positive",
    "check_text",
    "check_truth",
    "check_unique",
    "check_weight",
    "is_choice",
    "is_count",
    "is_finite",
    "is_fraction",
    "is_natural",
    "is_open_fraction",
    "is_positive",
    "number_text",
]


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


def is_count(value: object) -> TypeGuard[Integral]:
    """The one rule for a count: an integer ``>= 1``.

    numpy integers are integers; a bool is not a count (``True`` is no way to write 1).
    """
    return isinstance(value, Integral) and not isinstance(value, bool) and int(value) >= 1


def is_positive(value: object) -> TypeGuard[Real]:
    """The one rule for a positive number: a finite real ``> 0`` (numpy numbers too, never a bool)."""
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value) and float(value) > 0


def check_count(where: str, argument: str, value: object, meaning: str = "") -> int:
    """An integer ``>= 1`` (:func:`is_count`) as an ``int``; ``meaning`` says what it counts in the message.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the value given.
    """
    if not is_count(value):
        raise InvalidSpec(where, f"expected {argument} to be an integer >= 1{aside(meaning)}, got {value!r}")
    return int(value)


def check_positive(where: str, argument: str, value: object, meaning: str = "") -> float:
    """A finite number ``> 0`` (:func:`is_positive`) as a float; ``meaning`` says what it is for in the message.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the value given.
    """
    if not is_positive(value):
        raise InvalidSpec(
            where,
            f"expected {argument} to be a finite number > 0{aside(meaning)}, got {value!r}",
            hint=f"{argument} must be a positive finite number",
        )
    return float(value)


def is_natural(value: object) -> TypeGuard[Integral]:
    """The one rule for a count from zero (a seed, draws that may be none): an integer ``>= 0``, never a bool."""
    return isinstance(value, Integral) and not isinstance(value, bool) and int(value) >= 0


def check_natural(where: str, argument: str, value: object, meaning: str = "") -> int:
    """An integer ``>= 0`` (:func:`is_natural`) as an ``int``; ``meaning`` says what it counts in the message.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the value given.

    Example:
        >>> check_natural("Falsify", "seed", 0)
        0
        >>> check_natural("Falsify", "seed", -1)
        Traceback (most recent call last):
        ...
        specguard.error.InvalidSpec: Falsify: expected seed to be an integer >= 0, got -1...
    """
    if not is_natural(value):
        raise InvalidSpec(where, f"expected {argument} to be an integer >= 0{aside(meaning)}, got {value!r}")
    return int(value)


def is_open_fraction(value: object) -> TypeGuard[Real]:
    """The one rule for a level, a confidence or a rate: a real number strictly between 0 and 1 (never a bool)."""
    return isinstance(value, Real) and not isinstance(value, bool) and 0.0 < float(value) < 1.0


def check_open_fraction(where: str, argument: str, value: object, meaning: str = "") -> float:
    """A number in the open interval ``(0, 1)`` (:func:`is_open_fraction`) as a float.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the value given (``nan`` and the ends 0 and 1 included).

    Example:
        >>> check_open_fraction("Spec 'up'", "confidence", 0.95)
        0.95
        >>> check_open_fraction("Spec 'up'", "confidence", 1.0)
        Traceback (most recent call last):
        ...
        specguard.error.InvalidSpec: Spec 'up': expected confidence to be a number in (0, 1), got 1.0...
    """
    if not is_open_fraction(value):
        raise InvalidSpec(where, f"expected {argument} to be a number in (0, 1){aside(meaning)}, got {value!r}")
    return float(value)


def is_fraction(value: object) -> TypeGuard[Real]:
    """The one rule for a share that may be whole (a margin of rate points): a real number in ``(0, 1]``, never a
    bool."""
    return isinstance(value, Real) and not isinstance(value, bool) and 0.0 < float(value) <= 1.0


def check_fraction(where: str, argument: str, value: object, meaning: str = "") -> float:
    """A number in the half-open interval ``(0, 1]`` (:func:`is_fraction`) as a float.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the value given (``nan``, ``0`` and a string included).

    Example:
        >>> check_fraction("compare_agents", "margin", 1)
        1.0
        >>> check_fraction("compare_agents", "margin", "x")
        Traceback (most recent call last):
        ...
        specguard.error.InvalidSpec: compare_agents: expected margin to be a number in (0, 1], got 'x'...
    """
    if not is_fraction(value):
        raise InvalidSpec(where, f"expected {argument} to be a number in (0, 1]{aside(meaning)}, got {value!r}")
    return float(value)


def is_finite(value: object) -> TypeGuard[Real]:
    """The one rule for a bound: a finite real number (numpy numbers too), never a bool or a numeric string."""
    return isinstance(value, Real) and not isinstance(value, (bool, np.bool_)) and math.isfinite(value)


def check_finite(where: str, argument: str, value: object) -> float:
    """A finite real number (:func:`is_finite`) as a float; ``"0"`` and ``True`` are not numbers here.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the value given.
    """
    if not is_finite(value):
        raise InvalidSpec(where, f"expected {argument} to be a finite number, got {value!r}")
    return float(value)


def check_flag(where: str, argument: str, value: object) -> bool:
    """``True`` or ``False`` (a ``bool`` or ``numpy.bool_``): ``"no"`` would be true, and ``1`` reads as a count.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the value given.
    """
    if not isinstance(value, (bool, np.bool_)):
        raise InvalidSpec(where, f"expected {argument} to be True or False, got {value!r}")
    return bool(value)


def check_text(where: str, argument: str, value: object) -> str:
    """A non-empty (not blank) string, as a plain ``str``: a name of a variable, an option's key.

    Unlike :func:`check_name` it allows the path separators: it names no node.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the value given.
    """
    if not isinstance(value, str) or not value.strip():
        raise InvalidSpec(where, f"expected {argument} to be a non-empty string, got {value!r}")
    return str.__str__(value)


def check_folder(where: str, argument: str, value: object) -> str:
    """A folder to write into, made where it is missing (a TensorBoard folder): a path, as a plain ``str``, that
    holds no NUL, whose names fit the file system and whose existing part is folders.

    Raises:
        InvalidSpec: naming ``where``, ``argument`` and the path given (or the file it lies in).
    """
    if not isinstance(value, (str, os.PathLike)) or not isinstance(os.fspath(value), str) or not os.fspath(value):
        raise InvalidSpec(where, f"expected {argument} to be a folder, got {value!r}")
    path = str(os.fspath(value))
    if "\0" in path:
        raise InvalidSpec(where, f"expected {argument} to be a folder, got {path!r}, which holds a NUL character")
    existing = os.path.abspath(path)
    while not os.path.lexists(existing) and os.path.dirname(existing) != existing:
        existing = os.path.dirname(existing)
    if not os.path.isdir(existing):
        what = "is a file" if existing == os.path.abspath(path) else f"lies below the file {existing!r}"
        raise InvalidSpec(where, f"expected {argument} to be a folder, got {path!r}, which {what}")
    try:
        longest, name_max = os.pathconf(existing, "PC_PATH_MAX"), os.pathconf(existing, "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):  # not on Linux or macOS: the common limits
        longest, name_max = 4096, 255
    names = os.path.abspath(path).split(os.sep)
    too_long = next((n for n in names if len(os.fsencode(n)) > name_max), None)
    if too_long is not None or len(os.fsencode(os.path.abspath(path))) >= longest:
        part = f"a name over {name_max} bytes" if too_long is not None else f"over {longest} bytes"
        shown_path = elide(path, 60)
        raise InvalidSpec(where, f"expected {argument} to be a folder, got {shown_path!r}, which is too long ({part})")
    return path


def is_choice(value: object, choices: Sequence[str]) -> bool:
    """The one rule for a choice: a string among ``choices``, exactly as written there."""
    return isinstance(value, str) and value in choices


def check_choice(where: str, argument: str, value: object, choices: Sequence[str]) -> str:
    """``value`` if it is one of ``choices`` (:func:`is_choice`).

    Raises:
        InvalidSpec: naming ``where``, ``argument``, the choices and the value given.

    Example:
        >>> check_choice("Spec 'up'", "undecided", "xfail", ("fail", "xfail", "pass"))
        'xfail'
    """
    if not is_choice(value, choices):
        raise InvalidSpec(where, f"expected {argument} to be one of {', '.join(choices)}, got {value!r}")
    return str(value)


def check_unique(where: str, pairs: Iterable[tuple[str, Any]]) -> dict[str, Any]:
    """``pairs`` as a dict, each name given once: a repeated name would let its last value win in silence.

    Raises:
        InvalidSpec: naming ``where``, the repeated name and both of its values.

    Example:
        >>> check_unique("--starts", [("x", (0.0, 1.0)), ("v", (0.0, 1.0))])
        {'x': (0.0, 1.0), 'v': (0.0, 1.0)}
    """
    out: dict[str, Any] = {}
    for name, value in pairs:
        if name in out:
            raise InvalidSpec(
                where, f"{name!r} is given twice: {out[name]!r}, then {value!r}", hint="give each name once"
            )
        out[name] = value
    return out


def check_budget(where: str, budget: object) -> int:
    """An integer ``>= 1``: the violations allowed per episode."""
    return check_count(where, "budget", budget, "violations allowed per episode")


def check_callable(where: str, fn: object, signature: str) -> Callable[..., Any]:
    """``fn`` if it is callable; ``signature`` says how it will be called (``"fn(s, a)"``)."""
    if not callable(fn):
        raise InvalidSpec(where, f"expected fn to be callable as {signature}, got {fn!r}")
    return fn


def check_truth(where: str | None, value: object) -> bool:
    """A constraint function's result: ``True`` or ``False`` (a ``bool`` or ``numpy.bool_``), nothing else.

    ``None`` (a ``def`` that forgot to ``return``) would never count a
    violation, and a string would always count one: both are errors, as are
    ``0``/``1``, NaN and ``numpy.float64``. Both evaluators apply it to every
    step's result, so a bad value is the same error in either.

    Raises:
        EvaluationError: naming ``where`` (the constraint's key; ``None`` for a
            message without it, which the evaluator that called the
            constraint prefixes with the key) and the value returned.

    Example:
        >>> check_truth("pendulum:fast", False)
        False
        >>> check_truth("pendulum:fast", None)
        Traceback (most recent call last):
        ...
        specguard.error.EvaluationError: pendulum:fast: the constraint function returned None (NoneType)...
    """
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    prefix = "" if where is None else f"{where}: "
    raise EvaluationError(
        f"{prefix}the constraint function returned {value!r} ({type(value).__name__}); expected True or False "
        "(a bool or numpy.bool_)",
        hint="return the comparison itself, e.g. `return abs(s.x) > 1`; a def without return gives None",
    )
