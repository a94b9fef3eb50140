"""The pytest plugin: ``pytest --goal-specs`` (registered through the ``pytest11`` entry point).

Options, ini settings, markers and hooks only; the logic lives in
:mod:`specguard.pytest_plugin.gate`, :mod:`specguard.stats.compare`, :mod:`specguard.report.session` and
:mod:`specguard.engine.run`, which are imported when a goal spec actually runs, so
plain ``pytest`` in a project with specguard installed stays fast.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import warnings
from collections.abc import Callable, Generator
from pathlib import Path
from typing import Any

import pytest

from specguard.pytest_plugin.declare import GOAL_FIXTURE, SpecItem

MARKER = "goal_spec"
PROPERTY = "specguard"
UNDECIDED = ("fail", "xfail", "pass")
SKIP_REASON = "goal spec: run `pytest --goal-specs` to train it and check its goals"


class GoalMissed(AssertionError):
    """A goal missed its threshold (the failure an ``xfail`` goal expects)."""


@dataclasses.dataclass
class _Options:
    enabled: bool
    budget_scale: float
    checkpoints: int
    workers: int | str
    cache_dir: str | None
    undecided: str
    report_dir: Path | None
    save: str | None
    compare: str | None
    baseline_dir: Path
    executor: str


@dataclasses.dataclass
class _Session:
    options: _Options
    baseline: Any = None  # a specguard.stats.compare.Baseline
    executor: Any = None  # a specguard.engine.executors.Executor, made once per session
    memo: dict[str, Any] = dataclasses.field(default_factory=dict)
    rows: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    specs: dict[str, Any] = dataclasses.field(default_factory=dict)  # group -> its trained Spec, for report GIFs
    progress: Callable[[Any], None] | None = None  # the run_spec sink: events to the terminal reporter


_SESSION = pytest.StashKey[_Session]()

# (option, ini name, ini type, default, help)
_SETTINGS: list[tuple[str, str, str, Any, str]] = [
    (
        "--goal-specs-budget-scale",
        "goal_specs_budget_scale",
        "string",
        "1",
        "multiply training timesteps (0.25: quick PR check)",
    ),
    (
        "--goal-specs-checkpoints",
        "goal_specs_checkpoints",
        "string",
        "10",
        "judge runs at this many checkpoints and stop training once every threshold is met "
        "(anytime verdicts); 1: train every run's whole budget",
    ),
    (
        "--goal-specs-workers",
        "goal_specs_workers",
        "string",
        "auto",
        "parallel training processes per pytest process: N, or auto = the usable cores (shared among xdist workers)",
    ),
    ("--goal-specs-cache-dir", "goal_specs_cache_dir", "string", ".specguard/cache", "where trained runs are cached"),
    (
        "--goal-specs-undecided",
        "goal_specs_undecided",
        "string",
        "fail",
        "what a goal whose runs stayed undecided does: fail, xfail or pass (with a warning)",
    ),
    (
        "--goal-specs-report",
        "goal_specs_report",
        "string",
        "",
        "write JSON, Markdown and PNG reports to this directory",
    ),
    (
        "--goal-specs-executor",
        "goal_specs_executor",
        "string",
        "local",
        "where runs train: local (this machine) or a Dask scheduler address, tcp://host:8786",
    ),
    (
        "--goal-specs-baseline-dir",
        "goal_specs_baseline_dir",
        "string",
        "",
        "where saved baselines live (default: 'baselines' beside the cache dir, .specguard/baselines)",
    ),
]


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("specguard", "goal specs (specguard)")
    group.addoption("--goal-specs", action="store_true", default=None, help="train goal specs and check their goals")
    group.addoption(
        "--goal-specs-show",
        action="store_true",
        default=False,
        help="with --goal-specs: print every goal spec's tree, reward formula, observation layout and budget, "
        "train nothing, and report its items skipped",
    )
    parser.addini("goal_specs", type="bool", default=False, help="run goal specs without --goal-specs")
    for option, ini, kind, default, text in _SETTINGS:
        group.addoption(option, default=None, help=f"{text} (ini: {ini}, default: {default or 'none'})")
        parser.addini(ini, type=kind, default=default, help=text)  # type: ignore[arg-type]
    group.addoption(
        "--goal-specs-no-cache", action="store_true", default=False, help="neither read nor write the cache"
    )
    group.addoption(
        "--goal-specs-save", metavar="NAME", default=None, help="store this session's results as baseline NAME"
    )
    group.addoption(
        "--goal-specs-compare",
        metavar="NAME",
        nargs="?",
        const="latest",
        default=None,
        help="fail goals whose success dropped against baseline NAME (default: the latest saved)",
    )


def _setting(config: pytest.Config, option: str, ini: str) -> str:
    value = config.getoption(option.lstrip("-").replace("-", "_"))
    return str(value if value is not None else config.getini(ini))


def _parse_options(config: pytest.Config) -> _Options:
    def get(option: str) -> str:
        ini = next(i for o, i, *_ in _SETTINGS if o == option)
        return _setting(config, option, ini)

    from specguard.validation import parse_positive

    try:
        scale = parse_positive(get("--goal-specs-budget-scale"))
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-budget-scale: {e}") from None
    from specguard.engine.workers import resolve_workers
    from specguard.error import InvalidSpec
    from specguard.stats.anytime import parse_checkpoints

    try:
        checkpoints = parse_checkpoints(get("--goal-specs-checkpoints"))
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-checkpoints: {e}") from None

    workerinput = getattr(config, "workerinput", None)
    try:  # under xdist, "auto" shares the cores among its workers
        workers = resolve_workers(get("--goal-specs-workers"), share=int((workerinput or {}).get("workercount", 1)))
    except InvalidSpec as e:
        raise pytest.UsageError(f"--goal-specs-workers: {e.message}") from None
    undecided = get("--goal-specs-undecided")
    if undecided not in UNDECIDED:
        raise pytest.UsageError(f"--goal-specs-undecided: expected one of {', '.join(UNDECIDED)}, got {undecided!r}")
    report = get("--goal-specs-report")
    return _Options(
        enabled=bool(config.getoption("goal_specs") or config.getini("goal_specs")),
        budget_scale=scale,
        checkpoints=checkpoints,
        workers=workers,
        cache_dir=None if config.getoption("goal_specs_no_cache") else get("--goal-specs-cache-dir"),
        undecided=undecided,
        report_dir=Path(report) if report else None,
        save=config.getoption("goal_specs_save"),
        compare=config.getoption("goal_specs_compare"),
        baseline_dir=Path(get("--goal-specs-baseline-dir") or Path(get("--goal-specs-cache-dir")).parent / "baselines"),
        executor=_checked_executor(get("--goal-specs-executor")),
    )


def _checked_executor(text: str) -> str:
    from specguard.engine.executors import ExecutorError, check_address

    try:
        return check_address(text)
    except ExecutorError as e:
        raise pytest.UsageError(f"--goal-specs-executor: {str(e).removeprefix('executor: ')}") from None


def _baseline_path(options: _Options, name: str) -> Path:
    if name == "latest":
        saved = sorted(options.baseline_dir.glob("*.json"), key=lambda p: p.stat().st_mtime)
        if not saved:
            raise pytest.UsageError(
                f"--goal-specs-compare: no baseline saved in {str(options.baseline_dir)!r}; "
                "store one first with --goal-specs-save NAME"
            )
        return saved[-1]
    return options.baseline_dir / f"{name}.json"


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        f"{MARKER}(expect=None, xfail=None): a test returning a specguard.Spec, trained and checked by "
        "`pytest --goal-specs` (declare it with @specguard.goal_spec)",
    )
    options = _parse_options(config)
    state = _Session(options)
    if options.enabled and options.compare:
        from specguard.stats.compare import BaselineError, load_baseline

        try:
            state.baseline = load_baseline(_baseline_path(options, options.compare))
        except BaselineError as e:
            raise pytest.UsageError(f"--goal-specs-compare: {e}") from None
    if options.enabled and options.executor != "local":
        from specguard.engine.executors import ExecutorError, make_executor

        try:  # connect now: a cluster that does not answer is a usage error before anything trains
            state.executor = make_executor(options.executor, workers=1)
        except ExecutorError as e:
            raise pytest.UsageError(f"--goal-specs-executor: {e}") from None
    state.progress = _terminal_progress(config)
    config.stash[_SESSION] = state
    config.pluginmanager.register(_Recorder(config, state), "specguard-recorder")


def pytest_unconfigure(config: pytest.Config) -> None:
    state = config.stash.get(_SESSION, None)
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
    return lambda spec: _run(state, _scaled(state, spec))


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    marker = metafunc.definition.get_closest_marker(MARKER)
    if marker is None or GOAL_FIXTURE not in metafunc.fixturenames:
        return
    if marker.kwargs.get("cases"):  # sg.goal_specs: one item per spec and goal, with the spec's own marks
        metafunc.parametrize(GOAL_FIXTURE, marker.kwargs["cases"], indirect=True)
        return
    expect = marker.kwargs.get("expect")
    goals = list(expect) if expect else [None]
    metafunc.parametrize(GOAL_FIXTURE, goals, ids=["spec" if g is None else str(g) for g in goals], indirect=True)


def _group(item: pytest.Item) -> str:
    """The item's spec: its test without the goal parameter (one training for all its goals)."""
    assert isinstance(item, pytest.Function)
    callspec = getattr(item, "callspec", None)
    case = callspec.params.get(GOAL_FIXTURE) if callspec is not None else None
    if isinstance(case, SpecItem):
        return f"{item.path.name}::{item.originalname}[{case.spec}]"
    ids = list(getattr(callspec, "_idlist", []))
    params = list(callspec.params) if callspec is not None else []
    if callspec is not None and GOAL_FIXTURE in params and len(ids) == len(params):
        del ids[params.index(GOAL_FIXTURE)]
    suffix = f"[{'-'.join(ids)}]" if ids else ""
    return f"{item.path.name}::{item.originalname}{suffix}"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    state = config.stash[_SESSION]
    for item in items:
        marker = item.get_closest_marker(MARKER)
        if marker is None or not isinstance(item, pytest.Function):
            continue
        if not state.options.enabled:
            item.add_marker(pytest.mark.skip(reason=SKIP_REASON))
            continue
        item.add_marker(pytest.mark.xdist_group(name=_group(item)))
        param = item.callspec.params.get(GOAL_FIXTURE) if hasattr(item, "callspec") else None
        reasons: dict[Any, str] = marker.kwargs.get("xfail") or {}
        goal = param
        if isinstance(param, SpecItem):  # sg.goal_specs: the spec's own xfail
            goal, reasons = param.goal, ({param.goal: param.xfail} if param.xfail else {})
        if goal is not None and goal in reasons:
            item.add_marker(pytest.mark.xfail(reason=reasons[goal], raises=GoalMissed, strict=False))


# -- running -------------------------------------------------------------------


def _scaled(state: _Session, spec: Any) -> Any:
    """The spec as this session trains it: its budget scaled, judged at the session's checkpoints."""
    return spec.scaled(state.options.budget_scale, checkpoints=state.options.checkpoints)


def _terminal_progress(config: pytest.Config) -> Callable[[Any], None]:
    """The progress sink of a session: events as lines through pytest's terminal reporter.

    Not captured (no ``-s`` needed), each on a line of its own. On a terminal,
    every event (a line per tenth of each seed's budget); in a log (not a tty,
    or no markup), only the line that ends each seed's run; under ``-q``, none.
    """

    def write(event: Any) -> None:
        from specguard.engine.progress import format_event

        if config.get_verbosity() < 0:
            return
        reporter = config.pluginmanager.get_plugin("terminalreporter")
        if reporter is None:  # e.g. -p no:terminal: stderr, as `specguard run` does
            if event.finished:
                from specguard.engine.progress import print_event

                print_event(event)
            return
        live = reporter.isatty and config.get_terminal_writer().hasmarkup
        if not live and not event.finished:
            return
        capture = config.pluginmanager.get_plugin("capturemanager")
        with capture.global_and_fixture_disabled() if capture is not None else contextlib.nullcontext():
            reporter.ensure_newline()
            reporter.write_line(format_event(event))

    return write


def _run(state: _Session, spec: Any) -> Any:
    from specguard.engine.fingerprint import fingerprint_spec
    from specguard.engine.run import run_spec

    # Every goal item of a spec shares one result, under the spec's whole identity
    # (seeds, quorum and `undecided` included), the one the cache and baselines use.
    key = fingerprint_spec(spec).spec_key
    if key not in state.memo:
        state.memo[key] = run_spec(
            spec,
            workers=state.options.workers,
            cache_dir=state.options.cache_dir,
            progress=state.progress,
            executor=state.executor or "local",
        )
        state.memo[key].spec_key = key
    return state.memo[key]


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem: pytest.Function) -> bool | None:
    marker = pyfuncitem.get_closest_marker(MARKER)
    if marker is None:
        return None
    from specguard.engine.spec import Spec
    from specguard.error import SpecError
    from specguard.pytest_plugin.gate import check_item, with_thresholds
    from specguard.stats.intervals import GoalOutcome

    state = pyfuncitem.config.stash[_SESSION]
    where = f"{pyfuncitem.path.name}::{pyfuncitem.name}"
    if marker.kwargs.get("error"):  # a malformed @goal_spec fails its own item, not the collection
        pytest.fail(f"{where}: {marker.kwargs['error']}", pytrace=False)
    args = {name: pyfuncitem.funcargs[name] for name in pyfuncitem._fixtureinfo.argnames}
    spec = pyfuncitem.obj(**args)
    if not isinstance(spec, Spec):
        pytest.fail(f"{where}: a goal spec must return a specguard.Spec, got {type(spec).__name__}", pytrace=False)
    goal = pyfuncitem.funcargs.get(GOAL_FIXTURE)
    if isinstance(goal, SpecItem):  # sg.goal_specs: the spec's own thresholds, this item's goal
        goal = goal.goal
    error: str | None = None
    try:
        spec, paths = with_thresholds(spec, marker.kwargs.get("expect"), goal)
        result = _run(state, _scaled(state, spec))
    except SpecError as e:
        error = f"{where}: {e}"
        if _detailed(pyfuncitem.config):  # the worker's own traceback only when asked for
            error += "".join(f"\n\n{note}" for note in getattr(e, "__notes__", ()))
    if error is not None:  # outside the handler: one message, not a chain of two
        pytest.fail(error, pytrace=False)
    baseline = (state.baseline, state.options.compare or "latest") if state.baseline is not None else None
    checks = check_item(result, spec, paths, _group(pyfuncitem), baseline=baseline)
    failures, undecided = [], []
    for check in checks:
        row = check.to_row()
        if state.options.report_dir is not None:
            row["curves"] = [r.curve for r in result.runs]
            state.specs.setdefault(row["group"], _scaled(state, spec))  # the spec as trained: its cache entries
        pyfuncitem.user_properties.append((PROPERTY, json.dumps(row)))
        pyfuncitem.user_properties += [(f"{PROPERTY}.{check.goal}.{k}", v) for k, v in check.junit_properties()]
        if check.outcome is GoalOutcome.FAILED:
            failures.append(check.message())
        elif check.outcome is GoalOutcome.UNDECIDED:
            undecided.append(check.message())
    if failures or (undecided and state.options.undecided == "fail"):
        text = "\n\n".join(failures + undecided)
        if _detailed(pyfuncitem.config) and result.tracebacks:
            text += "".join(f"\n\nworker traceback (seed {k}):\n{tb}" for k, tb in sorted(result.tracebacks.items()))
        raise GoalMissed(text)
    if undecided and state.options.undecided == "xfail":
        pytest.xfail("undecided: " + "\n\n".join(undecided))
    if undecided:
        warnings.warn(
            "undecided goal spec passed by --goal-specs-undecided=pass:\n" + "\n".join(undecided), stacklevel=1
        )
    return True


def _detailed(config: pytest.Config) -> bool:
    """Whether the user asked for details: ``-v`` or ``--tb=long``."""
    return bool(config.get_verbosity() > 0 or config.getoption("tbstyle", "auto") == "long")


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Generator[None, Any, Any]:
    report = yield
    if call.excinfo is not None and isinstance(call.excinfo.value, GoalMissed) and report.failed:
        report.longrepr = str(call.excinfo.value)  # the figures, not a traceback into the plugin
    return report


# -- reporting -----------------------------------------------------------------


def _verdict(report: pytest.TestReport) -> str:
    if hasattr(report, "wasxfail"):
        return "xpassed" if report.passed else "xfailed"
    return report.outcome


class _Recorder:
    """Collects the figures of goal items as reports arrive (on the xdist controller too) and reports them."""

    def __init__(self, config: pytest.Config, state: _Session) -> None:
        self.config = config
        self.state = state

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when != "call":
            return
        for key, value in report.user_properties:
            if key != PROPERTY:
                continue
            row = json.loads(str(value))
            verdict = _verdict(report)
            row["verdict"] = "undecided" if verdict == "passed" and row["outcome"] == "undecided" else verdict
            self.state.rows.append(row)

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        if not self.state.rows:
            return
        from specguard.report.session import table_lines

        terminalreporter.write_sep("=", "specguard goal specs")
        for line in table_lines(self.state.rows):
            terminalreporter.write_line(line)
        for path in _write_outputs(self.config, self.state):
            terminalreporter.write_line(f"specguard: wrote {path}")


def _write_outputs(config: pytest.Config, state: _Session) -> list[Path]:
    if hasattr(config, "workerinput"):  # an xdist worker: the controller writes
        return []
    written: list[Path] = []
    if state.options.report_dir is not None:
        from specguard.report.gifs import report_gifs
        from specguard.report.session import write_reports

        gifs = report_gifs(state.options.report_dir, state.rows, state.specs, state.options.cache_dir)
        written += write_reports(state.options.report_dir, state.rows, gifs=gifs)
        written += [gif.path for gif in gifs.values() if gif.path is not None]
        terminal = config.pluginmanager.get_plugin("terminalreporter")
        for group, gif in gifs.items():
            if gif.path is None and terminal is not None:
                terminal.write_line(f"specguard: {group}: {gif.text}")
    if state.options.save:
        from specguard.stats.compare import save_baseline

        path = state.options.baseline_dir / f"{state.options.save}.json"
        rows = [r for r in state.rows if r["runs_counts"]]
        save_baseline(
            path,
            {f"{r['group']}::{r['goal']}": r["runs_counts"] for r in rows},
            {f"{r['group']}::{r['goal']}": r["spec_key"] for r in rows if r.get("spec_key")},
        )
        written.append(path)
    return written


# -- showing (--goal-specs-show) -----------------------------------------------------

SHOW_PROPERTY = "specguard.show"
SHOWN = "shown, not trained"
_SHOWN_GROUPS = pytest.StashKey[set[str]]()


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_call(item: pytest.Item) -> None:
    """Under ``--goal-specs-show``, a goal spec item renders its spec and is skipped instead of training."""
    marker = item.get_closest_marker(MARKER)
    if not item.config.getoption("goal_specs_show", False) or marker is None or not isinstance(item, pytest.Function):
        return
    if not item.config.stash[_SESSION].options.enabled or marker.kwargs.get("error"):
        return  # skipped without --goal-specs; a malformed @goal_spec fails as usual
    from specguard.engine.spec import Spec
    from specguard.error import SpecError
    from specguard.pytest_plugin.gate import with_thresholds
    from specguard.pytest_plugin.show import render_spec

    group = _group(item)
    shown = item.config.stash.setdefault(_SHOWN_GROUPS, set())
    if group in shown:  # one rendering (and one budget warning) per spec, not per goal item
        pytest.skip(SHOWN)
    where = f"{item.path.name}::{item.name}"
    spec = item.obj(**{name: item.funcargs[name] for name in item._fixtureinfo.argnames})
    if not isinstance(spec, Spec):
        pytest.fail(f"{where}: a goal spec must return a specguard.Spec, got {type(spec).__name__}", pytrace=False)
    error: str | None = None
    try:
        spec, _ = with_thresholds(spec, marker.kwargs.get("expect"), item.funcargs.get(GOAL_FIXTURE))
        text = render_spec(_scaled(item.config.stash[_SESSION], spec), group)
    except SpecError as e:
        error = f"{where}: {e}"
    if error is not None:
        pytest.fail(error, pytrace=False)
    shown.add(group)
    item.user_properties.append((SHOW_PROPERTY, text))
    pytest.skip(SHOWN)


def pytest_terminal_summary(terminalreporter: Any) -> None:
    """Print the specs ``--goal-specs-show`` rendered (on the xdist controller too: they travel in the reports)."""
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
