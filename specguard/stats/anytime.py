"""Anytime verdicts: judging a run at evaluation checkpoints while it trains.

A budget with ``checkpoints=C`` (``C > 1``) evaluates the policy after every
``C``-th of its training steps. At the first checkpoint where **every**
thresholded goal and safety rate is *met*, training stops: the budget is a
ceiling, not a fixed cost. A run whose goals are not all met trains its whole
budget and is evaluated as before, so specs expected to miss still get every
step they are given.

Looking more than once raises the chance of a false pass: a run whose true
success is exactly the threshold could be called met at any of the looks.
The correction (Bonferroni over the looks) keeps the single-look promise of
:mod:`specguard.stats.intervals`:

* the *looks* of a run are its ``C - 1`` interim checkpoints plus the stages
  of its final evaluation (``eval_episodes``, doubled while undecided, up to
  ``max_eval_episodes``: 30, 60, 120 by default), ``L = C - 1 + stages``;
* each look judges at confidence ``1 - (1 - confidence) / L`` instead of
  ``confidence``, so each one-sided error is at most ``(1 - confidence) / (2 L)``
  and, summed over the ``L`` looks (whatever their dependence), at most
  ``(1 - confidence) / 2``, the promise of one look.

The union bound holds for any policies between looks, so it covers runs whose
success drifts while they train; ``tests/test_anytime.py`` checks it by
simulating 10 000 runs at a success equal to the threshold.

An interim look evaluates ``eval_episodes`` episodes and stops as soon as
some goal can no longer reach the successes a pass needs (no evaluation is
spent on a look that cannot end training); it never extends.

Example:
    >>> looks(checkpoints=10, stages=3)
    12
    >>> round(look_confidence(0.95, 12), 5)
    0.99583
    >>> evaluation_stages(30, 120)
    [30, 60, 120]
    >>> checkpoint_steps(100_000, 4)
    [25000, 50000, 75000]
    >>> min_successes_to_meet(30, 0.8, 0.95)
    29
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping

from specguard.stats.intervals import run_verdict, success_interval
from specguard.stats.verdicts import RunVerdict

__all__ = [
    "DEFAULT_CHECKPOINTS",
    "EpisodeCounts",
    "checkpoint_steps",
    "evaluation_stages",
    "final_evaluation",
    "interim_look",
    "look_confidence",
    "looks",
    "met",
    "min_successes_to_meet",
    "parse_checkpoints",
]

DEFAULT_CHECKPOINTS = 10
"""The one default of every door (``run_spec``, ``specguard run``, ``pytest --goal-specs``): a run is judged at
every tenth of its budget and stops training once every threshold is met. A spec that wants another
judgment says so in its ``Budget(checkpoints=...)``; a door's option (``--checkpoints``,
``--goal-specs-checkpoints``) overrides it for one session, visibly."""

EpisodeCounts = Callable[[int, int], dict[str, int]]
"""``evaluate(start, count)``: the counts per key of episodes ``start .. start + count - 1``."""


def parse_checkpoints(text: str | int) -> int:
    """A checkpoint count from an option: an integer >= 1 (1 trains every run's whole budget).

    Raises:
        ValueError: anything else, saying what was expected.
    """
    from specguard.utils.parsing import parse_count

    return parse_count(text, "1: train every run's whole budget")


def evaluation_stages(eval_episodes: int, max_eval_episodes: int) -> list[int]:
    """Episodes evaluated after each stage of a final evaluation: doubled while undecided, up to the maximum."""
    stages = [eval_episodes]
    while stages[-1] < max_eval_episodes:
        stages.append(min(2 * stages[-1], max_eval_episodes))
    return stages


def looks(checkpoints: int, stages: int) -> int:
    """The looks of a run: its interim checkpoints plus the stages of its final evaluation."""
    return checkpoints - 1 + stages


def look_confidence(confidence: float, n_looks: int) -> float:
    """The confidence each of ``n_looks`` looks judges at, so that all of them together keep ``confidence``."""
    return 1.0 - (1.0 - confidence) / n_looks


def checkpoint_steps(timesteps: int, checkpoints: int) -> list[int]:
    """The training steps of the interim checkpoints: every ``checkpoints``-th of ``timesteps``, the end excluded."""
    return [math.ceil(k * timesteps / checkpoints) for k in range(1, checkpoints)]


@functools.lru_cache(maxsize=4096)
def min_successes_to_meet(episodes: int, threshold: float, confidence: float) -> int:
    """The fewest successes out of ``episodes`` whose interval lies at or above ``threshold``.

    ``episodes + 1`` when even every episode succeeding would not do.
    """
    lo, hi = 0, episodes + 1  # the interval's lower end grows with the successes: bisect
    while lo < hi:
        mid = (lo + hi) // 2
        if success_interval(mid, episodes, confidence)[0] >= threshold:
            hi = mid
        else:
            lo = mid + 1
    return lo


def met(counts: Mapping[str, int], episodes: int, thresholds: Mapping[str, float], confidence: float) -> bool:
    """Whether every threshold is met by ``counts`` out of ``episodes`` (at a look's ``confidence``)."""
    return all(
        run_verdict(counts.get(key, 0), episodes, t, confidence) is RunVerdict.MET for key, t in thresholds.items()
    )


def interim_look(
    evaluate: EpisodeCounts, episodes: int, thresholds: Mapping[str, float], confidence: float
) -> tuple[dict[str, int], int, bool]:
    """One checkpoint: evaluate up to ``episodes`` episodes, stopping once some goal cannot pass any more.

    Returns:
        The counts, the episodes evaluated and whether every threshold was met.
    """
    need = {key: min_successes_to_meet(episodes, t, confidence) for key, t in thresholds.items()}
    counts: dict[str, int] = {}
    for i in range(episodes):
        for key, k in evaluate(i, 1).items():
            counts[key] = counts.get(key, 0) + k
        left = episodes - i - 1
        if any(counts.get(key, 0) + left < n for key, n in need.items()):
            return counts, i + 1, False
    return counts, episodes, met(counts, episodes, thresholds, confidence)


def final_evaluation(
    evaluate: EpisodeCounts, stages: list[int], thresholds: Mapping[str, float], confidence: float
) -> tuple[dict[str, int], int]:
    """The end-of-training evaluation: stage after stage while some threshold is still undecided.

    Returns:
        The counts and the episodes evaluated.
    """
    counts: dict[str, int] = {}
    done = 0
    for total in stages:
        for key, k in evaluate(done, total - done).items():
            counts[key] = counts.get(key, 0) + k
        done = total
        if not any(
            run_verdict(counts.get(key, 0), done, t, confidence) is RunVerdict.UNDECIDED
            for key, t in thresholds.items()
        ):
            break
    return counts, done
