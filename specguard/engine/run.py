"""Running a spec: seeds in parallel processes, sequential seeds, per-goal verdicts.

``run_spec`` trains ``budget.min_seeds`` runs (in parallel worker processes,
each with one torch thread), judges every thresholded goal and safety rate
(keys of :mod:`specguard.tree.keys`), and trains further seeds, up to
``budget.max_seeds``, only while some quorum is still open.
Runs come from the cache when an identical run was trained before
(:mod:`specguard.engine.cache`).

Example:
    >>> import specguard as sg
    >>> from example_specs import pendulum
    >>> spec = sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(timesteps=100_000))
    >>> result = sg.run_spec(spec, workers=2)  # doctest: +SKIP
    >>> print(result.table())  # doctest: +SKIP
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

from specguard.engine.cache import Cache, try_acquire, wait_for
from specguard.engine.executors import LOCAL, Executor, make_executor
from specguard.engine.fingerprint import check_versions, fingerprint_spec, versions
from specguard.engine.progress import ProgressEvent, decode_update, print_event
from specguard.engine.spec import Spec
from specguard.engine.train import RunResult, TrainingError
from specguard.engine.workers import Failure, Outcome, Report, Task, resolve_workers
from specguard.error import SpecError
from specguard.stats.intervals import QuorumVerdict, RunVerdict, quorum_verdict, run_verdict, success_interval
from specguard.tree.keys import GOAL, kind, label, result_keys
from specguard.utils.text import render_table, weights_text

__all__ = ["GoalVerdict", "SpecResult", "resolve_workers", "run_spec"]

Progress = Callable[[ProgressEvent], None]


@dataclass
class GoalVerdict:
    """One goal (or safety rate) of a spec against its threshold, over all runs.

    Attributes:
        path: the node path, or for a safety rate its key ``path:name``.
        threshold: the minimum success asked for.
        required: runs that must meet it.
        runs: each run's verdict, by seed order.
        verdict: passed, failed, or open (more runs could still decide it).
        successes, episodes: pooled over runs (for a safety rate: episodes without a violation).
        interval: the pooled success rate's confidence interval.
    """

    path: str
    threshold: float
    required: int
    runs: list[RunVerdict]
    verdict: QuorumVerdict
    successes: int
    episodes: int
    interval: tuple[float, float]

    @property
    def success(self) -> float:
        return self.successes / self.episodes if self.episodes else 0.0


@dataclass
class SpecResult:
    """Everything ``run_spec`` measured; ``to_dict()`` is JSON-serialisable."""

    spec: str
    runs: list[RunResult]
    goals: dict[str, GoalVerdict]
    errors: dict[int, str] = field(default_factory=dict)
    tracebacks: dict[int, str] = field(default_factory=dict)  # the worker's, per failed seed (shown under -v)
    cached: dict[int, bool] = field(default_factory=dict)
    seconds: float = 0.0
    confidence: float = 0.95
    spec_key: str | None = None
    trained: Spec | None = field(default=None, repr=False, compare=False)  # the spec as run, for model()/rollout()
    cache_dir: Path | None = field(default=None, repr=False, compare=False)

    @property
    def passed(self) -> bool:
        """No seed failed and every thresholded goal passed."""
        return not self.errors and all(g.verdict is QuorumVerdict.PASSED for g in self.goals.values())

    @property
    def as_expected(self) -> bool:
        """No seed failed and every thresholded goal passed, except goals the spec expects to miss (``xfail``)."""
        xfail = self.trained.xfail if self.trained is not None else {}
        return not self.errors and all(g.verdict is QuorumVerdict.PASSED or p in xfail for p, g in self.goals.items())

    def model(self, seed: int) -> Any:
        """The trained SB3 model of run ``seed`` (loaded from the cache, after its checksums are verified).

        Raises:
            SpecError: the run was not cached (``cache_dir=None``) or is gone.
        """
        return self._load(seed)[0]

    def rollout(self, seed: int, episodes: int = 1, *, deterministic: bool = True) -> list[list[dict[str, Any]]]:
        """Episodes of run ``seed``'s policy on its env, seeded as evaluation episodes are.

        Returns:
            One list of steps per episode: ``{"obs", "action", "reward",
            "terminated", "truncated", "info"}`` with ``info["goals"]``.

        Example:
            >>> result = goal_spec_result(spec)  # doctest: +SKIP
            >>> last = result.rollout(0, episodes=1)[0][-1]  # doctest: +SKIP
            >>> assert last["info"]["goals"]["pendulum/stabilization"]  # doctest: +SKIP
        """
        from specguard.engine.rollout import rollout

        model, normalizer = self._load(seed)
        assert self.trained is not None
        return rollout(model, self.trained, episodes=episodes, deterministic=deterministic, normalizer=normalizer)

    def _load(self, seed: int) -> tuple[Any, Any]:
        from specguard.engine.rollout import load_model

        if self.trained is None or self.cache_dir is None:
            raise SpecError(
                f"Spec {self.spec!r}: no model kept for seed {seed}: the runs were not cached",
                hint="run with a cache (the default) to reach trained models",
            )
        try:
            return load_model(self.trained, seed, self.cache_dir)
        except FileNotFoundError as e:
            raise SpecError(f"Spec {self.spec!r}: {e}", hint="train it again: its cache entry is gone") from None

    def success(self, path: str) -> tuple[int, int]:
        """Pooled ``(successes, episodes)`` of a goal (or safe episodes of a safety key) over all runs."""
        return sum(r.successes[path] for r in self.runs), sum(r.episodes for r in self.runs)

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.spec,
            "passed": self.passed,
            "seconds": self.seconds,
            "runs": [r.to_dict() for r in self.runs],
            "goals": {p: {**asdict(g), "kind": kind(p)} for p, g in self.goals.items()},
            "errors": {str(k): v for k, v in self.errors.items()},
            "cached": {str(k): v for k, v in self.cached.items()},
            "confidence": self.confidence,
            "spec_key": self.spec_key,
        }

    def table(self) -> str:
        """A per-goal table: pooled success with interval, threshold, runs, verdict.

        Goals first, then the safety rates, labelled ``path:name (safe)``.
        """
        paths = [p for r in self.runs[:1] for p in r.successes] or list(self.goals)
        paths.sort(key=lambda p: kind(p) != GOAL)  # stable: each kind keeps its order
        header = ("goal", "success", f"{self.confidence:.0%} interval", "threshold", "runs met", "verdict")
        rows = []
        for p in paths:
            k, n = self.success(p)
            rate = f"{k / n:.0%} ({k}/{n})" if n else "-"
            iv = "-" if not n else "[{:.2f}, {:.2f}]".format(*success_interval(k, n, self.confidence))
            g = self.goals.get(p)
            met = "-" if g is None else f"{g.runs.count(RunVerdict.MET)}/{len(g.runs)} (need {g.required})"
            threshold = "-" if g is None else f">= {g.threshold:g}"
            rows.append((label(p), rate, iv, threshold, met, "-" if g is None else g.verdict.value))
        lines = render_table(header, rows)
        for run in self.runs:
            if run.weights:
                lines.append(f"seed {run.seed} adapted weights: {weights_text(run.weights)}")
        for seed, message in self.errors.items():
            lines.append(f"seed {seed} failed: {message}")
        return "\n".join(lines)


def _train_task(spec: Spec, seed: int, keyed_versions: Mapping[str, str] | None, *, report: Report) -> dict[str, Any]:
    """A worker's task (a local process or a cluster worker): train one seed, return its result and model bytes.

    The driver stores them in its cache: keys are computed only by the driver
    (functions unpickled in a worker are not the driver's), and cluster
    workers need no shared filesystem. ``keyed_versions``, given when the
    result is to be cached, are the versions the driver's key names: a worker
    with other code refuses to train (:class:`~specguard.error.VersionMismatch`).
    """
    from specguard.engine.cache import model_files
    from specguard.engine.train import train_run

    if keyed_versions is not None:
        check_versions(keyed_versions, f"Spec {spec.label!r}, seed {seed}")
    with_model = keyed_versions is not None
    result, model = train_run(spec, seed, report=report)
    files = model_files(model, normalize=spec.normalize) if with_model else {}
    return {"result": result.to_dict(), "files": files}


_PHASES = {"start": "starting", "build": "building the env", "train": "training step", "evaluate": "evaluation episode"}


def _describe_failure(seed: int, failure: Failure) -> str:
    """One line: the seed, where the run was, and why it failed."""
    if isinstance(failure.exception, TrainingError):
        return failure.exception.message  # already names the seed, the phase and the step (the hint is generic)
    where = _PHASES.get(failure.phase, failure.phase)
    step = "" if failure.step is None or failure.phase not in ("train", "evaluate") else f" {failure.step}"
    return f"seed {seed}, {where}{step}: {failure.cause}"


def _is_spec_error(failure: Failure) -> bool:
    """A mistake in the spec itself (e.g. rejected hyperparameters): every seed would hit it, so stop all."""
    return isinstance(failure.exception, SpecError) and not isinstance(failure.exception, TrainingError)


def _judge(spec: Spec, runs: list[RunResult], failed_seeds: int) -> dict[str, GoalVerdict]:
    assert spec.budget.max_seeds is not None
    goals = {}
    for path, threshold in spec.thresholds.items():
        verdicts = [run_verdict(r.successes[path], r.episodes, threshold, spec.verdict_confidence) for r in runs]
        counted = [RunVerdict.MET if (v is RunVerdict.UNDECIDED and spec.undecided == "pass") else v for v in verdicts]
        counted += [RunVerdict.MISSED] * failed_seeds  # a run that crashed met nothing
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


def _still_needed(spec: Spec, goals: dict[str, GoalVerdict], done: int) -> int:
    """How many more runs could still change an open verdict (0 when every goal is settled)."""
    assert spec.budget.max_seeds is not None
    open_goals = [g for g in goals.values() if g.verdict is QuorumVerdict.OPEN]
    if done < spec.budget.min_seeds:
        return spec.budget.min_seeds - done
    if not open_goals:
        return 0
    missing = max(g.required - g.runs.count(RunVerdict.MET) for g in open_goals)
    return min(missing, spec.budget.max_seeds - done)


class _Runs:
    """The seeds of one ``run_spec`` call: looked up in the cache, locked, trained in workers, recorded."""

    def __init__(
        self,
        spec: Spec,
        result: SpecResult,
        cache: Cache | None,
        executor: Executor,
        lock_timeout: float,
        say: Progress,
    ) -> None:
        self.spec = spec
        self.result = result
        self.cache = cache
        self.executor = executor
        self.lock_timeout = lock_timeout
        self.say = say
        self.paths = result_keys(spec.tree)  # what a cached run must have measured
        self.fingerprint = None if cache is None else fingerprint_spec(spec)
        if self.fingerprint is not None and not self.fingerprint.reproducible:
            self.cache = None

    def _key(self, seed: int) -> str | None:
        return None if self.fingerprint is None or self.cache is None else self.fingerprint.run_key(seed)

    def _hit(self, seed: int) -> bool:
        key = self._key(seed)
        if key is None or self.cache is None:
            return False
        run = self.cache.load_key(key, seed=seed, paths=self.paths)
        if run is None:
            return False
        run.spec = self.spec.label  # the label is not part of a run's key
        self.result.runs.append(run)
        self.result.cached[seed] = True
        self._event(seed, "cached", run, message=self._rates(run))
        return True

    def run(self, seeds: list[int]) -> None:
        """Get every seed's run: from the cache, from another process training it, or trained here."""
        locks: dict[int, Any] = {}
        busy: list[int] = []
        try:
            todo = []
            for seed in seeds:
                if self._hit(seed):
                    continue
                key = self._key(seed)
                if key is not None and self.cache is not None:
                    lock = self.cache.lock(key, self.lock_timeout)
                    if not try_acquire(lock):
                        busy.append(seed)  # another process trains it: take it from the cache when it is done
                        continue
                    locks[seed] = lock
                    if self._hit(seed):  # stored while we looked
                        continue
                todo.append(seed)
            self._train(todo)
            for seed in busy:
                key = self._key(seed)
                assert key is not None and self.cache is not None
                lock = self.cache.lock(key, self.lock_timeout)
                if not try_acquire(lock):
                    self.say(ProgressEvent(self.spec.label, seed, "waiting"))
                    wait_for(lock, f"Spec {self.spec.label!r}, seed {seed}", self.lock_timeout)
                locks[seed] = lock
                if not self._hit(seed):
                    self._train([seed])  # the other process failed or did not store it
        finally:
            for lock in locks.values():
                lock.release()

    def _train(self, seeds: list[int]) -> None:
        if not seeds:
            return
        tasks = []
        keyed = versions() if self.fingerprint is not None and self.cache is not None else None
        for seed in seeds:
            self.say(ProgressEvent(self.spec.label, seed, "start", budget=self.spec.budget.timesteps))
            tasks.append(Task(seed, _train_task, (self.spec, seed, keyed)))
        trained: dict[int, RunResult] = {}

        def finished(seed: int, outcome: Outcome) -> None:
            # As each seed ends, not after the batch: a finished run is stored even if a later seed
            # is interrupted (Ctrl-C, SIGTERM) or the spec is stopped.
            if isinstance(outcome, Failure):
                if not _is_spec_error(outcome):  # a spec error is raised below, once every child has stopped
                    self.result.errors[seed] = _describe_failure(seed, outcome)
                    if outcome.traceback:
                        self.result.tracebacks[seed] = outcome.traceback
                    self.say(ProgressEvent(self.spec.label, seed, "failed", message=self.result.errors[seed]))
                return
            run = RunResult(**outcome.value["result"])
            key = self._key(seed)
            if key is not None and self.cache is not None:
                self.cache.store_files(key, run, outcome.value["files"])
            trained[seed] = run
            self._event(seed, "done", run, message=self._rates(run))

        outcomes = self.executor.run(
            tasks,
            on_line=lambda seed, line: self.say(decode_update(self.spec.label, seed, line)),
            stop_on=_is_spec_error,
            on_outcome=finished,
        )
        for outcome in outcomes.values():
            if isinstance(outcome, Failure) and _is_spec_error(outcome):
                assert outcome.exception is not None
                if outcome.traceback:
                    outcome.exception.add_note(f"worker traceback (seed {outcome.key}):\n{outcome.traceback}")
                raise outcome.exception
        for seed in outcomes:  # the runs in seed order, whatever order they finished in
            if seed in trained:
                self.result.runs.append(trained[seed])
                self.result.cached[seed] = False

    @staticmethod
    def _rates(run: RunResult) -> str:
        return ", ".join(f"{label(p)} {c}/{run.episodes}" for p, c in run.successes.items())

    def _event(self, seed: int, kind: Literal["done", "cached"], run: RunResult, message: str) -> None:
        """A finished run's event: its steps, training time and the root goal's evaluation success."""
        root = next(iter(run.successes.values()), None)
        self.say(
            ProgressEvent(
                self.spec.label,
                seed,
                kind,
                steps=run.timesteps,
                budget=self.spec.budget.timesteps,
                elapsed_s=run.train_seconds,
                success=None if root is None or not run.episodes else root / run.episodes,
                episodes=run.episodes,
                message=("thresholds met at a checkpoint | " if run.met_early else "") + message,
            )
        )


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


def run_spec(
    spec: Spec,
    *,
    workers: int | str = "auto",
    cache_dir: str | Path | None = ".specguard/cache",
    progress: Progress | None = print_event,
    lock_timeout: float = 3600.0,
    executor: str | Executor = LOCAL,
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
        progress: called with a :class:`~specguard.engine.progress.ProgressEvent` per
            seed's start, tenth of training, end, cache hit, failure or wait
            (``format_event`` or ``str(event)`` makes it a line); ``None`` for silence.
        lock_timeout: seconds to wait for another process training the same run.
        executor: ``"local"`` (a process per seed on this machine, ``workers``
            at once), a Dask scheduler address (``"tcp://host:8786"``), or an
            :class:`~specguard.engine.executors.Executor`. The cache stays on this
            machine either way: only missing seeds are submitted.

    Returns:
        The runs, per-goal verdicts, errors by seed and which runs came from the cache.

    Raises:
        SpecError: the spec is invalid (also when a worker finds it so, e.g.
            rejected hyperparameters), or cannot be fingerprinted for the cache.
    """
    _refuse_in_spawned_import()
    say = progress or (lambda event: None)
    n_workers = resolve_workers(workers)
    cache = Cache(Path(cache_dir)) if cache_dir is not None else None
    start = time.perf_counter()
    result = SpecResult(spec=spec.label, runs=[], goals={}, confidence=spec.confidence, trained=spec)
    owned = isinstance(executor, str)
    runner = make_executor(executor, workers=n_workers) if isinstance(executor, str) else executor
    try:
        runs = _Runs(spec, result, cache, runner, lock_timeout, say)
        result.spec_key = None if runs.fingerprint is None else runs.fingerprint.spec_key
        result.cache_dir = None if runs.cache is None else runs.cache.root
        next_seed = 0
        while True:
            result.goals = _judge(spec, result.runs, len(result.errors))
            needed = _still_needed(spec, result.goals, len(result.runs) + len(result.errors))
            if needed == 0:
                break
            runs.run(list(range(next_seed, next_seed + needed)))
            next_seed += needed
            result.runs.sort(key=lambda r: r.seed)
    finally:
        if owned:
            runner.close()
    result.seconds = time.perf_counter() - start
    return result
