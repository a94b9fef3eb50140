"""Judging a spec's runs: each thresholded goal's quorum verdict, the notes on their evaluation episodes, what to
try where a goal did not pass, and how many more seeds could change a verdict.

The hints are one function, :func:`goal_hint`, for every door: the pytest item's failure (``pytest
--goal-specs``), the table of ``specguard run`` and ``specguard check``, a result's JSON, and ``specguard
reproduce``'s Markdown (:attr:`SpecResult.hints <specguard.engine.spec_result.SpecResult.hints>`). A sparse
goal never reached asks for a ``Distance``, subgoals that compete name the weaker one, runs left undecided say by
how much, a safety rate names its violations, and an agent trained elsewhere is told what its episodes show, not
how to train it.

Example:
    >>> import specguard as sg
    >>> from specguard.training.result import RunResult
    >>> spec = sg.Spec(sg.InitialEnv("Pendulum-v1", features=("x",)), sg.Goal("up", x=(0.9, 1.0)),
    ...                budget=sg.Budget(timesteps=64, min_seeds=1), expect=0.5)
    >>> run = RunResult(spec="up", seed=0, timesteps=64, episodes=30, successes={"up": 0}, train_seconds=1.0)
    >>> judged(spec, [run]).hints
    {'up': "sparse goal never reached in 1/1 seeds: consider a Distance annotation on 'up'"}
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from specguard.construction import cap
from specguard.engine.spec_result import GoalVerdict, SpecResult
from specguard.extend import SHAPING, Node, until_end
from specguard.spec.spec import Spec
from specguard.stats.intervals import quorum_verdict, run_verdict, success_interval
from specguard.stats.verdicts import GoalOutcome, QuorumVerdict, RunVerdict
from specguard.training.result import RunResult
from specguard.tree.keys import SAFETY, kind
from specguard.tree.nodes import keeps_to_horizon
from specguard.utils.node_paths import child_path
from specguard.utils.text import interval_text

__all__ = ["episode_notes", "goal_hint", "hints", "judge", "judged", "seeds_still_needed"]


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
    spec: Spec,
    runs: Sequence[RunResult],
    *,
    errors: Mapping[int, str] | None = None,
    ends_at_goal: bool | None = None,
    agent: str | None = None,
) -> SpecResult:
    """The result of ``spec`` over ``runs`` (and the seeds that crashed, ``errors``): verdicts, notes, words, hints.

    ``agent``: the name of the agent judged, for an agent trained elsewhere (its hints speak of its episodes).

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
    result = SpecResult(
        spec=spec.label,
        runs=runs,
        goals=judge(spec, runs, len(errors)),
        errors=errors,
        confidence=spec.confidence,
        undecided=spec.undecided,
        xfail=dict(spec.xfail),
        notes=episode_notes(spec.tree, runs, ends_at_goal=not spec.baseline if ends_at_goal is None else ends_at_goal),
        agent=agent,
        trained=spec,
    )
    result.hints = hints(spec, result)
    return result


def episode_notes(tree: Node | None, runs: Sequence[RunResult], *, ends_at_goal: bool = True) -> list[str]:
    """The facts about the evaluation episodes that every door shows beside the verdicts, one line each.

    First, each run whose training one of the trainer's callbacks stopped before its budget (``seed 0: training
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


def hints(spec: Spec, result: SpecResult) -> dict[str, str]:
    """:func:`goal_hint` of every thresholded goal and safety rate of ``result`` that did not pass, in its order."""
    out = {}
    for path in result.goals:
        if result.outcome(path) is not GoalOutcome.PASSED:
            hint = goal_hint(spec, path, result)
            if hint is not None:
                out[path] = hint
    return out


def _node(tree: Node, path: str) -> Node:
    return dict(tree.walk())[path]


def _undecided_hint(spec: Spec, path: str, result: SpecResult) -> str:
    """Why runs stayed undecided: each is judged alone, at the corrected confidence, by its own interval."""
    confidence, threshold = spec.verdict_confidence, spec.thresholds[path]
    undecided = [
        f"seed {r.seed} {interval_text(success_interval(r.successes[path], r.episodes, confidence))}"
        for r in result.runs
        if run_verdict(r.successes[path], r.episodes, threshold, confidence) is RunVerdict.UNDECIDED
    ]
    return (
        f"runs stayed undecided after {spec.budget.max_eval_episodes} evaluation episodes: each run is judged on "
        f"its own episodes at {confidence:.2%} confidence (the table's {spec.confidence:.0%}, corrected for "
        f"{spec.budget.looks} looks), and these intervals contain the threshold {threshold:g}: "
        f"{', '.join(undecided) or 'none'}; raise budget.max_eval_episodes, or ask for a threshold further from "
        "the measured rate"
    )


def _safety_hint(spec: Spec, key: str, result: SpecResult, verdicts: list[RunVerdict]) -> str | None:
    """What to try when a safety rate (``path:name``) missed its threshold."""
    runs = result.runs
    episodes = sum(r.episodes for r in runs)
    if not episodes:
        return None
    if RunVerdict.UNDECIDED in verdicts and RunVerdict.MISSED not in verdicts:
        return _undecided_hint(spec, key, result)
    unsafe = episodes - sum(r.successes[key] for r in runs)
    always = [r.seed for r in runs if r.successes[key] == 0]
    where = f"; in every episode of {len(always)}/{len(runs)} seeds" if always else ""
    return (
        f"{key!r} was violated in {unsafe / episodes:.0%} of evaluation episodes{where} "
        "(an episode with any violation counts as unsafe, whatever the annotation's budget): "
        "consider a larger weight for its penalty, or a larger training budget"
    )


def _agent_hint(spec: Spec, path: str, result: SpecResult, verdicts: list[RunVerdict]) -> str | None:
    """What an agent's (trained elsewhere) failing goal or safety rate shows of its behaviour: nothing of training."""
    episodes = sum(r.episodes for r in result.runs)
    if not episodes:
        return None
    who = f"agent {result.agent!r}"
    if RunVerdict.UNDECIDED in verdicts and RunVerdict.MISSED not in verdicts:
        return (
            f"{who}'s {episodes} evaluation episodes leave it undecided: their interval contains the threshold "
            f"{spec.thresholds[path]:g}; give it more episodes (max_episodes, --max-episodes), or ask for a "
            "threshold further from the measured rate"
        )
    met = sum(r.successes[path] for r in result.runs)
    if kind(path) == SAFETY:
        return f"{who} violated {path!r} in {episodes - met} of its {episodes} evaluation episodes"
    fell = sum(r.terminated for r in result.runs)
    if fell and keeps_to_horizon(spec.tree) and until_end(spec.tree):
        return (
            f"the env ended {fell} of {who}'s {episodes} evaluation episodes before the horizon (a fall, a crash), "
            "which a goal held until the end does not keep; where the env's termination is a good end, say so "
            "with sg.Always(..., until='termination')"
        )
    if not met:
        return f"{who} never ended an evaluation episode in {path!r} ({episodes} episodes)"
    node = _node(spec.tree, path)
    if node.children:
        kids = [child_path(path, c.name) for c in node.children]
        rates = {kid: sum(r.successes[kid] for r in result.runs) / episodes for kid in kids}
        worst = min(rates, key=rates.__getitem__)
        return f"{who} fell short on {worst!r}, met in {rates[worst]:.0%} of its episodes"
    return None


def goal_hint(spec: Spec, path: str, result: SpecResult) -> str | None:
    """What to try where goal (or safety key) ``path`` of ``result`` did not pass, or ``None`` where nothing is known
    to help; for an agent trained elsewhere (:attr:`SpecResult.agent`), what its episodes show of it.

    ``spec`` is the spec the result judged (its thresholds, tree and budget).
    """
    verdicts = result.goals[path].runs
    if result.agent is not None:  # trained elsewhere: its behaviour, not advice on training
        return _agent_hint(spec, path, result, verdicts)
    if kind(path) == SAFETY:
        return _safety_hint(spec, path, result, verdicts)
    runs = result.runs
    fell = sum(r.terminated for r in runs)
    horizon = keeps_to_horizon(spec.tree)
    if fell and horizon and until_end(spec.tree):
        episodes = sum(r.episodes for r in runs)
        share = "every" if fell == episodes else f"{fell} of {episodes}"
        return (
            f"the env ended {share} evaluation episode{'s' if 1 < fell < episodes else ''} before the "
            "horizon (a fall, a crash), which a goal held until the end does not keep: state the env's failure "
            "condition in the spec (a Constraint, a goal) so the agent learns to avoid it, or, where the env's "
            "termination is a good end, say so with sg.Always(..., until='termination')"
        )
    never = [r.seed for r in runs if r.successes[path] == 0]
    shaped = any(a.role == SHAPING for _, n in _node(spec.tree, path).walk() for a in n.annotations)
    if never:
        from specguard.construction.preflight import unreachable_reason

        # "Impossible" is refused before training; should a result from elsewhere (an old cache) get here,
        # no Distance can help: say why, instead of "never reached".
        impossible = unreachable_reason(spec.initial_env, spec.tree, path)
        if impossible is not None:
            return f"goal impossible, not just never reached: {impossible}"
    if never and not shaped:
        return (
            f"sparse goal never reached in {len(never)}/{len(runs)} seeds: consider a Distance annotation on {path!r}"
        )
    if never:
        return f"goal never reached in {len(never)}/{len(runs)} seeds: consider a larger budget or other weights"
    node = _node(spec.tree, path)
    episodes = sum(r.episodes for r in runs)
    if node.children and episodes:
        kids = [child_path(path, c.name) for c in node.children]
        rates = {kid: sum(r.successes[kid] for r in runs) / episodes for kid in kids}
        best, worst = max(rates, key=rates.__getitem__), min(rates, key=rates.__getitem__)
        if rates[best] - rates[worst] >= 0.3:
            return (
                f"subgoals compete: {best!r} is reached in {rates[best]:.0%} of episodes, {worst!r} in "
                f"{rates[worst]:.0%}; consider a Distance on {worst!r} or a larger weight for it"
            )
    if RunVerdict.UNDECIDED in verdicts:
        return _undecided_hint(spec, path, result)
    if any(r.hit_wall_clock for r in runs):
        return "training stopped at the budget's wall-clock cap in some seeds"
    return None
