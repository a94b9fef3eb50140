"""What a spec's gate can see, with no training: thresholds judged at a few true successes, drops a comparison flags.

``specguard plan FILE[::SPEC]`` and ``pytest --goal-specs --goal-specs-plan``
print, per thresholded goal and safety rate of a spec:

* the chance that one run whose true success is ``p`` is judged *met*, for a
  few ``p`` around the threshold (:data:`OFFSETS`), and the chance that the
  goal passes its quorum (:func:`specguard.stats.power.chance_met`,
  :func:`~specguard.stats.power.chance_passed`): at the final evaluation, its
  stages and the spec's look-corrected confidence (interim checkpoints can only
  end a run earlier, as met, each at that confidence too);
* for a comparison with a baseline, the smallest drop flagged with 80% power
  at the spec's own seeds, and with the extra seeds a comparison may train
  (:func:`specguard.stats.power.min_detectable_drop`, the gate simulated):
  at the baseline's success and seed-to-seed spread when a baseline has
  figures for the goal, else at an assumed success (halfway from the
  threshold to 1) and spread (:data:`specguard.stats.power.DEFAULT_SPREAD`,
  or the given one), with the baseline a save stores.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from specguard.gate.comparison import gate_ceiling
from specguard.spec.spec import Spec
from specguard.stats.family import first_level
from specguard.stats.power import DEFAULT_SPREAD, chance_met, chance_passed, estimated_spread, min_detectable_drop
from specguard.stats.sequential import DEFAULT_ALPHA, DEFAULT_COMPARE_SEEDS, Design
from specguard.stats.verdicts import UNDECIDED_AS, Word

__all__ = ["OFFSETS", "VISIBLE_DROP", "GoalPlan", "SpecPlan", "plan_spec"]

OFFSETS = (-0.1, -0.05, 0.0, 0.05, 0.1, 0.15)
"""The true successes a plan judges a run at: the threshold plus these."""

VISIBLE_DROP = 0.2
"""A comparison that cannot flag a drop this large (rate points) with 80% power says so."""


@dataclass(frozen=True)
class GoalPlan:
    """What the gate can see of one goal (or safety rate).

    Attributes:
        met: per true success (the threshold plus each of :data:`OFFSETS` in [0, 1]), the chance one run is judged met.
        passed: per true success, the chance the goal passes its quorum.
        success, spread: the baseline's success and seed-to-seed spread the comparison figures assume.
        estimated: both come from a baseline's seeds (else assumed).
        at_start, with_extra: the smallest drop flagged with 80% power at the spec's own seeds, and with
            the extra seeds a comparison may train (None: not even a drop to 0).
    """

    path: str
    threshold: float
    met: dict[float, float]
    passed: dict[float, float]
    success: float
    spread: float
    estimated: bool
    at_start: float | None
    with_extra: float | None

    @property
    def blind(self) -> bool:
        """Whether even the extra seeds cannot flag a drop of :data:`VISIBLE_DROP` with 80% power."""
        return self.with_extra is None or self.with_extra > VISIBLE_DROP


@dataclass(frozen=True)
class SpecPlan:
    """A spec's plan: its goals, and the comparison's design (seeds of each side, the level of each comparison)."""

    label: str
    goals: list[GoalPlan]
    start: int
    ceiling: int
    baseline_seeds: dict[str, int]  # per path: the baseline's seeds (stored, or what a save stores)
    level: float
    family: int
    quorum: int
    runs: int
    stages: tuple[int, ...]
    confidence: float


def _successes(threshold: float) -> list[float]:
    """The threshold plus each of :data:`OFFSETS` that lies in [0, 1]."""
    return [round(threshold + d, 4) for d in OFFSETS if 0.0 <= threshold + d <= 1.0]


@functools.lru_cache(maxsize=512)
def _drop(
    success: float, spread: float, level: float, baseline: int, start: int, ceiling: int, step: int, n: int
) -> float | None:
    design = Design(alpha=level, baseline_seeds=baseline, first=start, ceiling=ceiling, step=step)
    return min_detectable_drop(success, spread, design, episodes=n)


def plan_spec(
    spec: Spec,
    *,
    family: int,
    compare_seeds: int = DEFAULT_COMPARE_SEEDS,
    spread: float = DEFAULT_SPREAD,
    baseline: Mapping[str, Sequence[tuple[int, int]]] | None = None,
    label: str | None = None,
) -> SpecPlan:
    """The plan of every thresholded goal and safety rate of ``spec``.

    Args:
        family: the comparisons in a session (each is judged at the family-wise 5% over them).
        compare_seeds: the session's ``--goal-specs-compare-seeds``.
        spread: the seed-to-seed spread assumed where the baseline has no figures.
        baseline: per path, the baseline's ``(successes, episodes)`` per seed, where one exists.
    """
    budget = spec.budget
    assert budget.max_seeds is not None
    ceiling = gate_ceiling(spec, compare_seeds)
    level = first_level(DEFAULT_ALPHA, family)
    stages = tuple(budget.evaluation_stages)
    goals, stored = [], {}
    for path, threshold in spec.thresholds.items():
        met = {
            p: chance_met(
                p,
                threshold=threshold,
                stages=stages,
                confidence=spec.verdict_confidence,
                undecided_met=UNDECIDED_AS[spec.undecided] is Word.PASSED,
            )
            for p in _successes(threshold)
        }
        passed = {p: chance_passed(m, required=spec.required_runs, runs=budget.max_seeds) for p, m in met.items()}
        runs = list((baseline or {}).get(path, ()))
        measured = estimated_spread(runs) if runs else None
        success = sum(k / n for k, n in runs) / len(runs) if runs else (1.0 + threshold) / 2
        seeds = len(runs) or ceiling
        stored[path] = seeds
        common = (round(success, 4), round(measured if measured is not None else spread, 4), level, seeds)
        goals.append(
            GoalPlan(
                path=path,
                threshold=threshold,
                met=met,
                passed=passed,
                success=success,
                spread=measured if measured is not None else spread,
                estimated=measured is not None,
                at_start=_drop(*common, budget.min_seeds, budget.min_seeds, budget.min_seeds, budget.eval_episodes),
                with_extra=_drop(*common, budget.min_seeds, ceiling, budget.min_seeds, budget.eval_episodes),
            )
        )
    return SpecPlan(
        label=label or spec.label,
        goals=goals,
        start=budget.min_seeds,
        ceiling=ceiling,
        baseline_seeds=stored,
        level=level,
        family=family,
        quorum=spec.required_runs,
        runs=budget.max_seeds,
        stages=stages,
        confidence=spec.verdict_confidence,
    )
