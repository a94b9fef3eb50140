"""Text every door writes the same way: numbers written exactly, user functions by name, plain and Markdown
tables, intervals, bounds, adapted weights.

Example:
    >>> number_text(0.1 + 0.2), number_text(1.0), number_text(float("-inf"))
    ('0.30000000000000004', '1', '-inf')
"""

from __future__ import annotations

import functools
import reprlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

__all__ = [
    "MAX_CELL",
    "MAX_SHOWN",
    "MAX_VALUE",
    "SHORT_DIGEST",
    "aside",
    "bounds_text",
    "digests_text",
    "elide",
    "function_text",
    "interval_text",
    "markdown_cell",
    "markdown_table",
    "number_text",
    "per_seed_text",
    "render_table",
    "shown",
    "value_text",
    "weights_text",
]


MAX_CELL = 60  # the widest a table cell is drawn, but in the last column (never padded)
MAX_VALUE = 200  # the most characters of a value read from a file that an error or warning quotes


def number_text(x: float) -> str:
    """A number written exactly: the shortest text that reads back as the same float.

    Whole numbers drop their ``.0``; infinities read ``inf``/``-inf``. Used by
    every description, so printing, formulas and fingerprints never round.
    """
    text = float.__repr__(float(x))
    return text[:-2] if text.endswith(".0") else text


def function_text(fn: Callable[..., Any]) -> str:
    """A user function's name as descriptions show it: its qualified name without ``<locals>.``.

    Never ``repr(fn)``, which holds a memory address. A ``functools.partial`` is named by the function it wraps.
    """
    while isinstance(fn, functools.partial):
        fn = fn.func
    name = getattr(fn, "__qualname__", None) or getattr(fn, "__name__", None)
    if not isinstance(name, str):
        name = type(fn).__qualname__  # a callable object: its class
    return name.rsplit("<locals>.", 1)[-1]


def aside(text: str) -> str:
    """``text`` as an aside to a message, `` (text)``; nothing for no text.

    Example:
        >>> f"expected an integer >= 1{aside('runs')}", f"expected an integer >= 1{aside('')}"
        ('expected an integer >= 1 (runs)', 'expected an integer >= 1')
    """
    return f" ({text})" if text else ""


def elide(text: str, width: int) -> str:
    """``text`` cut to ``width`` characters by an ellipsis in the middle, so both of its ends stay readable.

    Example:
        >>> elide("tests/specs/test_pendulum.py::test_swing_up", 24)
        'tests/specs/…st_swing_up'
    """
    if len(text) <= width:
        return text
    head = width // 2
    return text[:head] + "…" + text[len(text) - (width - 1 - head) :]


class _BoundedRepr(reprlib.Repr):
    """:mod:`reprlib`'s repr, never building a whole repr of a value read from a file: integers too."""

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel = 4
        self.maxtuple = self.maxlist = self.maxdict = self.maxset = self.maxfrozenset = 8
        self.maxstring = self.maxother = self.maxlong = MAX_VALUE

    def repr_int(self, x: int, level: int) -> str:
        if x.bit_length() > 4 * MAX_VALUE:  # its decimal text alone would be longer than any message quotes
            return f"<an integer of {x.bit_length()} bits>"
        return super().repr_int(x, level)


_REPR = _BoundedRepr()


def value_text(value: object, width: int = MAX_VALUE) -> str:
    """``repr(value)`` bounded, for a message: containers cut after 4 levels and 8 items, the text after ``width``.

    The whole repr is never built (a YAML document of nested aliases expands to a repr of gigabytes), and what is
    left is elided in the middle (:func:`elide`), so both ends stay readable.

    Example:
        >>> value_text([[[[[1]]]]]), value_text(list(range(100))), value_text("x" * 500, 12)
        ('[[[[[...]]]]]', '[0, 1, 2, 3, 4, 5, 6, 7, ...]', "'xxxxx…xxxx'")
    """
    return elide(_REPR.repr(value), width)


MAX_SHOWN = 120
"""The most characters of a user's value (or of an error's message) that a message shows."""


def shown(value: object) -> str:
    """:func:`value_text` at :data:`MAX_SHOWN` characters: a user's value or an error's message, bounded.

    Example:
        >>> shown("x" * 200)[:8], len(shown("x" * 200))
        ("'xxxxxxx", 120)
    """
    return value_text(value, MAX_SHOWN)


def render_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    """Left-aligned columns two spaces apart, a rule of dashes under the header, no trailing spaces.

    A cell longer than :data:`MAX_CELL` is elided in the middle (:func:`elide`),
    so one long spec key does not pad every line; the last column, which pads
    nothing, is written whole.

    Example:
        >>> print("\\n".join(render_table(["goal", "success"], [["pendulum", "91%"]])))
        goal      success
        --------  -------
        pendulum  91%
    """
    last = len(header) - 1
    cells = [[str(c) if i == last else elide(str(c), MAX_CELL) for i, c in enumerate(r)] for r in [header, *rows]]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        return "  ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip()

    return [line(cells[0]), "  ".join("-" * w for w in widths), *(line(r) for r in cells[1:])]


def weights_text(weights: Mapping[str, Sequence[float]]) -> str:
    """Adapted weights as read in a report: ``pendulum (0.71, 0.29)``, nodes separated by ``; ``.

    Example:
        >>> weights_text({"pendulum": [0.714285, 0.285714]})
        'pendulum (0.71, 0.29)'
    """
    return "; ".join(f"{path} ({', '.join(f'{w:.2f}' for w in ws)})" for path, ws in weights.items())


def per_seed_text(seeds: Iterable[tuple[int, Mapping[str, Sequence[float]]]]) -> str:
    """Each seed's adapted weights: ``seed 0 pendulum (0.71, 0.29), seed 1 ...`` (seeds without any left out).

    Example:
        >>> per_seed_text([(0, {"p": [0.75, 0.25]}), (1, {})])
        'seed 0 p (0.75, 0.25)'
    """
    return ", ".join(f"seed {seed} {weights_text(weights)}" for seed, weights in seeds if weights)


SHORT_DIGEST = 12
"""The hex digits of a digest a report shows (a run's weights digest): enough to tell two apart at a glance."""


def digests_text(seeds: Iterable[tuple[int, str | None]]) -> str:
    """Each seed's weights digest, its first :data:`SHORT_DIGEST` hex digits: ``seed 0: 3c61144ad8e8; seed 1: ...``
    (seeds without one left out).

    Example:
        >>> digests_text([(0, "3c61144ad8e8" + "0" * 52), (1, None)])
        'seed 0: 3c61144ad8e8'
    """
    return "; ".join(f"seed {seed}: {digest[:SHORT_DIGEST]}" for seed, digest in seeds if digest)


def numerics_text(numerics: Iterable[str | None]) -> str:
    """What runs computed with (:attr:`RunResult.numerics <specguard.training.result.RunResult>`), each kind once:
    ``"portable numerics"``; ``""`` where no run says.

    Example:
        >>> numerics_text(["portable", "portable", None]), numerics_text(["native (AVX512)", "portable"])
        ('portable numerics', 'native (AVX512), portable numerics')
    """
    kinds = sorted({n for n in numerics if n})
    return f"{', '.join(kinds)} numerics" if kinds else ""


def interval_text(interval: Sequence[float], digits: int = 2) -> str:
    """A confidence interval of a success rate: ``[0.88, 1.00]`` (``digits`` decimals, both ends alike).

    Example:
        >>> interval_text((0.8843, 1.0)), interval_text((0.8843, 1.0), digits=4)
        ('[0.88, 1.00]', '[0.8843, 1.0000]')
    """
    lo, hi = interval
    return f"[{lo:.{digits}f}, {hi:.{digits}f}]"


def bounds_text(lo: float, hi: float) -> str:
    """A feature's range or a box side as written in errors and ``specguard show``: ``[-1, 1]``, ``[-inf, 0.5]``.

    Example:
        >>> bounds_text(-1.0, float("inf"))
        '[-1, inf]'
    """
    return f"[{lo:g}, {hi:g}]"


def markdown_cell(text: object) -> str:
    r"""``text`` safe inside a Markdown table cell: ``\`` and ``|`` escaped, line breaks as spaces.

    Example:
        >>> print(markdown_cell("a|b\nc"))
        a\|b c
    """
    return " ".join(str(text).replace("\\", "\\\\").replace("|", "\\|").splitlines())


def markdown_table(header: Sequence[object], rows: Sequence[Sequence[object]]) -> list[str]:
    r"""A Markdown table, every cell through :func:`markdown_cell`.

    Example:
        >>> print("\n".join(markdown_table(["spec", "root"], [["w", "86% | 4/5"]])))
        | spec | root |
        |---|---|
        | w | 86% \| 4/5 |
    """
    lines = ["| " + " | ".join(markdown_cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(markdown_cell(c) for c in row) + " |" for row in rows]
