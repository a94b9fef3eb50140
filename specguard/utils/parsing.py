"""An option's text read by the argument rules: the one parser per rule, for every door.

The CLI's options, the pytest plugin's options and ini settings, and the
worker and checkpoint counts read each value here, by the rule a spec's
argument obeys (:func:`specguard.validation.is_count` and its kin), so ``"05"``
or ``"inf"`` is refused in the same words wherever it is typed. A parser
raises a plain ``ValueError`` saying what was expected; each door makes it its
own usage error (argparse's, ``pytest.UsageError``).

Example:
    >>> parse_count(" 4 "), parse_natural("0"), parse_positive("2e-3"), parse_choice("fail", ("fail", "pass"))
    (4, 0, 0.002, 'fail')
    >>> parse_count("05", "runs")
    Traceback (most recent call last):
    ...
    ValueError: expected an integer >= 1 (runs), got '05'
"""

from __future__ import annotations

import re
from collections.abc import Sequence

from specguard.utils.text import aside
from specguard.validation import is_choice, is_count, is_natural, is_positive

__all__ = ["parse_choice", "parse_count", "parse_natural", "parse_positive"]

_COUNT_TEXT = re.compile(r"[1-9][0-9]*")
"""How an option writes a count: ASCII digits without sign, separator or leading zero."""


def parse_count(text: object, meaning: str = "") -> int:
    """An integer ``>= 1`` (:func:`~specguard.validation.is_count`) from an option's text, or given as an integer.

    The text is decimal digits without sign, ``_`` or leading zero (``"05"``
    is refused, as a typo or an octal number would be); blanks around it are ignored.

    Raises:
        ValueError: anything else, saying what was expected; each door (an
            option of the CLI or of the pytest plugin) makes it its own usage error.
    """
    value = int(text.strip()) if isinstance(text, str) and _COUNT_TEXT.fullmatch(text.strip()) else text
    if not is_count(value):
        raise ValueError(f"expected an integer >= 1{aside(meaning)}, got {text!r}")
    return int(value)


def parse_positive(text: object, meaning: str = "") -> float:
    """A finite number ``> 0`` (:func:`~specguard.validation.is_positive`) from an option's text, or given as a number.

    Raises:
        ValueError: anything else (``inf`` and ``nan`` included), saying what
            was expected; each door makes it its own usage error.
    """
    value: object = text
    if isinstance(text, str):
        try:
            value = float(text)
        except ValueError:
            value = None
    if not is_positive(value):
        raise ValueError(f"expected a finite number > 0{aside(meaning)}, got {text!r}")
    return float(value)


def parse_natural(text: object, meaning: str = "") -> int:
    """An integer ``>= 0`` (:func:`~specguard.validation.is_natural`) from an option's text: ``0``, or a count
    (see :func:`parse_count`).

    Raises:
        ValueError: anything else, saying what was expected; each door makes it its own usage error.
    """
    value = 0 if isinstance(text, str) and text.strip() == "0" else text
    if isinstance(value, str) and _COUNT_TEXT.fullmatch(value.strip()):
        value = int(value.strip())
    if not is_natural(value):
        raise ValueError(f"expected an integer >= 0{aside(meaning)}, got {text!r}")
    return int(value)


def parse_choice(text: object, choices: Sequence[str]) -> str:
    """One of ``choices`` (:func:`~specguard.validation.is_choice`) from an option's text; blanks around it are
    ignored.

    Raises:
        ValueError: anything else, saying what was expected; each door makes it its own usage error.
    """
    value = text.strip() if isinstance(text, str) else text
    if not is_choice(value, choices):
        raise ValueError(f"expected one of {', '.join(choices)}, got {text!r}")
    return str(value)
