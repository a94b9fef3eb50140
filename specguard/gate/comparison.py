"""Gating a spec against a stored baseline: extra seeds while a comparison is open, and the seeds a baseline stores.

Plain logic over a spec's result and a trainer (``train(seeds)``, e.g.
:func:`specguard.engine.run_spec.train_seeds`), used by the pytest plugin and by
``benchmarks/gate_real.py``:

* :func:`compare_spec` compares every goal and safety rate of a spec that the
  baseline has figures for, by :func:`specguard.stats.sequential.compare_seeds`.
  While one of them is *open* (neither a clear drop nor clearly within the
  margin), and none has dropped, it trains ``budget.min_seeds`` more seeds
  (cached seeds are reused) and looks again, up to the ceiling
  (:func:`gate_ceiling`). A spec whose identity and runs are the baseline's
  own (a pull request that left it alone: its runs come from the cache the
  baseline filled) is not compared and trains nothing.
* :func:`baseline_runs` gives a spec's runs up to the ceiling for
  ``--goal-specs-save``: a baseline stores more seeds than a pull request
  starts with, so that the pull request's few seeds meet a well-measured
  baseline.

Verdicts against thresholds are not touched: they stay those of the spec's
own seeds (:func:`specguard.engine.run_spec.run_spec`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

from specguard.engine.spec_result import SpecResult
from specguard.gate.baseline import Baseline
from specguard.spec.spec import Spec
from specguard.stats.sequential import DEFAULT_MARGIN, Design, GateState, Look, compare_seeds
from specguard.training.result import RunResult

__all__ = ["SpecGate", "Train", "baseline_runs", "compare_spec", "gate_ceiling"]

Train = Callable[[list[int]], SpecResult]
"""Train (or read from the cache) exactly these seeds of the spec."""


def gate_ceiling(spec: Spec, compare_seeds: int) -> int:
    """The most seeds a comparison trains, and a saved baseline stores, for ``spec``: ``compare_seeds``,
    or the spec's own ``budget.max_seeds`` where that is more."""
    assert spec.budget.max_seeds is not None
    return max(compare_seeds, spec.budget.max_seeds)


@dataclass
class SpecGate:
    """A spec's comparisons with a baseline.

    Attributes:
        looks: per compared path (goal or safety key), its comparison after the last look.
        runs: the runs compared, in the order they were trained: the spec's own, then the extra ones.
        errors: extra seeds whose training failed (they are left out of the comparison).
        unchanged: the spec's identity and runs are the baseline's own; nothing was compared.
    """

    looks: dict[str, Look]
    runs: list[RunResult]
    errors: dict[int, str] = field(default_factory=dict)
    unchanged: bool = False

    @property
    def seeds(self) -> list[int]:
        return [r.seed for r in self.runs]


def _counts(runs: Sequence[RunResult], path: str) -> list[tuple[int, int]]:
    return [(r.successes[path], r.episodes) for r in runs]


def _next_seed(runs: Sequence[RunResult], failed: Sequence[int]) -> int:
    return max([r.seed for r in runs] + list(failed) + [-1]) + 1


def compare_spec(
    spec: Spec,
    result: SpecResult,
    baseline: Baseline,
    keys: Mapping[str, str],
    *,
    level: float,
    ceiling: int,
    train: Train,
    margin: float = DEFAULT_MARGIN,
) -> SpecGate:
    """Compare the spec's paths with the baseline, training extra seeds while a comparison is open.

    Args:
        keys: per path of the spec, its key in the baseline (paths the baseline lacks are left out).
        level: each comparison's level (Holm's first step: the family-wise level over the baseline's comparisons).
        ceiling: the most seeds of the pull request (:func:`gate_ceiling`).
        train: trains given seeds of ``spec``.
    """
    paths = {path: key for path, key in keys.items() if key in baseline.runs}
    runs = sorted(result.runs, key=lambda r: r.seed)
    if not paths or not runs:
        return SpecGate({}, runs)
    own = {path: [(r.seed, r.successes[path], r.episodes) for r in runs] for path in paths}
    if all(baseline.same_runs(key, result.spec_key, own[path]) for path, key in paths.items()):
        return SpecGate({}, runs, unchanged=True)
    design = Design(
        alpha=level, baseline_seeds=1, first=len(runs), ceiling=ceiling, step=spec.budget.min_seeds, margin=margin
    )
    looks_at = [len(runs)]
    errors: dict[int, str] = {}
    while True:
        looks = {
            path: compare_seeds(baseline.runs[key], _counts(runs, path), design, looks_at)
            for path, key in paths.items()
        }
        states = {look.state for look in looks.values()}
        if GateState.DROPPED in states or GateState.OPEN not in states or len(runs) >= design.ceiling:
            return SpecGate(looks, runs, errors)
        start = _next_seed(runs, [*result.errors, *errors])
        extra = train(list(range(start, start + design.next_seeds(len(runs)) - len(runs))))
        errors.update(extra.errors)
        if not extra.runs:  # every extra seed failed: the comparison stays as it is
            return SpecGate(looks, runs, errors)
        runs = runs + sorted(extra.runs, key=lambda r: r.seed)
        looks_at.append(len(runs))


def baseline_runs(result: SpecResult, *, ceiling: int, train: Train, runs: Sequence[RunResult] = ()) -> SpecGate:
    """The runs a saved baseline stores for a spec: its own (or ``runs``, e.g. a comparison's), then more up to
    ``ceiling`` (one attempt per seed: a seed that fails is left out)."""
    have = sorted(runs or result.runs, key=lambda r: r.seed)
    missing = ceiling - len(have)
    if missing <= 0:
        return SpecGate({}, list(have))
    start = _next_seed(have, list(result.errors))
    extra = train(list(range(start, start + missing)))
    return SpecGate({}, [*have, *sorted(extra.runs, key=lambda r: r.seed)], dict(extra.errors))
