"""Running a spec: seeds in parallel processes, sequential seeds, per-goal verdicts.

``run_spec`` trains ``budget.min_seeds`` runs (in parallel worker processes,
each with one torch thread), judges every thresholded goal and safety rate
(keys of :mod:`specguard.tree.keys`), and trains further seeds, up to
``budget.max_seeds``, only while some quorum is still open.
Runs come from the cache when an identical run was trained before
(:mod:`specguard.cache.store`).

Example:
    >>> import specguard as sg
    >>> pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    >>> upright = sg.Goal("upright", x=(0.966, 1.0), y=(-0.259, 0.259), omega=(-0.25, 0.25))
    >>> spec = sg.Spec(pendulum, upright, budget=sg.Budget(timesteps=100_000), expect=0.8)
    >>> result = sg.run_spec(spec, workers=2)  # doctest: +SKIP
    >>> print(sg.table(result))  # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from specguard.cache.store import Cache
from specguard.engine.ahead import TrainAhead
from specguard.engine.judging import episode_notes, hints, judge, seeds_still_needed
from specguard.engine.seeds import Runs
from specguard.engine.spec_result import SpecResult
from specguard.error import SpecError
from specguard.parallel.executors import LOCAL, Executor, make_executor
from specguard.parallel.workers import resolve_workers
from specguard.spec.spec import Spec, check_spec
from specguard.training.progress import ProgressEvent, print_event
from specguard.utils.atomic import DEFAULT_CACHE_DIR

__all__ = ["RunOptions", "check_before_training", "run_spec", "run_with", "train_seeds"]

Progress = Callable[[ProgressEvent], None]


def _refuse_in_spawned_import() -> None:
    """Fail fast when a worker process re-imports the user's script and reaches its ``run_spec`` call.

    Workers are spawned: each imports the main script again (as ``__mp_main__``).
    A script calling ``run_spec`` outside ``if __name__ == "__main__":`` would
    have every worker start its own run and wait on the parent's cache lock forever.
    """
    import multiprocessing

    # The flag multiprocessing's own check for this mistake reads (spawn._check_not_importing_main).
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise SpecError(
            "run_spec was called while a worker process imported your script",
            hint='call it under `if __name__ == "__main__":` (worker processes import the script again)',
        )


@dataclass(frozen=True)
class RunOptions:
    """How one call trains a spec's seeds: :func:`run_spec`'s keyword arguments as one value (see them there).

    The pytest plugin makes one per session and passes it to :func:`run_with` and :func:`train_seeds`.
    ``ahead``: the session's runs trained ahead (:mod:`specguard.engine.ahead`), taken from there where planned.
    """

    workers: int | str = "auto"
    cache_dir: str | Path | None = DEFAULT_CACHE_DIR
    progress: Progress | None = print_event
    lock_timeout: float = 3600.0
    executor: str | Executor = LOCAL
    ahead: TrainAhead | None = None


def run_spec(
    spec: Spec,
    *,
    workers: int | str = "auto",
    cache_dir: str | Path | None = DEFAULT_CACHE_DIR,
    progress: Progress | None = print_event,
    lock_timeout: float = 3600.0,
    executor: str | Executor = LOCAL,
    tensorboard_log: str | os.PathLike[str] | None = None,
) -> SpecResult:
    """Train and judge ``spec`` within its budget.

    Each seed trains in a worker process of its own: a seed whose worker
    raises, is killed or dies is reported in ``errors`` with its phase and
    step, and the other seeds' results are kept and cached. ``KeyboardInterrupt``
    (SIGINT, or SIGTERM in the main thread) ends every worker and stores
    nothing partial.

    Args:
        spec: the spec.
        workers: parallel training processes (``"auto"``: the usable cores).
        cache_dir: where trained runs are kept and looked up; ``None`` disables the cache.
        progress: called with a :class:`~specguard.training.progress.ProgressEvent` per
            seed's start, tenth of training, end, cache hit, failure or wait
            (``format_event`` or ``str(event)`` makes it a line); ``None`` for silence.
        lock_timeout: seconds to wait for another process training the same run.
        executor: ``"local"`` (a process per seed on this machine, ``workers``
            at once), a Dask scheduler address (``"tcp://host:8786"``), or an
            :class:`~specguard.parallel.executors.Executor`. The cache stays on this
            machine either way: only missing seeds are submitted.
        tensorboard_log: a folder every run trained writes TensorBoard logs to (SB3's curves and each goal's
            success), one subfolder per spec and seed (:attr:`SB3.tensorboard_log <specguard.SB3>`); not part of
            the cache key: a run found in the cache trains nothing and writes nothing.

    Returns:
        The runs, per-goal verdicts, errors by seed and which runs came from the cache.

    Raises:
        SpecError: the spec is invalid (also when a worker finds it so, e.g.
            rejected hyperparameters), or cannot be fingerprinted for the cache.
    """
    if tensorboard_log is not None:
        spec = spec.as_run(tensorboard_log=tensorboard_log)
    return run_with(spec, RunOptions(workers, cache_dir, progress, lock_timeout, executor))


def run_with(spec: Spec, options: RunOptions) -> SpecResult:
    """:func:`run_spec` with its options as one :class:`RunOptions` value."""
    _refuse_in_spawned_import()
    check_before_training(spec)
    start = time.perf_counter()
    with _seeds_of(spec, options) as (runs, result):
        next_seed = 0
        while True:
            result.goals = judge(spec, result.runs, len(result.errors))
            needed = seeds_still_needed(spec, result.goals, len(result.runs) + len(result.errors))
            if needed == 0:
                break
            runs.run(list(range(next_seed, next_seed + needed)))
            next_seed += needed
            result.runs.sort(key=lambda r: r.seed)
    result.seconds = time.perf_counter() - start
    return result


def train_seeds(spec: Spec, seeds: Sequence[int], options: RunOptions = RunOptions()) -> SpecResult:
    """Train exactly ``seeds`` of ``spec`` (each from the cache when an identical run was stored), as ``run_spec`` does.

    For seeds beyond a spec's own: the extra seeds of a comparison with a baseline, and the
    seeds a saved baseline stores (:mod:`specguard.gate.comparison`). The result has runs and
    errors only: no verdicts (these seeds are beyond the spec's quorum).
    """
    _refuse_in_spawned_import()
    check_before_training(spec)
    start = time.perf_counter()
    with _seeds_of(spec, options) as (runs, result):
        runs.run(list(seeds))
        result.runs.sort(key=lambda r: r.seed)
    result.seconds = time.perf_counter() - start
    return result


def check_before_training(spec: Spec) -> None:
    """Build the spec's env once, here: every check of its construction runs in the caller's process, first.

    A spec refused (an unreachable goal, a root goal met at every start) is refused before any seed is
    submitted, whatever the door (the API, ``specguard run``, ``pytest --goal-specs``); its warnings (a root
    goal met at some starts) are given once, here, not by every worker.

    Raises:
        SpecError: the env cannot be built, or its construction refuses the spec.
    """
    check_spec(spec)


@contextlib.contextmanager
def _seeds_of(spec: Spec, options: RunOptions) -> Iterator[tuple[Runs, SpecResult]]:
    """The seeds of one call (cache, executor) and the result they fill; an executor made here is closed here."""
    say = options.progress or (lambda event: None)
    n_workers = resolve_workers(options.workers)
    cache = Cache(Path(options.cache_dir)) if options.cache_dir is not None else None
    executor = options.executor
    result = SpecResult(
        spec=spec.label,
        runs=[],
        goals={},
        confidence=spec.confidence,
        undecided=spec.undecided,
        xfail=dict(spec.xfail),
        trained=spec,
    )
    owned = isinstance(executor, str)
    runner = make_executor(executor, workers=n_workers) if isinstance(executor, str) else executor
    try:
        runs = Runs(spec, result, cache, runner, options.lock_timeout, say, options.ahead)  # its probes check envs
        result.spec_key = None if runs.fingerprint is None else runs.fingerprint.spec_key
        result.cache_dir = None if runs.cache is None else runs.cache.root
        yield runs, result
        result.notes = episode_notes(spec.tree, result.runs, ends_at_goal=not spec.baseline)
        result.hints = hints(spec, result)
    finally:
        if owned:
            runner.close()
