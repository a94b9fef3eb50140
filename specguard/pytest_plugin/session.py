"""A pytest session's goal-spec state: its options, the one result per spec, and where progress goes."""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from specguard.pytest_plugin.options import Options

if TYPE_CHECKING:
    from specguard.engine.ahead import TrainAhead
    from specguard.engine.check_agent import AgentCheck
    from specguard.engine.run_spec import RunOptions
    from specguard.engine.spec_result import SpecResult
    from specguard.gate.baseline import AgentEntry, Baseline
    from specguard.gate.comparison import SpecGate
    from specguard.gate.saved_agent import SavedAgentGate
    from specguard.parallel.executors import Executor
    from specguard.parallel.slots import SlotPool
    from specguard.spec.spec import Spec
    from specguard.training.progress import ProgressEvent

__all__ = [
    "GoalSpecSession",
    "agent_gate_of",
    "baseline_name",
    "close_ahead",
    "gate_of",
    "judge_agent",
    "run",
    "run_options",
    "saved_agent",
    "saved_runs",
    "scaled",
    "terminal_lines",
    "terminal_progress",
    "upcoming_specs",
]


@dataclasses.dataclass
class GoalSpecSession:
    """What a ``--goal-specs`` session keeps: options, the baseline compared with, the executor, results and report
    rows (named apart from pytest's own ``Session``, which holds it in its stash)."""

    options: Options
    baseline: Baseline | None = None
    executor: Executor | None = None  # made once per session
    memo: dict[str, SpecResult] = dataclasses.field(default_factory=dict)
    agents: dict[str, SpecResult] = dataclasses.field(default_factory=dict)  # group -> its AgentCheck's result
    agent_checks: dict[str, AgentCheck] = dataclasses.field(default_factory=dict)  # group -> it, agent loaded (GIFs)
    rows: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    counterexamples: list[dict[str, Any]] = dataclasses.field(default_factory=list)  # falsify items' runs
    specs: dict[str, Spec] = dataclasses.field(default_factory=dict)  # group -> its trained Spec, for report GIFs
    progress: Callable[[ProgressEvent], None] | None = None  # the run_spec sink: events to the terminal reporter
    gates: dict[str, SpecGate] = dataclasses.field(default_factory=dict)  # spec key -> its comparisons
    saved: dict[str, SpecGate] = dataclasses.field(default_factory=dict)  # spec key -> the runs a saved baseline stores
    goal_items: int = 0  # goal-spec items collected: a plan's family of comparisons when no baseline gives one
    agent_outcomes: dict[str, list[dict[str, int]]] = dataclasses.field(default_factory=dict)  # group -> episodes'
    agent_gates: dict[str, SavedAgentGate] = dataclasses.field(default_factory=dict)  # group -> vs the saved agent
    agent_entries: dict[str, AgentEntry | str] = dataclasses.field(default_factory=dict)  # group -> saved, or why not
    ran: set[str] = dataclasses.field(default_factory=set)  # the items that ran to their teardown (node ids)
    interrupted: str | None = None  # why the session stopped before its last item, as its reports say it
    upcoming: list[Spec] | None = None  # the specs its items will train, in order, to train ahead (None: none)
    pool: SlotPool | None = None  # the training slots, shared by the foreground and the runs trained ahead
    ahead: TrainAhead | None = None  # the runs trained ahead (specguard.engine.ahead), made at the first training


def run_options(state: GoalSpecSession) -> RunOptions:
    """How this session trains: its workers, cache, progress sink and executor, one value for every call."""
    from specguard.engine.run_spec import RunOptions
    from specguard.parallel.slots import PooledExecutor

    return RunOptions(
        workers=state.options.workers,
        cache_dir=state.options.cache_dir,
        progress=state.progress,
        executor=PooledExecutor(state.pool) if state.pool is not None else state.executor or "local",
        ahead=state.ahead,
    )


def upcoming_specs(state: GoalSpecSession, items: list[pytest.Item]) -> list[Spec]:
    """The specs ``items`` will train, in their order, as the session trains them (its options, the items'
    thresholds): those of ``sg.goal_specs``, known at collection (a ``@goal_spec`` function's spec is known only
    once it runs with its fixtures); an item a mark skips, or an agent's (nothing to train), is left out."""
    from _pytest.skipping import evaluate_skip_marks

    from specguard.pytest_plugin.declare import GOAL_FIXTURE, SpecItem
    from specguard.pytest_plugin.judge import with_thresholds
    from specguard.spec.spec import Spec

    specs: list[Spec] = []
    for item in items:
        callspec = getattr(item, "callspec", None)
        case = callspec.params.get(GOAL_FIXTURE) if callspec is not None else None
        if not isinstance(case, SpecItem) or not isinstance(item, pytest.Function):
            continue
        try:
            if evaluate_skip_marks(item) is not None:
                continue
            returned = item.obj(**{GOAL_FIXTURE: case})
            if isinstance(returned, Spec):
                specs.append(scaled(state, with_thresholds(returned, None, None)[0]))
        except Exception:  # the item says what is wrong when it runs
            continue
    return specs


def _start_ahead(state: GoalSpecSession) -> None:
    """At the session's first training: its slots, and the seeds of its upcoming specs queued behind the item."""
    if state.upcoming is None:
        return
    from specguard.cache.store import Cache
    from specguard.engine.ahead import TrainAhead
    from specguard.parallel.slots import SlotPool

    assert state.options.cache_dir is not None
    upcoming, state.upcoming = state.upcoming, None
    workers = state.options.workers
    state.pool = SlotPool(workers if isinstance(workers, int) else 1)
    state.ahead = TrainAhead(state.pool, Cache(Path(state.options.cache_dir)), say=state.progress)
    state.ahead.plan(upcoming)


def close_ahead(state: GoalSpecSession) -> None:
    """Stop what trains ahead, store what finished, and close the slots (the session's end, Ctrl-C)."""
    ahead, pool = state.ahead, state.pool
    state.ahead, state.pool = None, None
    try:
        if ahead is not None:
            ahead.close()
    finally:
        if pool is not None:
            pool.close()


def scaled(state: GoalSpecSession, spec: Spec) -> Spec:
    """The spec as this session trains and judges it: the session's options applied, the spec's own where unset."""
    options = state.options
    return spec.as_run(
        options.budget_scale,
        checkpoints=options.checkpoints,
        undecided=options.undecided,
        tensorboard_log=options.tensorboard_log,
        numerics=options.numerics,
    )


def terminal_progress(config: pytest.Config, every: float = 60.0) -> Callable[[Any], None]:
    """The progress sink of a session: events as lines through pytest's terminal reporter.

    Not captured (no ``-s`` needed), each on a line of its own. On a terminal,
    every event (a line per tenth of each seed's budget, and a worker's line at least every
    minute); in a log (not a tty, or no markup), the line that ends each seed's run, and
    another event's once ``every`` seconds passed since the last line shown (a CI log is
    never silent for long; ``--goal-specs-progress-every``, 0: none); under ``-q``, none.
    """
    shown = [time.monotonic()]

    def write(event: Any) -> None:
        from specguard.training.progress import format_event, print_event

        now = time.monotonic()
        due = every > 0 and now - shown[0] >= every
        if _terminal_line(
            config, format_event(event), final=event.finished or due, fallback=lambda: print_event(event)
        ):
            shown[0] = now

    return write


def terminal_lines(config: pytest.Config) -> Callable[[str], None]:
    """A sink for progress lines (the falsifier's phases), shown as training's are: on a terminal only."""

    def write(line: str) -> None:
        _terminal_line(config, f"[specguard] {line}", final=False, fallback=lambda: None)

    return write


def _terminal_line(config: pytest.Config, text: str, *, final: bool, fallback: Callable[[], None]) -> bool:
    """``text`` on a line of its own, uncaptured: always if ``final``, else only on a live terminal; none under -q.

    Returns whether it was shown.
    """
    if config.get_verbosity() < 0:
        return False
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if reporter is None:  # e.g. -p no:terminal: stderr, as `specguard run` does
        if final:
            fallback()
        return final
    live = reporter.isatty and config.get_terminal_writer().hasmarkup
    if not live and not final:
        return False
    capture = config.pluginmanager.get_plugin("capturemanager")
    with capture.global_and_fixture_disabled() if capture is not None else contextlib.nullcontext():
        reporter.ensure_newline()
        reporter.write_line(text)
    return True


def run(state: GoalSpecSession, spec: Spec, item: pytest.Item) -> SpecResult:
    """The spec's result: trained (or read from the cache) once per session, shared by all its goal items.

    The first time, other plugins hear of it (``pytest_goal_spec_result``, :mod:`~specguard.pytest_plugin.hooks`),
    with ``item``, the item that ran it.
    """
    from specguard.cache.fingerprint import fingerprint_spec
    from specguard.engine.run_spec import run_with

    # Every goal item of a spec shares one result, under the spec's whole identity
    # (seeds, quorum and `undecided` included), the one the cache and baselines use.
    key = fingerprint_spec(spec).spec_key
    if key not in state.memo:
        _start_ahead(state)
        result = run_with(spec, run_options(state))
        result.spec_key = key
        state.memo[key] = result
        item.config.hook.pytest_goal_spec_result(item=item, spec=spec, result=result)
    return state.memo[key]


def judge_agent(
    state: GoalSpecSession, check: AgentCheck, item: pytest.Item, group: str
) -> tuple[AgentCheck, SpecResult]:
    """The agent check as this session judges it (its ``--goal-specs-undecided``; there is no budget to scale, nothing
    is trained) and its result: judged once per test, shared by all its goal items; other plugins hear of it as of a
    trained spec's (``pytest_goal_spec_result``)."""
    from specguard.engine.check_agent import spec_agent

    if group in state.agent_checks:  # its agent loaded once per test, for its goal items and its report GIF
        return state.agent_checks[group], state.agents[group]
    spec = check.spec.as_run(undecided=state.options.undecided)
    loaded = spec_agent(spec, check.agent, algorithm=check.algorithm, trust=check.trust)
    check = dataclasses.replace(check, spec=spec, agent=loaded)
    if group not in state.agents:
        # each episode's outcomes where a baseline saves or pairs them (the evaluation cache keeps counts only)
        paired = state.options.save or (state.baseline is not None and group in state.baseline.agents)
        outcomes = state.agent_outcomes.setdefault(group, []) if paired else None
        result = state.agents[group] = check.run(cache_dir=state.options.cache_dir, outcomes=outcomes)
        item.config.hook.pytest_goal_spec_result(item=item, spec=check.spec, result=result)
    state.agent_checks[group] = check
    return check, state.agents[group]


def baseline_name(state: GoalSpecSession) -> str:
    """The name of the baseline compared with, as the comparisons' lines say it."""
    return state.options.compare or "latest"


def agent_gate_of(state: GoalSpecSession, check: AgentCheck, group: str) -> SavedAgentGate | None:
    """The agent's comparison with the agent the session's baseline saved for its test (None without a baseline),
    once per test, on the baseline's own episodes (:func:`specguard.gate.saved_agent.compare_saved`), each key
    judged at Holm's first step over the baseline's comparisons."""
    if state.baseline is None:
        return None
    if group not in state.agent_gates:
        from specguard.gate.saved_agent import compare_saved
        from specguard.stats.family import first_level
        from specguard.stats.sequential import DEFAULT_ALPHA

        state.agent_gates[group] = compare_saved(
            check,
            state.agent_outcomes.setdefault(group, []),
            state.baseline,
            group,
            baseline_name(state),
            level=first_level(DEFAULT_ALPHA, state.baseline.family),
        )
    return state.agent_gates[group]


def saved_agent(state: GoalSpecSession, check: AgentCheck, group: str) -> AgentEntry | str:
    """What ``--goal-specs-save`` stores for the agent's test (:func:`specguard.gate.saved_agent.saved_entry`), or
    the line saying why nothing is (an agent, spec or ``wrap`` without an exact identity), once per test."""
    if group not in state.agent_entries:
        from specguard.error import AgentError, FingerprintError
        from specguard.gate.saved_agent import saved_entry

        try:
            entry: AgentEntry | str = saved_entry(check, state.agent_outcomes.setdefault(group, []))
        except (FingerprintError, AgentError) as e:
            entry = f"not saved: {e}"
        state.agent_entries[group] = entry
    return state.agent_entries[group]


def _train(state: GoalSpecSession, spec: Spec) -> Callable[[list[int]], SpecResult]:
    """Train given seeds of ``spec`` with the session's options (cached seeds are reused)."""
    from specguard.engine.run_spec import train_seeds

    def train(seeds: list[int]) -> SpecResult:
        return train_seeds(spec, seeds, run_options(state))

    return train


def gate_of(state: GoalSpecSession, spec: Spec, result: SpecResult, group: str) -> SpecGate | None:
    """The spec's comparisons with the session's baseline (None without one), once per spec: extra seeds are
    trained here while a comparison is open (:func:`specguard.gate.comparison.compare_spec`).

    Each comparison is judged at Holm's first step over the baseline's goals and safety rates.
    """
    if state.baseline is None:
        return None
    key = result.spec_key or group
    if key not in state.gates:
        from specguard.gate.comparison import compare_spec, gate_ceiling
        from specguard.stats.family import first_level
        from specguard.stats.sequential import DEFAULT_ALPHA

        state.gates[key] = compare_spec(
            spec,
            result,
            state.baseline,
            {path: f"{group}::{path}" for path in spec.thresholds},
            level=first_level(DEFAULT_ALPHA, state.baseline.family),
            ceiling=gate_ceiling(spec, state.options.compare_seeds),
            train=_train(state, spec),
        )
    return state.gates[key]


def saved_runs(state: GoalSpecSession, spec: Spec, result: SpecResult, gate: SpecGate | None) -> SpecGate:
    """The runs ``--goal-specs-save`` stores for the spec: its own and more, up to the ceiling, once per spec."""
    key = result.spec_key or spec.label
    if key not in state.saved:
        from specguard.gate.comparison import baseline_runs, gate_ceiling

        state.saved[key] = baseline_runs(
            result,
            ceiling=gate_ceiling(spec, state.options.compare_seeds),
            train=_train(state, spec),
            runs=gate.runs if gate is not None else (),
        )
    return state.saved[key]
