"""Success rates with confidence intervals, and the verdicts built on them.

A *run* (one training seed) is evaluated on ``n`` episodes, ``k`` of which end
in a goal. Its success rate gets a Clopper-Pearson ("exact") interval from
``scipy.stats.binomtest``; the run

* **meets** a threshold ``t`` when the whole interval lies at or above ``t``,
* **misses** it when the whole interval lies below ``t``,
* is **undecided** otherwise (more evaluation episodes narrow the interval).

False alarms: with confidence ``c`` the interval is two-sided, so a run whose
true success rate is exactly ``t`` is called *missed* with probability at most
``(1 - c) / 2`` (2.5% at the default 0.95), and a run whose true rate is below
``t`` is called *met* with at most that probability. Clopper-Pearson is
conservative: the actual rates are lower.

A spec's verdict counts runs against a quorum (:func:`quorum_verdict`), the
way the paper reports "6 of 10 runs". The verdicts' words, and every word
built on them, are :mod:`specguard.stats.verdicts`'s.

Example:
    >>> lo, hi = success_interval(28, 30)
    >>> round(lo, 3), round(hi, 3)
    (0.779, 0.992)
    >>> run_verdict(28, 30, threshold=0.7)
    <RunVerdict.MET: 'met'>
    >>> quorum_verdict([RunVerdict.MET, RunVerdict.MISSED], required=2, max_runs=2)
    <QuorumVerdict.FAILED: 'failed'>
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

from specguard.stats.verdicts import QuorumVerdict, RunVerdict
from specguard.validation import check_open_fraction

__all__ = [
    "failure_upper_bound",
    "quorum_verdict",
    "run_verdict",
    "success_interval",
]


def _check_counts(successes: int, episodes: int) -> None:
    if episodes < 1:
        raise ValueError(f"expected at least one episode, got episodes={episodes}")
    if not 0 <= successes <= episodes:
        raise ValueError(f"expected 0 <= successes <= episodes, got successes={successes}, episodes={episodes}")


@functools.lru_cache(maxsize=65536)
def success_interval(successes: int, episodes: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Clopper-Pearson interval of a success rate of ``successes`` out of ``episodes``.

    Cached: verdicts ask for the same few counts again and again (:mod:`specguard.stats.anytime`).

    Raises:
        ValueError: counts out of range, or ``confidence`` outside (0, 1).
    """
    _check_counts(successes, episodes)
    check_open_fraction("success_interval", "confidence", confidence)
    from scipy.stats import binomtest  # scipy.stats takes ~1 s to import: only when needed

    ci = binomtest(int(successes), int(episodes)).proportion_ci(confidence_level=confidence, method="exact")
    return float(ci.low), float(ci.high)


def failure_upper_bound(episodes: int, confidence: float = 0.95) -> float:
    """The most a failure rate can be, at ``confidence``, after ``episodes`` episodes without a failure.

    The one-sided exact binomial bound ``1 - (1 - confidence) ** (1 / episodes)``: the largest rate at which no failure
    in ``episodes`` episodes still has probability ``1 - confidence`` (about ``3 / episodes`` at 95%, the "rule of
    three"). What a result says of a goal that never failed, instead of a bare 100%.

    Raises:
        ValueError: ``episodes`` below 1, or ``confidence`` outside (0, 1).

    Example:
        >>> round(failure_upper_bound(30), 4), round(failure_upper_bound(300), 4)
        (0.095, 0.0099)
    """
    _check_counts(0, episodes)
    check_open_fraction("failure_upper_bound", "confidence", confidence)
    return float(1.0 - (1.0 - confidence) ** (1.0 / episodes))


def run_verdict(successes: int, episodes: int, threshold: float, confidence: float = 0.95) -> RunVerdict:
    """Whether one run's interval lies at or above ``threshold``, below it, or across it."""
    lo, hi = success_interval(successes, episodes, confidence)
    if lo >= threshold:
        return RunVerdict.MET
    if hi < threshold:
        return RunVerdict.MISSED
    return RunVerdict.UNDECIDED


def quorum_verdict(runs: Sequence[RunVerdict], required: int, max_runs: int) -> QuorumVerdict:
    """Count final run verdicts against a quorum of ``required`` out of at most ``max_runs``.

    Passed once ``required`` runs met the threshold; failed once so many runs
    did not (missed, or stayed undecided) that even ``max_runs`` runs cannot
    reach the quorum; open otherwise, which is when training another seed can
    still change the answer.
    """
    if not 1 <= required <= max_runs:
        raise ValueError(f"expected 1 <= required <= max_runs, got required={required}, max_runs={max_runs}")
    if len(runs) > max_runs:
        raise ValueError(f"got {len(runs)} runs, more than max_runs={max_runs}")
    met = sum(1 for r in runs if r is RunVerdict.MET)
    if met >= required:
        return QuorumVerdict.PASSED
    if len(runs) - met > max_runs - required:
        return QuorumVerdict.FAILED
    return QuorumVerdict.OPEN
