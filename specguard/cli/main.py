"""The ``specguard`` command line.

``specguard show PATH[::NAME]`` prints the tree and the reward formula of the
specs (or trees) a Python file defines; ``specguard plan PATH[::NAME]`` prints
what each spec's gate can see, training nothing (:mod:`specguard.gate.plan`);
``specguard run PATH[::NAME]`` trains
them within their budgets and prints the per-goal table; ``specguard reproduce
PATH...`` trains every spec of case-study files on several seeds and writes a
Markdown table and plots (:mod:`specguard.engine.reproduce`,
:mod:`specguard.report.reproduction`). A file's specs are its
module-level ``Spec`` objects (named by variable) and the values of its
module-level dicts of specs (named by key); ``show`` also lists goal trees.

``specguard falsify PATH[::NAME]`` searches each trained run's start space for
starts from which it misses the spec; with ``--agent AGENT`` (and ``--algorithm``, ``--observation``, as ``check``
takes them), an agent trained elsewhere instead, training nothing
(:func:`specguard.engine.falsify_run.falsify_agent`). Its exit status: 0 when nothing was found, 1 when a
counterexample was, 2 for bad input (an agent that cannot be loaded, or whose spaces do not fit the env, in one line).

``specguard check PATH[::NAME] --agent AGENT`` judges an agent trained elsewhere (a saved SB3 or sb3-contrib zip, an
rl-zoo3 or Hub folder) against each spec, training nothing (:func:`specguard.engine.check_agent.check_agent`), and
prints the same table as ``run``; its exit status is ``run``'s: 0 when every spec passed, 1 when one failed, 2 for bad
input (an agent that cannot be loaded, or whose spaces do not fit the env, is one line naming it).

``run`` says pytest's words for the same run, per goal and per spec
(:func:`specguard.stats.verdicts.verdict_word`): ``passed``, ``failed``
(``FAILED`` on the spec's line), ``xfailed`` (a goal the spec declares in
``xfail`` missed), ``xpassed`` (it passed), and ``undecided`` (with what it
counts as).

Exit status of ``run``: 0 when every spec passed (a goal the spec declares in
``xfail`` may miss; an undecided goal counts as ``Spec.undecided`` or
``--undecided`` says), 1 when one failed, 2 for a usage or spec error (a spec
with no threshold has nothing to assert: refused before anything trains, as
``pytest --goal-specs`` refuses it). A ``--json`` file that cannot be written at
the end is a warning that says where the results went instead; the exit status
stays the verdicts'. Bad input (a path that is no Python file of specs, a spec
file that exits at import, a bad option value) is one line naming it, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from specguard.error import ExecutorError, InvalidSpec, SpecError
from specguard.parallel.executors import check_address
from specguard.parallel.workers import parse_workers
from specguard.spec.loading import load_objects, spec_path
from specguard.spec.spec import Spec
from specguard.stats.anytime import parse_checkpoints
from specguard.stats.verdicts import UNDECIDED_OUTCOMES
from specguard.tree.keys import require_thresholds
from specguard.tree.nodes import Node
from specguard.utils.atomic import DEFAULT_CACHE_DIR, write_atomic
from specguard.utils.numerics import NUMERICS
from specguard.utils.parsing import parse_choice, parse_count, parse_natural, parse_positive
from specguard.validation import check_unique
from specguard.version import __version__

__all__ = ["main"]


def _show(target: str) -> int:
    from specguard.report.show import has_goal_specs, render_spec, render_tree, show_goal_spec_file

    if has_goal_specs(spec_path(target)):  # a pytest file: only pytest resolves its fixtures
        return show_goal_spec_file(target)
    for name, obj in load_objects(target, (Spec, Node)).items():
        if isinstance(obj, Spec):
            print(render_spec(obj, name))
        else:
            print("\n".join([f"== {name}", *render_tree(obj)]))
        print()
    return 0


def _specs(target: str, command: str) -> dict[str, Spec]:
    """The specs of ``target`` for ``command``; a pytest goal-spec file that defines none (its specs are made by
    ``@goal_spec`` functions, an agent's as an ``sg.AgentCheck``) is refused with the pytest command that runs it."""
    from specguard.report.show import has_goal_specs

    path = spec_path(target)
    try:
        return load_objects(target)
    except SpecError as e:
        if not (has_goal_specs(path) and e.message.endswith("defines no Spec objects")):
            raise
        raise SpecError(
            f"{e.message}: it is a pytest goal-spec file, whose @goal_spec functions make their specs (and return "
            f"their agents, as sg.AgentCheck) under pytest; specguard {command} takes Spec objects",
            hint=f"pytest --goal-specs {path}",
        ) from None


def _plan(args: argparse.Namespace) -> int:
    from specguard.gate.plan import plan_spec
    from specguard.report.plan_lines import plan_lines
    from specguard.report.show import has_goal_specs, plan_goal_spec_file

    if has_goal_specs(spec_path(args.target)):  # a pytest file: only pytest resolves its fixtures
        return plan_goal_spec_file(args.target, compare_seeds=args.compare_seeds)
    specs = load_objects(args.target)
    family = args.comparisons or max(1, sum(len(spec.thresholds) for spec in specs.values()))
    for name, spec in specs.items():
        if not spec.thresholds:
            print(f"== {name}: no thresholds, nothing to judge or compare\n")
            continue
        plan = plan_spec(spec, family=family, compare_seeds=args.compare_seeds, spread=args.spread, label=name)
        print("\n".join(plan_lines(plan)))
        print()
    return 0


def _prepare_json(text: str) -> Path:
    """The ``--json`` file, its directory created now: a bad path must not cost a training run."""
    path = Path(text)
    if path.is_dir():
        raise SpecError(f"--json {path}: is a directory; expected a file name, e.g. {path / 'results.json'}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise SpecError(f"--json {path}: cannot create the directory {path.parent} ({e.strerror or e})") from e
    if not os.access(path.parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise SpecError(f"--json {path}: not writable; expected a file in a directory you can write to")
    return path


def _run(args: argparse.Namespace) -> int:
    from specguard.parallel.executors import make_executor
    from specguard.parallel.workers import resolve_workers

    specs = _specs(args.target, "run")
    for name, spec in specs.items():  # before anything trains: a spec with nothing to assert has no verdict
        require_thresholds(f"{args.target.partition('::')[0]}::{name}", spec.thresholds)
    json_path = _prepare_json(args.json) if args.json else None  # before training, which may take hours
    executor = make_executor(args.executor, workers=resolve_workers(args.workers))  # a cluster answers, or exit 2
    try:
        results, failed = _run_all(args, specs, executor)
    finally:
        executor.close()
    if json_path is not None:
        _write_results(json_path, json.dumps(results, indent=1))
    return 1 if failed else 0


def _write_results(path: Path, text: str) -> None:
    """Write ``--json``'s results; a write that fails warns in one line and keeps them.

    Kept in a temporary file it names, else printed on stdout; the exit status
    stays the verdicts' (the training is done: its results are not lost to a full disk).
    """
    try:
        write_atomic(path, text)
        return
    except OSError as e:
        reason = e.strerror or str(e)
    where = f"specguard: warning: --json {path}: could not write it ({reason}); the results"
    try:
        handle, name = tempfile.mkstemp(prefix=f"specguard-{path.stem}-", suffix=".json")
        with os.fdopen(handle, "w", encoding="utf-8") as f:
            f.write(text)
    except OSError:
        print(f"{where} follow on stdout", file=sys.stderr)
        print(text)
        return
    print(f"{where} are in {name}", file=sys.stderr)


def _run_all(args: argparse.Namespace, specs: dict[str, Any], executor: Any) -> tuple[dict[str, Any], bool]:
    """Train and print every spec; returns the results as JSON data and whether one failed.

    Several specs on the local executor with the cache share one pool of training slots, and a slot one spec
    leaves idle trains the others' seeds ahead (:mod:`specguard.engine.ahead`), as ``pytest --goal-specs`` does.
    """
    from specguard.engine.run_spec import RunOptions, run_with
    from specguard.report.table import table
    from specguard.training.progress import print_event

    cache_dir = None if args.no_cache else args.cache_dir
    progress = None if args.quiet else print_event
    runs = {
        name: spec.as_run(
            args.budget_scale,
            checkpoints=args.checkpoints,
            undecided=args.undecided,
            tensorboard_log=args.tensorboard_log,
            numerics=args.numerics,
        )
        for name, spec in specs.items()
    }
    results = {}
    failed = False
    with _ahead(runs, executor, cache_dir, progress) as (executor, ahead):
        for name, spec in runs.items():
            options = RunOptions(args.workers, cache_dir, progress, executor=executor, ahead=ahead)
            result = run_with(spec, options)
            results[name] = result.to_dict()
            print(f"== {name}: {result.status()} ({result.seconds:.1f}s)")
            print(table(result))
            print()
            failed = failed or not result.as_expected
    return results, failed


@contextmanager
def _ahead(runs: dict[str, Any], executor: Any, cache_dir: Any, progress: Any) -> Iterator[tuple[Any, Any]]:
    """The executor and the runs trained ahead for ``runs``: slots of the local executor's size, every spec planned
    on them (the foreground takes its own as it comes to it); ``executor`` alone with one spec, no cache or a
    cluster."""
    from specguard.parallel.executors import LocalExecutor

    if len(runs) < 2 or cache_dir is None or not isinstance(executor, LocalExecutor):
        yield executor, None
        return
    from specguard.cache.store import Cache
    from specguard.engine.ahead import TrainAhead
    from specguard.parallel.slots import PooledExecutor, SlotPool

    pool = SlotPool(executor.workers)
    ahead = TrainAhead(pool, Cache(Path(cache_dir)), say=progress)
    try:
        ahead.plan(list(runs.values()))
        yield PooledExecutor(pool), ahead
    finally:
        try:
            ahead.close()
        finally:
            pool.close()


_T = TypeVar("_T")


def _option(parse: Callable[[str], _T]) -> Callable[[str], _T]:
    """An option's argparse type from its shared check (:mod:`specguard.utils.parsing` and the rules built on it).

    The check's message (a ``ValueError``'s, or a ``SpecError``'s without where
    and hint) becomes argparse's usage error: ``argument --NAME: <message>``, exit status 2.
    """

    def convert(text: str) -> _T:
        try:
            return parse(text)
        except InvalidSpec as e:
            raise argparse.ArgumentTypeError(e.message) from None
        except ExecutorError as e:
            raise argparse.ArgumentTypeError(e.message.removeprefix("executor: ")) from None
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    convert.__name__ = getattr(parse, "__name__", "value")  # argparse names a type by it
    return convert


def _parse_undecided(text: str) -> str:
    return parse_choice(text, UNDECIDED_OUTCOMES)


def _parse_spread(text: str) -> float:
    """A standard deviation of per-seed success: a finite number in (0, 0.5)."""
    value = parse_positive(text, "a standard deviation of success, below 0.5")
    if value >= 0.5:
        raise ValueError(f"expected a standard deviation of success below 0.5, got {text!r}")
    return value


def _parse_case_scale(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise ValueError(f"expected CASE=X, e.g. lunar_lander=0.5, got {text!r}")
    return name, parse_positive(value)


_workers = _option(parse_workers)
_executor = _option(check_address)
_checkpoints = _option(parse_checkpoints)
_undecided = _option(_parse_undecided)
_scale = _option(parse_positive)
_spread = _option(_parse_spread)
_positive = _option(parse_count)
_case_scale = _option(_parse_case_scale)


def _natural(meaning: str) -> Callable[[str], int]:
    """An option's type: an integer >= 0 (:func:`specguard.utils.parsing.parse_natural`); ``meaning`` names it."""

    def natural(text: str) -> int:
        return parse_natural(text, meaning)

    return _option(natural)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="specguard",
        description="Goal-tree specifications for RL: show a spec, plan what its gate can see, run (train and "
        "judge) it, reproduce the case studies, falsify a trained spec, check an agent trained elsewhere.",
    )
    parser.add_argument("--version", action="version", version=f"specguard {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    show = sub.add_parser(
        "show",
        help="print the tree, reward formula, observation layout and budget of specs in a file "
        "(a pytest goal-spec file too), training nothing",
    )
    show.add_argument("target", metavar="PATH[::NAME]")
    from specguard.stats.power import DEFAULT_SPREAD
    from specguard.stats.sequential import DEFAULT_COMPARE_SEEDS

    plan = sub.add_parser(
        "plan",
        help="print what each spec's gate can see, training nothing: the chance a run is judged met around each "
        "threshold, and the smallest drop a comparison with a baseline flags with 80%% power",
    )
    plan.add_argument("target", metavar="PATH[::NAME]")
    plan.add_argument(
        "--spread",
        type=_spread,
        default=DEFAULT_SPREAD,
        metavar="S",
        help=f"seed-to-seed spread of success (standard deviation of per-seed success) to assume "
        f"(default: {DEFAULT_SPREAD:g})",
    )
    plan.add_argument(
        "--compare-seeds",
        type=_positive,
        default=DEFAULT_COMPARE_SEEDS,
        metavar="N",
        help=f"the most seeds a comparison trains and a saved baseline stores, as --goal-specs-compare-seeds "
        f"(default {DEFAULT_COMPARE_SEEDS}, or a spec's max_seeds if more)",
    )
    plan.add_argument(
        "--comparisons",
        type=_positive,
        default=None,
        metavar="N",
        help="comparisons in a session, over which the family-wise 5%% is shared (default: the thresholded "
        "goals and safety rates of the specs planned)",
    )
    run = sub.add_parser("run", help="train specs within their budgets and print per-goal verdicts")
    run.add_argument("target", metavar="PATH[::NAME]")
    run.add_argument(
        "--workers",
        type=_workers,
        default="auto",
        help="parallel training processes (default: auto, one per usable core)",
    )
    run.add_argument("--cache-dir", default=DEFAULT_CACHE_DIR, help=f"run cache (default: {DEFAULT_CACHE_DIR})")
    run.add_argument("--no-cache", action="store_true", help="neither read nor write the cache")
    run.add_argument(
        "--tensorboard-log",
        metavar="DIR",
        default=None,
        help="write TensorBoard logs of every training run here (SB3's curves and each goal's success), one "
        "subfolder per spec and seed; runs found in the cache train nothing and write nothing",
    )
    run.add_argument("--budget-scale", type=_scale, default=1.0, help="multiply training timesteps, e.g. 0.25")
    run.add_argument(
        "--checkpoints",
        type=_checkpoints,
        default=None,
        metavar="N",
        help="judge each run at N checkpoints and stop its training once every threshold is met "
        "(anytime verdicts; default: the spec's own Budget.checkpoints, 10 unless set; 1: the whole budget)",
    )
    run.add_argument(
        "--undecided",
        type=_undecided,
        default=None,
        help="what a goal whose runs stayed undecided counts as: fail, xfail or pass "
        "(default: the spec's own Spec.undecided, fail unless set)",
    )
    run.add_argument(
        "--numerics",
        choices=NUMERICS,
        default=None,
        help="what runs compute with: portable (kernels every x86-64 CPU computes alike: the same weights and "
        "verdicts on any machine) or native (this CPU's own, machine-dependent); default: the spec's own "
        "Spec.numerics, portable unless set",
    )
    run.add_argument("--json", metavar="FILE", help="also write the results as JSON (missing directories are created)")
    run.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    run.add_argument(
        "--executor",
        type=_executor,
        default="local",
        metavar="ADDRESS",
        help="where runs train: local (default; --workers processes here) or a Dask scheduler, tcp://host:8786",
    )
    rep = sub.add_parser(
        "reproduce",
        help="train every spec of the case-study files on N seeds at their whole budget; write a Markdown "
        "table beside the paper's figures and plots of success over training",
    )
    rep.add_argument("targets", metavar="PATH", nargs="*", help="case-study files (their specs and PAPER figures)")
    rep.add_argument(
        "--replot",
        action="store_true",
        help="train nothing: redraw the plots beside --out from the curve data written with them",
    )
    rep.add_argument("--seeds", type=_positive, default=5, help="seeds per spec (default: 5)")
    rep.add_argument("--budget-scale", type=_scale, default=1.0, help="multiply training timesteps, e.g. 0.5")
    rep.add_argument(
        "--case-scale",
        type=_case_scale,
        action="append",
        default=[],
        metavar="CASE=X",
        help="another budget scale for one case (its file's stem), e.g. lunar_lander=0.5; repeatable",
    )
    rep.add_argument(
        "--workers", type=_workers, default="auto", help="specs trained at once, one process each (default: auto)"
    )
    rep.add_argument(
        "--cache-dir", default=DEFAULT_CACHE_DIR, help=f"run cache, to resume (default: {DEFAULT_CACHE_DIR})"
    )
    rep.add_argument("--out", default="docs/reproduction.md", help="the Markdown file; plots go to images/ beside it")
    rep.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    _add_falsify(sub)
    _add_check(sub)
    return parser


def _wrap(args: argparse.Namespace) -> Callable[[Any], Any] | None:
    """``--wrap FILE.py::NAME``'s function, or ``None``."""
    from specguard.agents.sources import named_object

    if args.wrap is None:
        return None
    if args.agent is None:
        raise SpecError(f"--wrap names the --agent's wrappers, and no --agent is given (--wrap {args.wrap})", hint=None)
    wrap = named_object(args.wrap, "wrap", example="wrappers.py::stacked")
    if not callable(wrap):
        raise SpecError(f"wrap {args.wrap!r}: expected a function env -> env, got a {type(wrap).__name__}", hint=None)
    return wrap  # type: ignore[no-any-return]


def _add_agent(parser: argparse.ArgumentParser, *, required: bool, instead: str = "") -> None:
    """The options naming an agent trained elsewhere and what it sees: ``--agent``, ``--algorithm``,
    ``--observation`` (``check``'s and ``falsify``'s)."""
    from specguard.engine.check_agent import AGENT_OBSERVATIONS

    parser.add_argument(
        "--agent",
        required=required,
        default=None,
        help="the agent: an SB3 or sb3-contrib .zip, an rl-zoo3 or Hugging Face Hub folder, or FILE.py::NAME, a "
        "policy (a callable obs -> action, or an object with predict) defined in a Python file" + instead,
    )
    parser.add_argument("--algorithm", default=None, help="the zip's algorithm, e.g. PPO (default: read from the file)")
    parser.add_argument(
        "--wrap",
        default=None,
        metavar="FILE.py::NAME",
        help="the observation wrappers the agent was trained with: a function env -> env defined in a Python file "
        "(default: those an rl-zoo3 config.yml names, frame_stack and env_wrapper)",
    )
    parser.add_argument(
        "--trust-agent",
        action="store_true",
        help="run the code the agent's files may hold (a zip's pickled fields, a vecnormalize.pkl), as SB3's load "
        "does; by default they are decoded without running any (arrays, spaces, SB3's own classes) and a file that "
        "needs more is refused, naming the field",
    )
    parser.add_argument(
        "--observation",
        choices=AGENT_OBSERVATIONS,
        default="env",
        help="what the agent sees: env, the initial env's own observation (default), or spec, the constructed env's",
    )


def _add_check(sub: Any) -> None:
    ck = sub.add_parser(
        "check",
        help="judge an agent trained elsewhere (a saved model, an rl-zoo3 or Hub folder) against specs, "
        "training nothing",
    )
    ck.add_argument("target", metavar="PATH[::NAME]")
    _add_agent(ck, required=True)
    ck.add_argument(
        "--against",
        default=None,
        metavar="OLD",
        help="gate the agent against the one it replaces, on the same episodes: exit 1 also when a goal or safety "
        "rate dropped (exact one-sided McNemar test, Holm's procedure at family-wise 5%%)",
    )
    ck.add_argument(
        "--episodes",
        type=_positive,
        default=None,
        metavar="N",
        help="evaluation episodes of the first stage (default: the spec's Budget.eval_episodes)",
    )
    ck.add_argument(
        "--max-episodes",
        type=_positive,
        default=None,
        metavar="N",
        help="the most evaluation episodes, doubled up to while a goal is undecided "
        "(default: the spec's Budget.max_eval_episodes)",
    )
    ck.add_argument(
        "--seed", type=_natural("the evaluation seeds' run"), default=0, help="which evaluation seeds (default: 0)"
    )
    ck.add_argument(
        "--undecided",
        type=_undecided,
        default=None,
        help="what a goal still undecided counts as: fail, xfail or pass (default: the spec's own Spec.undecided)",
    )
    ck.add_argument("--cache-dir", default=DEFAULT_CACHE_DIR, help=f"evaluation cache (default: {DEFAULT_CACHE_DIR})")
    ck.add_argument("--no-cache", action="store_true", help="neither read nor write the cache")
    ck.add_argument("--json", metavar="FILE", help="also write the results as JSON (missing directories are created)")


def _add_falsify(sub: Any) -> None:
    from specguard.falsify.robustness import SCORES

    fz = sub.add_parser(
        "falsify",
        help="search a spec's start space for starts from which its trained agents (or --agent) miss the spec",
    )
    fz.add_argument("target", metavar="PATH[::NAME]")
    _add_agent(fz, required=False, instead="; default: the spec's own trained runs")
    fz.add_argument("--seed", type=_natural("the search's seed"), default=0, help="the search's seed (default: 0)")
    fz.add_argument("--examples", type=_positive, default=200, help="guided episodes per run at most (default: 200)")
    fz.add_argument(
        "--uniform",
        type=_natural("uniform draws"),
        default=100,
        help="uniform draws for the failure rate, 0 for none (default: 100)",
    )
    fz.add_argument(
        "--score",
        choices=SCORES,
        default="last",
        help="the score that steers the search: last, each key's margin in the episode's last state (default), or "
        "episode, over the whole episode (signal temporal logic's; dearer per episode)",
    )
    fz.add_argument(
        "--starts",
        type=_start_range,
        nargs="+",
        metavar="NAME=LO:HI",
        help="start ranges of the env's state variables (default: the spec's own, Spec.starts, else the env's)",
    )
    fz.add_argument(
        "--cache-dir",
        default=DEFAULT_CACHE_DIR,
        help=f"run cache, and its falsify/ the counterexamples (default: {DEFAULT_CACHE_DIR})",
    )
    fz.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def _start_range(text: str) -> tuple[str, tuple[float, float]]:
    """``--starts NAME=LO:HI`` (e.g. ``theta=-0.1:0.1``)."""
    name, _, rng = text.partition("=")
    lo, _, hi = rng.partition(":")
    try:
        return name.strip(), (float(lo), float(hi))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=LO:HI, e.g. theta=-0.1:0.1, got {text!r}") from None


def _falsify(args: argparse.Namespace) -> int:
    """Train (or find in the cache) each spec, then search its start space for counterexamples, per run; with
    ``--agent``, the agent's instead, training nothing."""
    from specguard.engine.falsify_run import falsify_agent, falsify_runs, start_space
    from specguard.engine.run_spec import run_spec
    from specguard.starts.space import StartSpace
    from specguard.training.progress import print_event

    starts = StartSpace(check_unique("--starts", args.starts)) if args.starts else None  # None: the spec's own
    found_any = False
    specs = _specs(args.target, "falsify")
    for spec in specs.values():  # names and bounds checked before anything trains
        start_space(spec, starts).resolve(spec.initial_env.make())
    say = None if args.quiet else (lambda line: print(f"[specguard] {line}", file=sys.stderr))
    if args.agent is None and args.algorithm is not None:
        raise SpecError("falsify: --algorithm names the --agent's algorithm, and no --agent is given", hint=None)
    for name, spec in specs.items():
        if args.agent is not None:
            f = falsify_agent(
                spec,
                args.agent,
                starts,
                examples=args.examples,
                uniform=args.uniform,
                search_seed=args.seed,
                database=Path(args.cache_dir) / "falsify",
                progress=say,
                observation=args.observation,
                algorithm=args.algorithm,
                score=args.score,
                trust=args.trust_agent,
                wrap=_wrap(args),
            )
            print(f"== {name} agent {args.agent}: {'COUNTEREXAMPLE' if f.found else 'none found'}")
            print(f.report())
            print()
            found_any = found_any or f.found
            continue
        quiet = args.quiet
        result = run_spec(spec, cache_dir=args.cache_dir, progress=None if quiet else print_event)
        found = falsify_runs(
            result,
            starts,
            examples=args.examples,
            uniform=args.uniform,
            search_seed=args.seed,
            progress=say,
            score=args.score,
        )
        for seed, f in found.items():
            print(f"== {name} seed {seed}: {'COUNTEREXAMPLE' if f.found else 'none found'}")
            print(f.report())
            print()
            found_any = found_any or f.found
    return 1 if found_any else 0


def _check(args: argparse.Namespace) -> int:
    """Judge the agent against each spec, training nothing; 1 when a spec failed."""
    from specguard.engine.check_agent import check_agent
    from specguard.gate.agent_gate import compare_agents
    from specguard.report.table import table

    specs = _specs(args.target, "check")
    for name, spec in specs.items():  # before any episode: a spec with nothing to assert has no verdict
        require_thresholds(f"{args.target.partition('::')[0]}::{name}", spec.thresholds)
    json_path = _prepare_json(args.json) if args.json else None
    results = {}
    failed = False
    for name, spec in specs.items():
        options = {
            "episodes": args.episodes,
            "max_episodes": args.max_episodes,
            "observation": args.observation,
            "seed": args.seed,
            "algorithm": args.algorithm,
            "trust": args.trust_agent,
            "wrap": _wrap(args),
        }
        run = spec.as_run(undecided=args.undecided)
        if args.against is None:
            result = check_agent(run, args.agent, cache_dir=None if args.no_cache else args.cache_dir, **options)
            results[name] = result.to_dict()
        else:
            comparison = compare_agents(run, args.agent, args.against, **options)
            result = comparison.result
            results[name] = {**result.to_dict(), "comparison": comparison.to_dict()}
        print(f"== {name}: {result.status()} ({result.seconds:.1f}s)")
        print(table(result))
        if args.against is not None:
            print(f"-- against {args.against}: {'DROPPED' if comparison.dropped else 'passed'}")
            print(_comparison_table(comparison))
            print(comparison.summary())
        print()
        # one rule with the Python object: AgentComparison.passed is the check as expected and nothing dropped
        failed = failed or not (result.as_expected if args.against is None else comparison.passed)
    if json_path is not None:
        _write_results(json_path, json.dumps(results, indent=1))
    return 1 if failed else 0


def _comparison_table(comparison: Any) -> str:
    """Per goal and safety rate: the old and new agents' successes, the drop's bound, the p-value, the state."""
    from specguard.tree.keys import label

    rows = [("goal", "old", "new", "lost/gained", "drop <=", "p", "state")]
    for key, k in comparison.keys.items():
        rows.append(
            (
                label(key),
                f"{k.old}/{k.episodes}",
                f"{k.new}/{k.episodes}",
                f"{k.lost}/{k.gained}",
                f"{k.bound:+.1%}",
                f"{k.p_value:.3g}",
                k.state.value,
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows)


def _reproduce(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from specguard.engine.reproduce import load_case, reproduce
    from specguard.parallel.workers import resolve_workers
    from specguard.report.reproduction import replot, write_markdown
    from specguard.training.progress import print_event

    if args.replot:
        if args.targets:
            raise SpecError("reproduce --replot trains nothing: give no case files", hint="drop the PATHs")
        drawn = replot(Path(args.out).parent / "images")
        print(f"redrew {len(drawn)} plots: " + ", ".join(str(p) for p in drawn) if drawn else "no curve data found")
        return 0
    if not args.targets:
        raise SpecError("reproduce: expected at least one case-study file", hint="e.g. example_specs/pendulum.py")

    cases = [load_case(path) for path in args.targets]
    command = "specguard " + " ".join(argv)
    result = reproduce(
        cases,
        seeds=args.seeds,
        budget_scale=args.budget_scale,
        case_scales=dict(args.case_scale),
        workers=resolve_workers(args.workers),
        cache_dir=args.cache_dir,
        progress=None if args.quiet else print_event,
        command=command,
    )
    out = write_markdown(result, Path(args.out))
    print(f"wrote {out} and its plots")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    try:
        if args.command == "show":
            return _show(args.target)
        if args.command == "reproduce":
            return _reproduce(args, argv)
        if args.command == "falsify":
            return _falsify(args)
        if args.command == "plan":
            return _plan(args)
        if args.command == "check":
            return _check(args)
        return _run(args)
    except SpecError as e:
        print(f"specguard: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("specguard: interrupted; finished runs are cached, unfinished ones were not stored", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
