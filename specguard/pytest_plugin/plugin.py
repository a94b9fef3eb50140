"""The pytest plugin: ``pytest --goal-specs`` (registered through the ``pytest11`` entry point).

Hooks, fixtures and the marker only. The logic lives in plain modules:
:mod:`~specguard.pytest_plugin.options` (the options and their one parse),
:mod:`~specguard.pytest_plugin.session` (the session object: one result per spec, and what each goal item runs),
:mod:`~specguard.pytest_plugin.items` (what an item runs and its outcome),
:mod:`~specguard.pytest_plugin.judge` (judging each goal),
:mod:`~specguard.pytest_plugin.recorder` (reports and baselines),
:mod:`~specguard.pytest_plugin.hooks` (the hooks other plugins implement) and
:mod:`~specguard.report.show` (``--goal-specs-show``, ``--goal-specs-plan``). Training
imports only when a goal spec runs, so plain ``pytest`` in a project with
specguard installed stays fast.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import Any

import pytest

from specguard.error import RunsCrashed
from specguard.pytest_plugin.declare import FALSIFY, GOAL_FIXTURE, SpecItem
from specguard.pytest_plugin.items import GoalMissed, falsify_check, group_of
from specguard.pytest_plugin.options import add_options, baseline_path, parse_options
from specguard.pytest_plugin.recorder import Recorder
from specguard.pytest_plugin.session import GoalSpecSession, terminal_progress

__all__ = ["GoalMissed"]

MARKER = "goal_spec"
SKIP_REASON = "goal spec: run `pytest --goal-specs` to train it and check its goals"

_SESSION = pytest.StashKey[GoalSpecSession]()


def pytest_addhooks(pluginmanager: pytest.PytestPluginManager) -> None:
    """Other plugins' hooks into goal specs (:mod:`~specguard.pytest_plugin.hooks`), as pytest-xdist adds its own."""
    from specguard.pytest_plugin import hooks

    pluginmanager.add_hookspecs(hooks)


def pytest_addoption(parser: pytest.Parser) -> None:
    add_options(parser)


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "slow: an expensive test (training, a fresh interpreter); specguard.testing.parametrize_with_checks marks "
        'the checks that start one; `pytest -m "not slow"` leaves them out',
    )
    config.addinivalue_line(
        "markers",
        f"{MARKER}(expect=None, xfail=None): a test returning a specguard.Spec, trained and checked by "
        "`pytest --goal-specs`, or a specguard.AgentCheck, its agent judged (declare it with @specguard.goal_spec)",
    )
    options = parse_options(config)
    state = GoalSpecSession(options)
    if options.enabled and options.compare:
        from specguard.gate.baseline import BaselineError, load_baseline

        try:
            state.baseline = load_baseline(baseline_path(options, options.compare))
        except BaselineError as e:
            raise pytest.UsageError(f"--goal-specs-compare: {e}") from None
    if options.enabled and options.executor != "local":
        from specguard.parallel.executors import ExecutorError, make_executor

        try:  # connect now: a cluster that does not answer is a usage error before anything trains
            state.executor = make_executor(options.executor, workers=1)
        except ExecutorError as e:
            raise pytest.UsageError(f"--goal-specs-executor: {e}") from None
    state.progress = terminal_progress(config, options.progress_every)
    config.stash[_SESSION] = state
    config.pluginmanager.register(Recorder(config, state), "specguard-recorder")


def pytest_unconfigure(config: pytest.Config) -> None:
    state = config.stash.get(_SESSION, None)
    if state is not None:
        state.close_ahead()
    if state is not None and state.executor is not None:
        state.executor.close()


# -- declaring and collecting -----------------------------------------------------


@pytest.fixture
def specguard_goal(request: pytest.FixtureRequest) -> Any:
    """The goal a goal-spec item asserts (``None``: every threshold of the spec)."""
    return getattr(request, "param", None)


@pytest.fixture
def goal_spec_result(request: pytest.FixtureRequest) -> Callable[[Any], Any]:
    """Train a spec (with the session's goal-spec options) and return its ``SpecResult``.

    Tests that use it are skipped without ``--goal-specs``.
    """
    state = request.config.stash[_SESSION]
    if not state.options.enabled:
        pytest.skip(SKIP_REASON)
    return lambda spec: state.run(state.scaled(spec), request.node)


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    marker = metafunc.definition.get_closest_marker(MARKER)
    if marker is None or GOAL_FIXTURE not in metafunc.fixturenames:
        return
    if marker.kwargs.get("cases"):  # sg.goal_specs: one item per spec and goal, with the spec's own marks
        metafunc.parametrize(GOAL_FIXTURE, marker.kwargs["cases"], indirect=True)
        return
    expect = marker.kwargs.get("expect")
    goals: list[Any] = list(expect) if expect else [None]
    if marker.kwargs.get("falsify") is not None:  # one more item, after the goals': the falsifier on the runs
        goals.append(FALSIFY)
    metafunc.parametrize(GOAL_FIXTURE, goals, ids=["spec" if g is None else str(g) for g in goals], indirect=True)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    state = config.stash[_SESSION]
    xdist = config.pluginmanager.hasplugin("xdist")
    for item in items:
        marker = item.get_closest_marker(MARKER)
        if marker is None or not isinstance(item, pytest.Function):
            continue
        state.goal_items += falsify_check(item, marker) is None  # a falsify item compares nothing with a baseline
        if not state.options.enabled:
            item.add_marker(pytest.mark.skip(reason=SKIP_REASON))
            continue
        if xdist:  # one spec's items on one xdist worker: one training (the marker is xdist's)
            item.add_marker(pytest.mark.xdist_group(name=group_of(item)))
        param = item.callspec.params.get(GOAL_FIXTURE) if hasattr(item, "callspec") else None
        reasons: dict[Any, str] = marker.kwargs.get("xfail") or {}
        goal = param
        if isinstance(param, SpecItem):  # sg.goal_specs: the spec's own xfail
            goal, reasons = param.goal, ({param.goal: param.xfail} if param.xfail else {})
        if goal is not None and goal in reasons:
            item.add_marker(pytest.mark.xfail(reason=reasons[goal], raises=GoalMissed, strict=False))


def pytest_collection_finish(session: pytest.Session) -> None:
    """The specs to train ahead (``--goal-specs-ahead``): the session's items are known, deselection done."""
    config = session.config
    state = config.stash[_SESSION]
    options = state.options
    local = options.executor == "local" and state.executor is None
    shows = config.getoption("goal_specs_show", False) or config.getoption("goal_specs_plan", False)
    worker = hasattr(config, "workerinput")  # an xdist worker runs only some of the items it collected
    if options.enabled and options.ahead and local and options.cache_dir is not None and not shows and not worker:
        state.upcoming = state.upcoming_specs(session.items)


# -- running -------------------------------------------------------------------


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool | None:
    marker = pyfuncitem.get_closest_marker(MARKER)
    if marker is None:
        return None
    state = pyfuncitem.config.stash[_SESSION]
    if marker.kwargs.get("error"):  # a malformed @goal_spec fails its own item, not the collection
        pytest.fail(f"{pyfuncitem.path.name}::{pyfuncitem.name}: {marker.kwargs['error']}", pytrace=False)
    check = falsify_check(pyfuncitem, marker)
    if check is not None:
        from specguard.pytest_plugin.falsify_item import run_falsify_item

        run_falsify_item(pyfuncitem, state, check, marker.kwargs.get("expect"))
    else:
        state.run_item(pyfuncitem, marker.kwargs.get("expect"))
    return True


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Generator[None, Any, Any]:
    report = yield
    if call.excinfo is not None and isinstance(call.excinfo.value, (GoalMissed, RunsCrashed)) and report.failed:
        report.longrepr = str(call.excinfo.value)  # the figures, not a traceback into the plugin
    return report


# -- showing (--goal-specs-show, --goal-specs-plan) ------------------------------------


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_call(item: pytest.Item) -> None:
    """Under ``--goal-specs-show`` or ``--goal-specs-plan``, a goal spec item renders its spec (or its plan) and is
    skipped instead of training."""
    marker = item.get_closest_marker(MARKER)
    show, plan = item.config.getoption("goal_specs_show", False), item.config.getoption("goal_specs_plan", False)
    if not (show or plan) or marker is None or not isinstance(item, pytest.Function):
        return
    state = item.config.stash[_SESSION]
    if not state.options.enabled or marker.kwargs.get("error"):
        return  # skipped without --goal-specs; a malformed @goal_spec fails as usual
    from specguard.report.show import SHOW_PROPERTY, SHOWN

    text = state.show_item(item, marker.kwargs.get("expect"), show=show, plan=plan)
    if text is not None:  # None: its spec was shown by an earlier item
        item.user_properties.append((SHOW_PROPERTY, text))
    pytest.skip(SHOWN)


def pytest_terminal_summary(terminalreporter: Any) -> None:
    """Print what ``--goal-specs-show`` and ``--goal-specs-plan`` rendered (on the xdist controller too)."""
    from specguard.report.show import SHOW_PROPERTY, SHOWN

    texts: dict[str, None] = {}
    for reports in terminalreporter.stats.values():
        for report in reports:
            for key, value in getattr(report, "user_properties", ()):
                if key == SHOW_PROPERTY:
                    texts.setdefault(str(value), None)
    if texts:
        terminalreporter.write_sep("=", f"specguard goal specs: {SHOWN}")
        for text in texts:
            terminalreporter.write_line(text)
            terminalreporter.write_line("")
