"""Judging a spec's runs: each thresholded goal's quorum verdict, and how many more seeds could change one."""

from __future__ import annotations

from specguard.engine.spec_result import GoalVerdict
from specguard.spec.spec import Spec
from specguard.stats.intervals import QuorumVerdict, RunVerdict, quorum_verdict, run_verdict, success_interval
from specguard.training.result import RunResult

__all__ = ["judge", "seeds_still_needed"]


def judge(spec: Spec, runs: list[RunResult], failed_seeds: int) -> dict[str, GoalVerdict]:
    """Each thresholded goal (and safety rate) of ``spec`` over ``runs``; a failed seed counts as a run that missed."""
    assert spec.budget.max_seeds is not None
    goals = {}
    for path, threshold in spec.thresholds.items():
        verdicts = [run_verdict(r.successes[path], r.episodes, threshold, spec.verdict_confidence) for r in runs]
        counted = verdicts + [RunVerdict.MISSED] * failed_seeds  # a run that crashed met nothing
        verdict = quorum_verdict(counted, spec.required_runs, spec.budget.max_seeds)
        k = sum(r.successes[path] for r in runs)
        n = sum(r.episodes for r in runs)
        goals[path] = GoalVerdict(
            path=path,
            threshold=threshold,
            required=spec.required_runs,
            runs=verdicts,
            verdict=verdict,
            successes=k,
            episodes=n,
            interval=success_interval(k, n, spec.confidence) if n else (0.0, 1.0),
        )
    return goals


def seeds_still_needed(spec: Spec, goals: dict[str, GoalVerdict], done: int) -> int:
    """How many more runs could still change an open verdict (0 when every goal is settled)."""
    assert spec.budget.max_seeds is not None
    open_goals = [g for g in goals.values() if g.verdict is QuorumVerdict.OPEN]
    if done < spec.budget.min_seeds:
        return spec.budget.min_seeds - done
    if not open_goals:
        return 0
    missing = max(g.required - g.runs.count(RunVerdict.MET) for g in open_goals)
    return min(missing, spec.budget.max_seeds - done)
