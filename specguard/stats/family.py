"""Family-wise control over a session's comparisons: Holm's step-down procedure.

A session compares every goal and safety rate the baseline has figures for:
``G`` comparisons, each with its repeated p-value
(:mod:`specguard.stats.sequential`). Tested each at 5% alone, 15 unchanged
goals raise at least one false alarm in up to 54% of sessions. Holm's
procedure (Holm 1979) keeps the chance of *any* false alarm at or below the
family-wise level ``alpha`` whatever the dependence between comparisons
(goals of one spec share their seeds): sort the p-values, ``p_(1) <= ... <=
p_(G)``; flag ``p_(i)`` while ``p_(j) <= alpha / (G - j + 1)`` for every
``j <= i``, and stop at the first that is not.

Its first step is Bonferroni's level ``alpha / G``, the level each comparison
is designed at while its seeds train (a comparison at or below it is flagged
by Holm whatever the others give); later steps can only flag more.

Example:
    >>> holm({"a": 0.001, "b": 0.02, "c": 0.04}, alpha=0.05)
    {'a': 1, 'b': 2, 'c': 3}
    >>> holm({"a": 0.001, "b": 0.04, "c": 0.03}, alpha=0.05)
    {'a': 1, 'b': None, 'c': None}
    >>> first_level(0.05, 15)
    0.0033333333333333335
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from specguard.validation import check_open_fraction

__all__ = ["PROCEDURE", "first_level", "holm", "holm_rejections", "procedure_text", "step_level"]

PROCEDURE = "Holm's step-down procedure"


def first_level(alpha: float, comparisons: int) -> float:
    """Holm's first step (Bonferroni's level): ``alpha / comparisons``.

    Raises:
        ValueError: no comparisons, or ``alpha`` outside (0, 1).
    """
    return step_level(alpha, comparisons, 1)


def step_level(alpha: float, comparisons: int, step: int) -> float:
    """The level of Holm's step ``step`` (1: the smallest p-value) over ``comparisons``: ``alpha / (G - step + 1)``.

    Raises:
        ValueError: no comparisons, a step outside ``1..comparisons``, or ``alpha`` outside (0, 1).
    """
    if comparisons < 1:
        raise ValueError(f"expected at least one comparison, got {comparisons}")
    if not 1 <= step <= comparisons:
        raise ValueError(f"expected a step in 1..{comparisons}, got {step}")
    check_open_fraction("step_level", "alpha", alpha, "the family-wise level")
    return alpha / (comparisons - step + 1)


def holm_rejections(p_values: np.ndarray, alpha: float) -> np.ndarray:
    """Which p-values Holm's procedure flags, for every family at once (last axis: the family's comparisons)."""
    p = np.asarray(p_values, dtype=float)
    size = p.shape[-1]
    first_level(alpha, size)
    order = np.argsort(p, axis=-1, kind="stable")
    ranked = np.take_along_axis(p, order, axis=-1)
    levels = np.array([step_level(alpha, size, step) for step in range(1, size + 1)])
    passed = np.cumprod(ranked <= levels, axis=-1).astype(bool)
    out = np.zeros_like(passed)
    np.put_along_axis(out, order, passed, axis=-1)
    return out


def holm(p_values: Mapping[str, float], alpha: float) -> dict[str, int | None]:
    """Per comparison, the step of Holm's procedure that flags it (1 is the smallest p-value), or None."""
    keys = list(p_values)
    if not keys:
        return {}
    flagged = holm_rejections(np.array([p_values[k] for k in keys]), alpha)
    ranks = np.argsort(np.argsort([p_values[k] for k in keys], kind="stable"), kind="stable")
    return {k: int(r) + 1 if f else None for k, f, r in zip(keys, flagged, ranks)}


def procedure_text(alpha: float, comparisons: int) -> str:
    """The procedure and its level in words, for a session's summary."""
    first_level(alpha, comparisons)
    return f"{PROCEDURE} over {comparisons} comparison{'s' if comparisons != 1 else ''} at family-wise {alpha:.0%}"
