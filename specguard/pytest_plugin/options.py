"""The plugin's options: the command-line flags, their ini settings, and the one parse of both per session.

Every value goes through the rule the other doors use (:mod:`specguard.utils.parsing`,
:func:`specguard.parallel.workers.resolve_workers`, :func:`specguard.stats.anytime.parse_checkpoints`);
a bad value is a ``pytest.UsageError`` before anything trains.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import pytest

from specguard.stats.sequential import DEFAULT_COMPARE_SEEDS
from specguard.utils.atomic import DEFAULT_CACHE_DIR

PROGRESS_EVERY_S = 60
"""In a log (not a terminal), the most seconds between two progress lines while a run trains."""

__all__ = ["Options", "add_options", "baseline_path", "parse_options"]


@dataclasses.dataclass
class Options:
    """A session's goal-spec options, parsed and checked."""

    enabled: bool
    budget_scale: float
    checkpoints: int | None  # None: each spec's own Budget.checkpoints
    workers: int | str
    cache_dir: str | None
    undecided: str | None  # None: each spec's own Spec.undecided
    report_dir: Path | None
    save: str | None
    compare: str | None
    baseline_dir: Path
    executor: str
    compare_seeds: int = DEFAULT_COMPARE_SEEDS
    plan: bool = False
    progress_every: int = PROGRESS_EVERY_S  # in a log: seconds between progress lines (0: each seed's last only)
    tensorboard_log: str | None = None  # None: each spec's trainer's own (SB3.tensorboard_log)
    numerics: str | None = None  # None: each spec's own Spec.numerics
    ahead: bool = True  # train the seeds of specs to come on cores the running item leaves idle


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
        "",
        "judge runs at this many checkpoints instead of each spec's own (Budget.checkpoints, 10 unless set) and "
        "stop training once every threshold is met (anytime verdicts); 1: train every run's whole budget",
    ),
    (
        "--goal-specs-workers",
        "goal_specs_workers",
        "string",
        "auto",
        "parallel training processes per pytest process: N, or auto = the usable cores (shared among xdist workers)",
    ),
    ("--goal-specs-cache-dir", "goal_specs_cache_dir", "string", DEFAULT_CACHE_DIR, "where trained runs are cached"),
    (
        "--goal-specs-ahead",
        "goal_specs_ahead",
        "string",
        "on",
        "on: while an item's spec trains, a core it leaves idle trains the seeds of the session's next specs "
        "(those of sg.goal_specs; with the local executor and a cache, not under xdist); off: one spec at a time",
    ),
    (
        "--goal-specs-undecided",
        "goal_specs_undecided",
        "string",
        "",
        "what a goal whose runs stayed undecided counts as: fail, xfail or pass (with a warning); "
        "default: the spec's own Spec.undecided, fail unless set",
    ),
    (
        "--goal-specs-numerics",
        "goal_specs_numerics",
        "string",
        "",
        "what runs compute with: portable (torch's and MKL's kernels held to those every x86-64 CPU computes alike: "
        "the same weights and verdicts on any machine) or native (the CPU's own, machine-dependent); default: the "
        "spec's own Spec.numerics, portable unless set",
    ),
    (
        "--goal-specs-tensorboard-log",
        "goal_specs_tensorboard_log",
        "string",
        "",
        "write TensorBoard logs of every training run to this directory (SB3's curves and each goal's success), "
        "one subfolder per spec and seed; runs found in the cache train nothing and write nothing",
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
        "--goal-specs-compare-seeds",
        "goal_specs_compare_seeds",
        "string",
        str(DEFAULT_COMPARE_SEEDS),
        "the most seeds a spec trains for a comparison that is still open, and the seeds --goal-specs-save stores "
        "per spec (a spec's own Budget.max_seeds when that is more)",
    ),
    (
        "--goal-specs-progress-every",
        "goal_specs_progress_every",
        "string",
        str(PROGRESS_EVERY_S),
        "when the output is not a terminal (a CI log): print a progress line of a training run at least this "
        "often, in seconds; 0: only each seed's last line (on a terminal every line is shown)",
    ),
    (
        "--goal-specs-baseline-dir",
        "goal_specs_baseline_dir",
        "string",
        "",
        "where saved baselines live (default: 'baselines' beside the cache dir, .specguard/baselines)",
    ),
]


def _help(text: str) -> str:
    """An option's help as argparse reads it: ``%`` written ``%%`` (argparse formats help with ``%``).

    Example:
        >>> _help("family-wise 5%")
        'family-wise 5%%'
    """
    return text.replace("%", "%%")


def add_options(parser: pytest.Parser) -> None:
    """Register the ``--goal-specs*`` options and their ini settings.

    Every option's help goes through :func:`_help`: one unescaped ``%`` would
    make ``pytest --help`` crash in every project of the environment.
    """
    group = parser.getgroup("specguard", "goal specs (specguard)")
    group.addoption(
        "--goal-specs", action="store_true", default=None, help=_help("train goal specs and check their goals")
    )
    group.addoption(
        "--goal-specs-show",
        action="store_true",
        default=False,
        help=_help(
            "with --goal-specs: print every goal spec's tree, reward formula, observation layout and budget, "
            "train nothing, and report its items skipped"
        ),
    )
    parser.addini("goal_specs", type="bool", default=False, help="run goal specs without --goal-specs")
    for option, ini, kind, default, text in _SETTINGS:
        group.addoption(option, default=None, help=_help(f"{text} (ini: {ini}, default: {default or 'none'})"))
        parser.addini(ini, type=kind, default=default, help=text)  # type: ignore[arg-type]
    group.addoption(
        "--goal-specs-no-cache", action="store_true", default=False, help=_help("neither read nor write the cache")
    )
    group.addoption(
        "--goal-specs-save", metavar="NAME", default=None, help=_help("store this session's results as baseline NAME")
    )
    group.addoption(
        "--goal-specs-compare",
        metavar="NAME",
        nargs="?",
        const="latest",
        default=None,
        help=_help(
            "fail goals whose success dropped against baseline NAME (default: the latest saved), training more "
            "seeds while a comparison is open; Holm's procedure over the session's comparisons at family-wise 5%"
        ),
    )
    group.addoption(
        "--goal-specs-plan",
        action="store_true",
        default=False,
        help=_help(
            "with --goal-specs: print what each spec's gate can see (the chance a run is judged met around each "
            "threshold; the smallest drop a comparison flags), train nothing, and report its items skipped"
        ),
    )


def _setting(config: pytest.Config, option: str, ini: str) -> str:
    value = config.getoption(option.lstrip("-").replace("-", "_"))
    return str(value if value is not None else config.getini(ini))


def parse_options(config: pytest.Config) -> Options:
    """The session's options from its command line and ini file.

    Raises:
        pytest.UsageError: a value breaks its rule (named, with the value).
    """

    def get(option: str) -> str:
        ini = next(i for o, i, *_ in _SETTINGS if o == option)
        return _setting(config, option, ini)

    from specguard.utils.parsing import parse_choice, parse_count, parse_natural, parse_positive

    try:
        scale = parse_positive(get("--goal-specs-budget-scale"))
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-budget-scale: {e}") from None
    from specguard.error import InvalidSpec
    from specguard.parallel.workers import resolve_workers
    from specguard.stats.anytime import parse_checkpoints
    from specguard.stats.verdicts import UNDECIDED_OUTCOMES
    from specguard.utils.numerics import NUMERICS

    try:
        text = get("--goal-specs-checkpoints")
        checkpoints = parse_checkpoints(text) if text else None  # None: each spec's own
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-checkpoints: {e}") from None

    workerinput = getattr(config, "workerinput", None)
    try:  # under xdist, "auto" shares the cores among its workers
        workers = resolve_workers(get("--goal-specs-workers"), share=int((workerinput or {}).get("workercount", 1)))
    except InvalidSpec as e:
        raise pytest.UsageError(f"--goal-specs-workers: {e.message}") from None
    undecided = get("--goal-specs-undecided") or None  # None: each spec's own Spec.undecided
    try:
        undecided = None if undecided is None else parse_choice(undecided, UNDECIDED_OUTCOMES)
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-undecided: {e}") from None
    numerics = get("--goal-specs-numerics") or None  # None: each spec's own Spec.numerics
    try:
        numerics = None if numerics is None else parse_choice(numerics, NUMERICS)
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-numerics: {e}") from None
    try:
        compare_seeds = parse_count(get("--goal-specs-compare-seeds"))
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-compare-seeds: {e}") from None
    try:
        progress_every = parse_natural(get("--goal-specs-progress-every"), "seconds")
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-progress-every: {e}") from None
    try:
        ahead = parse_choice(get("--goal-specs-ahead"), ("on", "off")) == "on"
    except ValueError as e:
        raise pytest.UsageError(f"--goal-specs-ahead: {e}") from None
    report = get("--goal-specs-report")
    tensorboard_log = get("--goal-specs-tensorboard-log") or None
    if tensorboard_log is not None:
        from specguard.spec.trainers import check_tensorboard_log

        try:
            check_tensorboard_log("--goal-specs-tensorboard-log", tensorboard_log)
        except InvalidSpec as e:
            raise pytest.UsageError(str(e).splitlines()[0]) from None
    return Options(
        enabled=bool(config.getoption("goal_specs") or config.getini("goal_specs")),
        budget_scale=scale,
        checkpoints=checkpoints,
        workers=workers,
        cache_dir=None if config.getoption("goal_specs_no_cache") else get("--goal-specs-cache-dir"),
        undecided=undecided,
        numerics=numerics,
        report_dir=Path(report) if report else None,
        save=config.getoption("goal_specs_save"),
        compare=config.getoption("goal_specs_compare"),
        baseline_dir=Path(get("--goal-specs-baseline-dir") or Path(get("--goal-specs-cache-dir")).parent / "baselines"),
        executor=_checked_executor(get("--goal-specs-executor")),
        compare_seeds=compare_seeds,
        plan=bool(config.getoption("goal_specs_plan")),
        progress_every=progress_every,
        tensorboard_log=tensorboard_log,
        ahead=ahead,
    )


def _checked_executor(text: str) -> str:
    from specguard.parallel.executors import ExecutorError, check_address

    try:
        return check_address(text)
    except ExecutorError as e:
        raise pytest.UsageError(f"--goal-specs-executor: {str(e).removeprefix('executor: ')}") from None


def baseline_path(options: Options, name: str) -> Path:
    """The file of baseline ``name`` (``latest``: the newest saved)."""
    if name == "latest":
        saved = sorted(options.baseline_dir.glob("*.json"), key=lambda p: p.stat().st_mtime)
        if not saved:
            raise pytest.UsageError(
                f"--goal-specs-compare: no baseline saved in {str(options.baseline_dir)!r}; "
                "store one first with --goal-specs-save NAME"
            )
        return saved[-1]
    return options.baseline_dir / f"{name}.json"
