"""Judging a spec's runs: each thresholded goal's quorum verdict, the notes on their evaluation episodes, and how
many more seeds could change a verdict."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from specguard.construction import cap
from specguard.engine.spec_result import GoalVerdict, SpecResult
from specguard.extend import Node, until_end
from specguard.spec.spec import Spec
from specguard.stats.intervals import quorum_verdict, run_verdict, success_interval
from specguard.stats.verdicts import QuorumVerdict, RunVerdict
from specguard.training.result import RunResult
from specguard.tree.nodes import keeps_to_horizon

__all__ = ["episode_notes", "judge", "judged", "seeds_still_needed"]


def judge(spec: Spec, runs: Sequence[RunResult], failed_seeds: int) -> dict[str, GoalVerdict]:
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


def judged(
    spec: Spec, runs: Sequence[RunResult], *, errors: Mapping[int, str] | None = None, ends_at_goal: bool | None = None
) -> SpecResult:
    """The result of ``spec`` over ``runs`` (and the seeds that crashed, ``errors``): verdicts, notes, words.

    What ``run_spec`` returns for the same runs, less what only a call knows (cache hits, time, the cache).

    Example:
        >>> import specguard as sg
        >>> from specguard.training.result import RunResult
        >>> spec = sg.Spec(sg.InitialEnv("Pendulum-v1", features=("x",)), sg.Goal("up", x=(0.9, 1.0)),
        ...                budget=sg.Budget(timesteps=64, min_seeds=1), expect=0.5, xfail=["up"])
        >>> run = RunResult(spec="up", seed=0, timesteps=64, episodes=30, successes={"up": 2}, train_seconds=1.0)
        >>> result = judged(spec, [run])
        >>> result.word("up"), result.status(), result.as_expected
        (<Word.XFAILED: 'xfailed'>, 'xfailed', True)
    """
    errors = dict(errors or {})
    runs = sorted(runs, key=lambda r: r.seed)
    return SpecResult(
        spec=spec.label,
        runs=runs,
        goals=judge(spec, runs, len(errors)),
        errors=errors,
        confidence=spec.confidence,
        undecided=spec.undecided,
        xfail=dict(spec.xfail),
        notes=episode_notes(spec.tree, runs, ends_at_goal=not spec.baseline if ends_at_goal is None else ends_at_goal),
        trained=spec,
    )


def episode_notes(tree: Node | None, runs: Sequence[RunResult], *, ends_at_goal: bool = True) -> list[str]:
    """The facts about the evaluation episodes that every door shows beside the verdicts, one line each.

    First, each run whose training one of the spec's callbacks stopped before its budget (``seed 0: training
    stopped by <callback> at <steps> of <budget> steps``, :attr:`RunResult.stop_reason
    <specguard.training.result.RunResult>`): its episodes are those of a policy trained that far. The episodes cut
    at specguard's step cap; where the root goal holds until the end, the episodes that started
    outside it (failed before the policy acted) and those the env ended by termination before their horizon
    (docs/semantics.md, "Goals that hold until the end"); for a reach goal, the episodes that started inside it
    (met before the policy acted where reaching the root goal ends the episode, ``ends_at_goal``: the constructed
    env's; in the baseline env, whose episodes are the initial env's own, a reach goal is judged at the last state
    like any episode's, docs/semantics.md, "One agent's statistics"). Without a ``tree``, the root is the runs' first
    key.
    """
    episodes = sum(r.episodes for r in runs)
    started = sum(r.started_in_goal for r in runs)
    root = tree.name if tree is not None else next((p for r in runs[:1] for p in r.successes), "?")
    lines = [f"seed {r.seed}: training {r.stop_reason}" for r in runs if r.stop_reason is not None]
    capped = sum(r.capped for r in runs)
    if capped:
        lines.append(
            f"{capped} of {episodes} evaluation episodes were cut at {cap.EPISODE_CAP} steps, specguard's cap "
            "for an env that declares no episode limit: give it the horizon you mean (max_episode_steps=N for "
            "an env id, a TimeLimit in a factory)"
        )
    if tree is None or not until_end(tree):
        if started:
            lines.append(
                f"{started} of {episodes} evaluation episodes started inside the root goal {root!r}: "
                + (
                    "met before the policy acted"
                    if ends_at_goal
                    else "the env does not end an episode there, so each was judged at its last state, as every "
                    "episode is"
                )
            )
        return lines
    if episodes - started:  # a goal that must hold from the first state on
        lines.append(
            f"{episodes - started} of {episodes} evaluation episodes started outside the root goal "
            f"{root!r}, which must hold until the end: failed before the policy acted"
        )
    terminated = sum(r.terminated for r in runs)
    if terminated:
        why = (
            "an Always goal does not keep such an episode unless until='termination'"
            if keeps_to_horizon(tree)
            else "until='termination' takes that as a good end: they were judged on their last state"
        )
        lines.append(
            f"{terminated} of {episodes} evaluation episodes were ended by termination before their horizon "
            f"(the env's: a fall, a crash): the root goal {root!r} holds until the end, and {why}"
        )
    return lines
