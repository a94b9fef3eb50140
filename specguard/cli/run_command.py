"""``specguard run PATH[::NAME]``: train the specs within their budgets and print each one's per-goal table; exit 1
when one failed. Several specs share one pool of training slots, and a slot one leaves idle trains the others' seeds
ahead (:mod:`specguard.engine.ahead`), as ``pytest --goal-specs`` does."""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from specguard.cli import arguments
from specguard.tree.keys import require_thresholds
from specguard.utils.atomic import DEFAULT_CACHE_DIR
from specguard.utils.numerics import NUMERICS

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    run = sub.add_parser("run", help="train specs within their budgets and print per-goal verdicts")
    run.add_argument("target", metavar="PATH[::NAME]")
    run.add_argument(
        "--workers",
        type=arguments.workers,
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
    run.add_argument("--budget-scale", type=arguments.scale, default=1.0, help="multiply training timesteps, e.g. 0.25")
    run.add_argument(
        "--checkpoints",
        type=arguments.checkpoints,
        default=None,
        metavar="N",
        help="judge each run at N checkpoints and stop its training once every threshold is met "
        "(anytime verdicts; default: the spec's own Budget.checkpoints, 10 unless set; 1: the whole budget)",
    )
    run.add_argument(
        "--undecided",
        type=arguments.undecided,
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
        type=arguments.executor,
        default="local",
        metavar="ADDRESS",
        help="where runs train: local (default; --workers processes here) or a Dask scheduler, tcp://host:8786",
    )


def run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from specguard.parallel.executors import make_executor
    from specguard.parallel.workers import resolve_workers

    specs = arguments.specs_of(args.target, "run")
    for name, spec in specs.items():  # before anything trains: a spec with nothing to assert has no verdict
        require_thresholds(f"{args.target.partition('::')[0]}::{name}", spec.thresholds)
    json_path = arguments.prepare_json(args.json) if args.json else None  # before training, which may take hours
    executor = make_executor(args.executor, workers=resolve_workers(args.workers))  # a cluster answers, or exit 2
    try:
        results, failed = _run_all(args, specs, executor)
    finally:
        executor.close()
    if json_path is not None:
        arguments.write_results(json_path, json.dumps(results, indent=1))
    return 1 if failed else 0


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
