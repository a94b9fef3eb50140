"""A pytest session's goal-spec state: its options, the one result per spec, and where progress goes."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from specguard.pytest_plugin.items import PROPERTY, group_of, one_line_errors, raise_outcome, spec_of
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

__all__ = ["GoalSpecSession", "terminal_lines", "terminal_progress"]

_ITEM_SPEC = pytest.StashKey[tuple[Any, list[str], Any]]()


@dataclasses.dataclass
class GoalSpecSession:
    """A ``--goal-specs`` session: what it keeps (options, the baseline compared with, the executor, results and
    report rows) and what it does with each goal-spec item (:meth:`run_item`, :meth:`show_item`), as pytest-xdist's
    ``DSession`` owns its logic and its hooks only call in. Named apart from pytest's own ``Session``, which holds it
    in its stash."""

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
    shown: set[str] = dataclasses.field(default_factory=set)  # the groups --goal-specs-show/plan rendered

    # -- an item ---------------------------------------------------------------------------------------------

    def item_spec(self, item: pytest.Function, expect: Any) -> tuple[Any, list[str], Any]:
        """What ``item`` asserts (:func:`~specguard.pytest_plugin.items.spec_of`: its function called once, the
        decorator's ``expect`` applied once), kept on the item for every later use (training, showing, planning).

        Raises:
            SpecError: the decorator's thresholds do not fit the spec (call it inside ``one_line_errors``).
        """
        found = item.stash.get(_ITEM_SPEC, None)
        if found is None:
            found = item.stash[_ITEM_SPEC] = spec_of(item, expect)
        return found

    def run_item(self, item: pytest.Function, expect: Any) -> None:
        """Run a goal-spec item: its spec trained once per session (an agent's judged, nothing trained), compared with
        the baseline, saved; its goals judged, its report rows and junit properties written, and its outcome raised
        (:func:`~specguard.pytest_plugin.items.raise_outcome`). A falsify item is
        :func:`~specguard.pytest_plugin.falsify_item.run_falsify_item`'s."""
        from specguard.pytest_plugin.judge import check_item

        group = group_of(item)
        with one_line_errors(item):
            spec, paths, agent = self.item_spec(item, expect)
            agent_gate, entry = None, None
            if agent is not None:  # an agent trained elsewhere: judged, not trained; compared on the saved episodes
                agent, result = self.judge_agent(agent, item, group)
                trained, gate, stored = agent.spec, None, None
                agent_gate = self.agent_gate(agent, group)
                entry = self.saved_agent(agent, group) if self.options.save else None
            else:
                trained = self.scaled(spec)
                result = self.run(trained, item)
                gate = self.gate(trained, result, group)
                stored = self.saved_runs(trained, result, gate) if self.options.save else None
        baseline = (self.baseline, self.baseline_name()) if self.baseline is not None else None
        checks = check_item(result, spec, paths, group, baseline=baseline, gate=gate, agent_gate=agent_gate)
        for goal in checks:
            if isinstance(entry, str):  # nothing to save: say why, after any comparison
                goal.comparison = f"{goal.comparison}; {entry}" if goal.comparison else entry
            elif entry is not None:
                goal.agent_baseline = entry.to_dict()
            if stored is not None:
                goal.baseline_runs = [[r.seed, r.successes[goal.goal], r.episodes] for r in stored.runs]
            row = goal.to_row()
            if self.options.report_dir is not None:
                if agent is not None:  # nothing trained: no curves; its GIF is the agent's own (agent_checks)
                    row["agent"], row["curves"] = result.agent, []
                else:
                    row["curves"] = [r.curve for r in result.runs]
                self.specs.setdefault(row["group"], trained)  # the spec as trained: its cache entries
            item.user_properties.append((PROPERTY, json.dumps(row)))
            item.user_properties += [(f"{PROPERTY}.{goal.goal}.{k}", v) for k, v in goal.junit_properties()]
        raise_outcome(item, checks, trained.undecided, result)

    def show_item(self, item: pytest.Function, expect: Any, *, show: bool, plan: bool) -> str | None:
        """What ``--goal-specs-show`` (the spec rendered) and ``--goal-specs-plan`` (its plan) print for ``item``;
        ``None`` where its spec was shown already (one rendering, and one budget warning, per spec)."""
        from specguard.report.show import agent_plan_text, plan_text, render_spec

        group = group_of(item)
        if group in self.shown:
            return None
        with one_line_errors(item):
            spec, _, agent = self.item_spec(item, expect)
            trained = self.scaled(spec) if agent is None else spec
            texts = [render_spec(trained, group)] if show else []
            # without a baseline: the session's goal items, and at least this spec's own thresholds (an item
            # asserting a spec's own thresholds is one item for several comparisons)
            family = self.baseline.family if self.baseline is not None else self.goal_items
            family = max(1, family, len(trained.thresholds))
            if plan and agent is not None:
                texts.append(agent_plan_text(agent, group, family=family, baseline=self.baseline))
            elif plan:
                texts.append(
                    plan_text(
                        trained,
                        group,
                        family=family,
                        compare_seeds=self.options.compare_seeds,
                        baseline=self.baseline,
                    )
                )
        self.shown.add(group)
        return "\n".join(texts)

    # -- training ------------------------------------------------------------------------------------------

    def run_options(self) -> RunOptions:
        """How this session trains: its workers, cache, progress sink and executor, one value for every call."""
        from specguard.engine.run_spec import RunOptions
        from specguard.parallel.slots import PooledExecutor

        return RunOptions(
            workers=self.options.workers,
            cache_dir=self.options.cache_dir,
            progress=self.progress,
            executor=PooledExecutor(self.pool) if self.pool is not None else self.executor or "local",
            ahead=self.ahead,
        )

    def upcoming_specs(self, items: list[pytest.Item]) -> list[Spec]:
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
                    specs.append(self.scaled(with_thresholds(returned, None, None)[0]))
            except Exception:  # the item says what is wrong when it runs
                continue
        return specs

    def _start_ahead(self) -> None:
        """At the session's first training: its slots, and the seeds of its upcoming specs queued behind the item."""
        if self.upcoming is None:
            return
        from specguard.cache.store import Cache
        from specguard.engine.ahead import TrainAhead
        from specguard.parallel.slots import SlotPool

        assert self.options.cache_dir is not None
        upcoming, self.upcoming = self.upcoming, None
        workers = self.options.workers
        self.pool = SlotPool(workers if isinstance(workers, int) else 1)
        self.ahead = TrainAhead(self.pool, Cache(Path(self.options.cache_dir)), say=self.progress)
        self.ahead.plan(upcoming)

    def close_ahead(self) -> None:
        """Stop what trains ahead, store what finished, and close the slots (the session's end, Ctrl-C)."""
        ahead, pool = self.ahead, self.pool
        self.ahead, self.pool = None, None
        try:
            if ahead is not None:
                ahead.close()
        finally:
            if pool is not None:
                pool.close()

    def scaled(self, spec: Spec) -> Spec:
        """The spec as this session trains and judges it: the session's options applied, the spec's own where unset."""
        options = self.options
        return spec.as_run(
            options.budget_scale,
            checkpoints=options.checkpoints,
            undecided=options.undecided,
            tensorboard_log=options.tensorboard_log,
            numerics=options.numerics,
        )

    def run(self, spec: Spec, item: pytest.Item) -> SpecResult:
        """The spec's result: trained (or read from the cache) once per session, shared by all its goal items.

        The first time, other plugins hear of it (``pytest_goal_spec_result``, :mod:`~specguard.pytest_plugin.hooks`),
        with ``item``, the item that ran it.
        """
        from specguard.cache.fingerprint import fingerprint_spec
        from specguard.engine.run_spec import run_with

        # Every goal item of a spec shares one result, under the spec's whole identity
        # (seeds, quorum and `undecided` included), the one the cache and baselines use.
        key = fingerprint_spec(spec).spec_key
        if key not in self.memo:
            self._start_ahead()
            result = run_with(spec, self.run_options())
            result.spec_key = key
            self.memo[key] = result
            item.config.hook.pytest_goal_spec_result(item=item, spec=spec, result=result)
        return self.memo[key]

    def judge_agent(self, check: AgentCheck, item: pytest.Item, group: str) -> tuple[AgentCheck, SpecResult]:
        """The agent check as this session judges it (its ``--goal-specs-undecided``; there is no budget to scale,
        nothing is trained) and its result: judged once per test, shared by all its goal items; other plugins hear of
        it as of a trained spec's (``pytest_goal_spec_result``)."""
        from specguard.engine.check_agent import spec_agent

        if group in self.agent_checks:  # its agent loaded once per test, for its goal items and its report GIF
            return self.agent_checks[group], self.agents[group]
        spec = check.spec.as_run(undecided=self.options.undecided)
        loaded = spec_agent(spec, check.agent, algorithm=check.algorithm, trust=check.trust)
        check = dataclasses.replace(check, spec=spec, agent=loaded)
        if group not in self.agents:
            # each episode's outcomes where a baseline saves or pairs them (the evaluation cache keeps counts only)
            paired = self.options.save or (self.baseline is not None and group in self.baseline.agents)
            outcomes = self.agent_outcomes.setdefault(group, []) if paired else None
            result = self.agents[group] = check.run(cache_dir=self.options.cache_dir, outcomes=outcomes)
            item.config.hook.pytest_goal_spec_result(item=item, spec=check.spec, result=result)
        self.agent_checks[group] = check
        return check, self.agents[group]

    def baseline_name(self) -> str:
        """The name of the baseline compared with, as the comparisons' lines say it."""
        return self.options.compare or "latest"

    def agent_gate(self, check: AgentCheck, group: str) -> SavedAgentGate | None:
        """The agent's comparison with the agent the session's baseline saved for its test (None without a baseline),
        once per test, on the baseline's own episodes (:func:`specguard.gate.saved_agent.compare_saved`), each key
        judged at Holm's first step over the baseline's comparisons."""
        if self.baseline is None:
            return None
        if group not in self.agent_gates:
            from specguard.gate.saved_agent import compare_saved
            from specguard.stats.family import first_level
            from specguard.stats.sequential import DEFAULT_ALPHA

            self.agent_gates[group] = compare_saved(
                check,
                self.agent_outcomes.setdefault(group, []),
                self.baseline,
                group,
                self.baseline_name(),
                level=first_level(DEFAULT_ALPHA, self.baseline.family),
            )
        return self.agent_gates[group]

    def saved_agent(self, check: AgentCheck, group: str) -> AgentEntry | str:
        """What ``--goal-specs-save`` stores for the agent's test (:func:`specguard.gate.saved_agent.saved_entry`), or
        the line saying why nothing is (an agent, spec or ``wrap`` without an exact identity), once per test."""
        if group not in self.agent_entries:
            from specguard.error import AgentError, FingerprintError
            from specguard.gate.saved_agent import saved_entry

            try:
                entry: AgentEntry | str = saved_entry(check, self.agent_outcomes.setdefault(group, []))
            except (FingerprintError, AgentError) as e:
                entry = f"not saved: {e}"
            self.agent_entries[group] = entry
        return self.agent_entries[group]

    def _trainer_of(self, spec: Spec) -> Callable[[list[int]], SpecResult]:
        """Train given seeds of ``spec`` with the session's options (cached seeds are reused)."""
        from specguard.engine.run_spec import train_seeds

        def train(seeds: list[int]) -> SpecResult:
            return train_seeds(spec, seeds, self.run_options())

        return train

    def gate(self, spec: Spec, result: SpecResult, group: str) -> SpecGate | None:
        """The spec's comparisons with the session's baseline (None without one), once per spec: extra seeds are
        trained here while a comparison is open (:func:`specguard.gate.comparison.compare_spec`).

        Each comparison is judged at Holm's first step over the baseline's goals and safety rates.
        """
        if self.baseline is None:
            return None
        key = result.spec_key or group
        if key not in self.gates:
            from specguard.gate.comparison import compare_spec, gate_ceiling
            from specguard.stats.family import first_level
            from specguard.stats.sequential import DEFAULT_ALPHA

            self.gates[key] = compare_spec(
                spec,
                result,
                self.baseline,
                {path: f"{group}::{path}" for path in spec.thresholds},
                level=first_level(DEFAULT_ALPHA, self.baseline.family),
                ceiling=gate_ceiling(spec, self.options.compare_seeds),
                train=self._trainer_of(spec),
            )
        return self.gates[key]

    def saved_runs(self, spec: Spec, result: SpecResult, gate: SpecGate | None) -> SpecGate:
        """The runs ``--goal-specs-save`` stores for the spec: its own and more, up to the ceiling, once per spec."""
        key = result.spec_key or spec.label
        if key not in self.saved:
            from specguard.gate.comparison import baseline_runs, gate_ceiling

            self.saved[key] = baseline_runs(
                result,
                ceiling=gate_ceiling(spec, self.options.compare_seeds),
                train=self._trainer_of(spec),
                runs=gate.runs if gate is not None else (),
            )
        return self.saved[key]


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
