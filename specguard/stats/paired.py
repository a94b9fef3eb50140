"""Gating one agent against another on paired episodes: an exact one-sided McNemar test of a drop in success.

Two given agents are each one policy: there are no training seeds, and the unit is the evaluation episode. Judged
with the same evaluation seed and episode count, the two agents play episode ``i`` from the same start
(:func:`specguard.engine.check_agent.check_agent`), so their outcomes come in pairs ``(old, new)``, and only the
*discordant* pairs tell them apart: ``b`` episodes the old agent met and the new one missed, ``c`` the other way.

**The statistic** (:func:`drop_p_value`): with no drop (the new agent's success probability at least the old's on
every start), each discordant pair is the old agent's win with probability at most 1/2, so ``b`` out of ``b + c`` is
at most ``Binomial(b + c, 1/2)``; the one-sided p-value is ``P(X >= b)`` (McNemar's exact test, McNemar 1947).

**The looks** (:func:`repeated_p_value`): the pairs are looked at after each of ``looks`` planned stages; each look's
p-value is held at ``level / looks`` (Bonferroni over the looks), so the smallest ``looks * p`` so far, capped at 1,
is a valid p-value however the looks stop, and a valid input to :mod:`specguard.stats.family`.

**Fine** (:func:`drop_upper_bound`): the drop ``(b - c) / n`` is at most the upper bound of ``b / n`` less the lower
bound of ``c / n`` (Clopper-Pearson, each one-sided at ``(1 + confidence) / 2``, Bonferroni over the two); a
comparison is *fine* once that bound is below the margin, as a seeds' comparison is
(:mod:`specguard.stats.sequential`).

Example:
    >>> discordant([True, True, False, True], [False, True, True, False])
    (2, 1)
    >>> round(drop_p_value(8, 0), 4), drop_p_value(0, 0)
    (0.0039, 1.0)
    >>> round(drop_upper_bound(0, 0, 20), 3)
    0.197
"""

from __future__ import annotations

from collections.abc import Sequence

from specguard.stats.intervals import success_interval
from specguard.stats.sequential import FUTILITY_CONFIDENCE
from specguard.validation import check_open_fraction

__all__ = ["TEST", "discordant", "drop_p_value", "drop_upper_bound", "repeated_p_value"]

TEST = "exact one-sided McNemar test on paired episodes"


def discordant(old: Sequence[bool], new: Sequence[bool]) -> tuple[int, int]:
    """``(b, c)``: the paired episodes only the old agent met, and only the new one met.

    Raises:
        ValueError: the two sequences differ in length.
    """
    if len(old) != len(new):
        raise ValueError(f"expected paired outcomes, got {len(old)} old and {len(new)} new episodes")
    b = sum(1 for o, w in zip(old, new) if o and not w)
    c = sum(1 for o, w in zip(old, new) if w and not o)
    return b, c


def drop_p_value(b: int, c: int) -> float:
    """The one-sided exact McNemar p-value of a drop: ``P(X >= b)``, ``X ~ Binomial(b + c, 1/2)``; 1 without
    discordant pairs.

    Raises:
        ValueError: a negative count.
    """
    if b < 0 or c < 0:
        raise ValueError(f"expected counts >= 0, got b={b}, c={c}")
    if b == 0:
        return 1.0
    from scipy.stats import binom

    return float(binom.sf(b - 1, b + c, 0.5))


def repeated_p_value(p_values: Sequence[float], looks: int) -> float:
    """The p-value of looks so far, of ``looks`` planned: the smallest ``looks * p``, capped at 1 (Bonferroni).

    Raises:
        ValueError: more looks taken than planned, or none planned.
    """
    if looks < 1 or len(p_values) > looks:
        raise ValueError(f"expected at most {looks} looks (and at least one planned), got {len(p_values)}")
    return min([1.0, *(looks * p for p in p_values)])


def drop_upper_bound(b: int, c: int, episodes: int, confidence: float = FUTILITY_CONFIDENCE) -> float:
    """The upper ``confidence`` bound on the drop in success, ``(b - c) / episodes`` on the rate scale.

    Raises:
        ValueError: counts out of range, or ``confidence`` outside (0, 1).
    """
    check_open_fraction("drop_upper_bound", "confidence", confidence)
    if b + c > episodes:
        raise ValueError(f"expected b + c <= episodes, got b={b}, c={c}, episodes={episodes}")
    # two-sided Clopper-Pearson at `confidence` gives each one-sided side at (1 + confidence) / 2
    return success_interval(b, episodes, confidence)[1] - success_interval(c, episodes, confidence)[0]
