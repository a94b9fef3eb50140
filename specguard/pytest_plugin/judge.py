"""Judging one goal (or safety rate) of a trained spec for a test item: outcome, message, figures.

Plain logic over :class:`specguard.engine.spec_result.SpecResult`, used by the pytest
plugin and unit-tested without pytest. A safety rate (key ``path:name``, see
:mod:`specguard.tree.keys`) is judged exactly as a goal is; its message and hint
speak of violations.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

from specguard.engine.spec_result import SpecResult
from specguard.spec.spec import Spec
from specguard.stats.sequential import GateState
from specguard.stats.verdicts import OUTCOME_VERBS, GoalOutcome, RunVerdict
from specguard.tree.keys import GOAL, SAFETY, kind, require_thresholds, resolve_goal
from specguard.utils.text import digests_text, interval_text, numerics_text

if TYPE_CHECKING:
    from specguard.gate.baseline import Baseline
    from specguard.gate.comparison import SpecGate
    from specguard.gate.saved_agent import SavedAgentGate

__all__ = ["GoalCheck", "check_item", "judge_goal", "with_thresholds"]


@dataclass
class GoalCheck:
    """One (spec, goal) item's figures and outcome; ``to_row()`` is plain data.

    Attributes:
        goal: the node path, or a safety key ``path:name``.
        outcome: passed, failed, or undecided (the goal failed only because
            runs stayed undecided: none missed, none crashed).
        success, successes: for a safety rate, the share and number of
            episodes without a violation.
        comparison: against the stored baseline, or a note that the baseline has no figures for it.
        kind: ``"goal"`` or ``"safety"``.
        gate: the comparison's figures (repeated p-values, state, seeds at each look, the seeds of
            each side, the level it was judged at), for the session's family-wise procedure.
        baseline_runs: ``[seed, successes, episodes]`` per run a saved baseline stores for this goal.
        agent_baseline: an agent item's entry a saved baseline stores for its test (the stored form of
            :class:`~specguard.gate.baseline.AgentEntry`).
        notes: the spec's facts about its evaluation episodes (:attr:`SpecResult.notes
            <specguard.engine.spec_result.SpecResult.notes>`), shown under the table as ``specguard run`` shows them.
        agent: the agent judged, for an agent trained elsewhere (:attr:`SpecResult.agent
            <specguard.engine.spec_result.SpecResult.agent>`): its episodes are one run that trained nothing.
    """

    group: str
    spec: str
    goal: str
    threshold: float
    outcome: GoalOutcome
    success: float
    interval: tuple[float, float]
    successes: int
    episodes: int
    runs_met: int
    runs: int
    required: int
    per_seed: list[dict[str, Any]]
    train_seconds: float
    cached: bool
    errors: dict[int, str] = field(default_factory=dict)
    hint: str | None = None
    comparison: str | None = None
    spec_key: str | None = None
    kind: str = GOAL
    gate: dict[str, Any] | None = None
    baseline_runs: list[list[int]] | None = None
    agent_baseline: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)
    agent: str | None = None

    @property
    def key(self) -> str:
        """The goal's identity across sessions, for stored baselines."""
        return f"{self.group}::{self.goal}"

    @property
    def runs_counts(self) -> list[tuple[int, int]]:
        return [(s["successes"], s["episodes"]) for s in self.per_seed]

    def junit_properties(self) -> list[tuple[str, Any]]:
        """The figures as ``(name, value)`` pairs for JUnit XML properties; ``stopped`` only where one of the
        trainer's callbacks stopped a run's training (``seed 0: stopped by <callback> at <steps> of <budget> steps``,
        one clause a seed); ``weights``, each run's weights digest (``seed 0: 3c61144ad8e8; seed 1: ...``, the first
        12 hex digits of :attr:`RunResult.weights_digest <specguard.training.result.RunResult>`), where any has one;
        ``numerics``, what the runs computed with (``portable numerics``)."""
        lo, hi = self.interval
        names = ("kind", "success", "threshold", "successes", "episodes", "runs_met", "runs", "train_seconds", "cached")
        properties = [(n, getattr(self, n)) for n in names] + [("interval", interval_text((lo, hi), digits=4))]
        stopped = [f"seed {s['seed']}: {s['stop_reason']}" for s in self.per_seed if s.get("stop_reason")]
        digests = digests_text((s["seed"], s.get("weights_digest")) for s in self.per_seed)
        computed = numerics_text(s.get("numerics") for s in self.per_seed)
        return (
            properties
            + ([("stopped", "; ".join(stopped))] if stopped else [])
            + ([("weights", digests)] if digests else [])
            + ([("numerics", computed)] if computed else [])
        )

    def message(self) -> str:
        verb = OUTCOME_VERBS[self.outcome]
        lo, hi = self.interval
        seeds = ", ".join(str(s["seed"]) for s in self.per_seed) or "none"
        safety = self.kind == SAFETY
        what = f"safety rate {self.goal!r}" if safety else f"goal {self.goal!r}"
        rate = "safe (no violation) in" if safety else "success"
        lines = [
            f"{what} of spec {self.spec!r} {verb} its threshold",
            f"  {rate} {self.success:.0%} ({self.successes}/{self.episodes}), interval {interval_text((lo, hi))}, "
            f"threshold >= {self.threshold:g}",
            f"  runs: {self.runs_met} of {self.runs} met ({self.required} required); seeds {seeds}",
            "  per seed: "
            + (
                ", ".join(f"seed {s['seed']}: {s['successes']}/{s['episodes']} ({s['verdict']})" for s in self.per_seed)
                or "-"
            ),
        ]
        lines += [f"  seed {seed} failed: {error}" for seed, error in self.errors.items()]
        lines += [f"  {note}" for note in self.notes]
        if self.hint:
            lines.append(f"  hint: {self.hint}")
        return "\n".join(lines)

    def to_row(self) -> dict[str, Any]:
        row = asdict(self)
        row["interval"] = list(self.interval)
        row["errors"] = {str(k): v for k, v in self.errors.items()}
        row["runs_counts"] = [list(r) for r in self.runs_counts]
        return row


def judge_goal(result: SpecResult, spec: Spec, path: str, group: str) -> GoalCheck:
    """The figures and outcome of goal (or safety key) ``path``, which must have a threshold in ``spec``."""
    verdict = result.goals[path]
    per_seed = [
        {
            "seed": r.seed,
            "successes": r.successes[path],
            "episodes": r.episodes,
            "verdict": v.value,
            "timesteps": r.timesteps,
            "met_early": r.met_early,
            "stop_reason": r.stop_reason,
            "weights_digest": r.weights_digest,
            "numerics": r.numerics,
            "train_seconds": r.train_seconds,
            "evaluated": sum(p.get("evaluation_episodes", 0) for p in r.curve) or r.episodes,
            **({"weights": r.weights} if r.weights else {}),
        }
        for r, v in zip(result.runs, verdict.runs)
    ]
    outcome = result.outcome(path)
    return GoalCheck(
        group=group,
        spec=spec.label,
        goal=path,
        threshold=verdict.threshold,
        outcome=outcome,
        success=verdict.success,
        interval=verdict.interval,
        successes=verdict.successes,
        episodes=verdict.episodes,
        runs_met=verdict.runs.count(RunVerdict.MET),
        runs=len(verdict.runs) + len(result.errors),
        required=verdict.required,
        per_seed=per_seed,
        train_seconds=sum(r.train_seconds for r in result.runs),
        cached=bool(result.cached) and all(result.cached.values()),
        errors=dict(result.errors),
        spec_key=result.spec_key,
        hint=result.hints.get(path),  # the judge's (specguard.engine.judging.hints): one hint at every door
        kind=kind(path),
        notes=list(result.notes),
        agent=result.agent,
    )


def with_thresholds(spec: Spec, expect: dict[Any, float] | None, goal: object) -> tuple[Spec, list[str]]:
    """The spec with a decorator's thresholds (if any) and the goal paths one item asserts.

    Raises:
        InvalidSpec: a goal the tree lacks, or nothing to check.
    """
    import dataclasses

    where = f"Spec {spec.label!r}"
    if expect:
        thresholds = {resolve_goal(spec.tree, g, where): t for g, t in expect.items()}
        xfail = {g: r for g, r in spec.xfail.items() if g in thresholds}  # the decorator's own xfail marks items
        spec = dataclasses.replace(spec, expect=thresholds, xfail=xfail)
    require_thresholds(where, spec.thresholds)
    return spec, [resolve_goal(spec.tree, goal, where)] if goal is not None else list(spec.thresholds)


def check_item(
    result: SpecResult,
    spec: Spec,
    paths: list[str],
    group: str,
    baseline: tuple[Baseline, str] | None = None,
    gate: SpecGate | None = None,
    agent_gate: SavedAgentGate | None = None,
) -> list[GoalCheck]:
    """Check the goals of one test item, failing a passing goal whose success dropped against ``baseline``.

    A goal or safety rate the baseline has no figures for (a baseline stored
    before it was asserted, or before safety rates were measured) is not
    compared; its ``comparison`` says so.

    Args:
        baseline: the stored baseline and its name.
        gate: the spec's comparisons with it (:func:`specguard.gate.comparison.compare_spec`, extra seeds
            included); without one, the spec's own runs are compared at one look, at the level of
            a family of the baseline's size.
        agent_gate: an agent item's comparison with the agent the baseline saved for its test
            (:func:`specguard.gate.saved_agent.compare_saved`), in place of ``gate``.
    """
    if baseline is not None and gate is None and agent_gate is None:
        gate = _one_look(result, spec, group, baseline[0])
    checks = []
    for path in paths:
        check = judge_goal(result, spec, path, group)
        if baseline is not None and agent_gate is not None:
            _compare_agent(check, agent_gate, baseline[1])
        elif baseline is not None and gate is not None:
            _compare(check, gate, *baseline)
        checks.append(check)
    return checks


def _compare(check: GoalCheck, gate: SpecGate, baseline: Baseline, name: str) -> None:
    """Judge one goal's comparison: its text and figures; a drop fails a goal that passed its threshold."""
    if check.key not in baseline.runs:
        check.comparison = f"not compared: baseline {name!r} has no figures for it"
        return
    if gate.unchanged:
        seeds = ", ".join(map(str, gate.seeds))
        check.comparison = f"unchanged: the same spec and runs as baseline {name!r} (seeds {seeds}); not compared"
        return
    look = gate.looks.get(check.goal)
    if look is None:  # no run to compare (every seed failed)
        check.comparison = "not compared: no run of this spec finished"
        return
    check.comparison = look.describe()
    if baseline.spec_changed(check.key, check.spec_key):
        check.comparison += f" (the spec changed since baseline {name!r})"
    check.gate = {
        "p_drop": look.p_drop,
        "p_rise": look.p_rise,
        "state": look.state.value,
        "looks": list(look.seeds),
        "baseline_seeds": look.baseline_seeds,
        "seeds": gate.seeds,
        "level": look.alpha,
        "before": look.before,
        "after": look.after,
    }
    if look.dropped and check.outcome is GoalOutcome.PASSED:
        check.outcome = GoalOutcome.FAILED
        rate = "safety rate" if check.kind == SAFETY else "success"
        check.hint = f"{rate} {check.comparison} against baseline {name!r}"


def _compare_agent(check: GoalCheck, gate: SavedAgentGate, name: str) -> None:
    """Judge one goal of an agent item against the saved agent: its text and figures; a drop fails a goal that
    passed its threshold, as a trained spec's does."""
    if gate.reason is not None:
        check.comparison = gate.reason
        return
    if check.goal not in gate.keys:
        check.comparison = f"not compared: baseline {name!r} has no figures for it"
        return
    check.comparison = gate.describe(check.goal)
    check.gate = gate.figures(check.goal)
    if gate.keys[check.goal].state is GateState.DROPPED and check.outcome is GoalOutcome.PASSED:
        check.outcome = GoalOutcome.FAILED
        rate = "safety rate" if check.kind == SAFETY else "success"
        check.hint = f"{rate} {check.comparison} against baseline {name!r}"


def _one_look(result: SpecResult, spec: Spec, group: str, baseline: Baseline) -> SpecGate:
    """The spec's comparisons at one look, on its own runs (nothing more is trained)."""
    from specguard.engine.spec_result import SpecResult as Empty
    from specguard.gate.comparison import compare_spec
    from specguard.stats.family import first_level
    from specguard.stats.sequential import DEFAULT_ALPHA

    keys = {path: f"{group}::{path}" for path in spec.thresholds}
    return compare_spec(
        spec,
        result,
        baseline,
        keys,
        level=first_level(DEFAULT_ALPHA, baseline.family),
        ceiling=len(result.runs),
        train=lambda seeds: Empty(spec=spec.label, runs=[], goals={}),
    )
