"""The seeds of one ``run_spec`` call: looked up in the cache, locked, trained by an executor, stored as each ends."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any, Literal

from specguard.cache.fingerprint import fingerprint_spec
from specguard.cache.store import Cache, try_acquire, wait_for
from specguard.cache.versions import versions
from specguard.engine.ahead import TrainAhead, seed_task
from specguard.engine.spec_result import SpecResult
from specguard.engine.worker_task import describe_failure, is_spec_error
from specguard.error import CacheWarning
from specguard.parallel.executors import Executor
from specguard.parallel.protocol import Failure, TaskOutcome
from specguard.spec.spec import Spec
from specguard.training.progress import ProgressEvent, decode_update
from specguard.training.result import RunResult
from specguard.tree.keys import label, result_keys

__all__ = ["Runs"]

Progress = Callable[[ProgressEvent], None]


class Runs:
    """The seeds of one ``run_spec`` call: looked up in the cache, locked, trained in workers, recorded.

    ``ahead``: the session's runs trained ahead (:mod:`specguard.engine.ahead`); a seed planned there is taken from
    it, with its lock, and recorded as one trained here.
    """

    def __init__(
        self,
        spec: Spec,
        result: SpecResult,
        cache: Cache | None,
        executor: Executor,
        lock_timeout: float,
        say: Progress,
        ahead: TrainAhead | None = None,
    ) -> None:
        self.spec = spec
        self.result = result
        self.cache = cache
        self.executor = executor
        self.lock_timeout = lock_timeout
        self.say = say
        self.ahead = ahead
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
        """Get every seed's run: trained ahead, from the cache, from another process training it, or trained here."""
        locks: dict[int, Any] = {}
        busy: list[int] = []
        handed: dict[int, TaskOutcome] = {}
        try:
            todo = []
            for seed in seeds:
                key = self._key(seed)
                given = None if self.ahead is None or key is None else self.ahead.take(key)
                if given is not None:
                    locks[seed] = given.lock
                    handed[seed] = given.outcome
                    given.replay_output()
                    continue
                if self._hit(seed):
                    continue
                key = self._key(seed)
                if key is not None and self.cache is not None:
                    try:
                        lock = self.cache.lock(key, self.lock_timeout)
                        acquired = try_acquire(lock)
                    except OSError as e:  # the cache folder cannot be made or written: train without it
                        self._without_cache(e)
                        todo.append(seed)
                        continue
                    if not acquired:
                        busy.append(seed)  # another process trains it: take it from the cache when it is done
                        continue
                    locks[seed] = lock
                    if self._hit(seed):  # stored while we looked
                        continue
                todo.append(seed)
            self._train(todo, handed)
            for seed in busy:
                key = self._key(seed)
                if key is None or self.cache is None:  # the cache failed meanwhile
                    self._train([seed])
                    continue
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

    def _train(self, seeds: list[int], handed: dict[int, TaskOutcome] | None = None) -> None:
        """Train ``seeds`` on the executor; ``handed``: the outcomes of seeds trained ahead, recorded as its own."""
        handed = handed or {}
        if not seeds and not handed:
            return
        tasks = []
        keyed = versions() if self.fingerprint is not None and self.cache is not None else None
        for seed in seeds:
            self.say(ProgressEvent(self.spec.label, seed, "start", budget=self.spec.budget.timesteps))
            tasks.append(seed_task(self.spec, seed, keyed))
        trained: dict[int, RunResult] = {}

        def finished(seed: int, outcome: TaskOutcome) -> None:
            # As each seed ends, not after the batch: a finished run is stored even if a later seed
            # is interrupted (Ctrl-C, SIGTERM) or the spec is stopped.
            if isinstance(outcome, Failure):
                if not is_spec_error(outcome):  # a spec error is raised below, once every child has stopped
                    self.result.errors[seed] = describe_failure(seed, outcome)
                    if outcome.traceback:
                        self.result.tracebacks[seed] = outcome.traceback
                    self.say(ProgressEvent(self.spec.label, seed, "failed", message=self.result.errors[seed]))
                return
            try:  # the same checks as a result read back from the cache: a worker's data is not trusted either
                run = RunResult.from_dict(outcome.value.get("result"), seed=seed, paths=self.paths)
            except (ValueError, TypeError, AttributeError) as e:
                self.result.errors[seed] = f"seed {seed}: the worker sent back a malformed result: {e}"
                self.say(ProgressEvent(self.spec.label, seed, "failed", message=self.result.errors[seed]))
                return
            key = self._key(seed)
            unstored = outcome.value.get("unstored")
            if unstored and key is not None and self.cache is not None:  # fail loudly, lose nothing
                warnings.warn(
                    f"specguard cache: spec {self.spec.label!r}, seed {seed}: {unstored}; the run is kept and "
                    "judged, not cached",
                    CacheWarning,
                    stacklevel=2,
                )
            elif key is not None and self.cache is not None:
                try:
                    self.cache.store_files(key, run, outcome.value["files"])
                except OSError as e:  # read-only, full, not a folder: the run is kept and judged all the same
                    self._without_cache(e)
            trained[seed] = run
            self._event(seed, "done", run, message=self._rates(run))

        for seed, outcome in handed.items():
            finished(seed, outcome)
        stopped = any(isinstance(o, Failure) and is_spec_error(o) for o in handed.values())
        outcomes = dict(handed)
        if tasks and not stopped:
            outcomes |= self.executor.run(
                tasks,
                on_line=lambda seed, line: self.say(decode_update(self.spec.label, seed, line)),
                stop_on=is_spec_error,
                on_outcome=finished,
            )
        for outcome in outcomes.values():
            if isinstance(outcome, Failure) and is_spec_error(outcome):
                assert outcome.exception is not None
                if outcome.traceback:
                    outcome.exception.add_note(f"worker traceback (seed {outcome.key}):\n{outcome.traceback}")
                raise outcome.exception
        for seed in sorted(outcomes):  # the runs in seed order, whatever order they finished in
            if seed in trained:
                self.result.runs.append(trained[seed])
                self.result.cached[seed] = False

    def _without_cache(self, error: OSError) -> None:
        """Warn once that the cache cannot be used (its path, the cause) and go on without it: nothing is lost."""
        if self.cache is None:
            return
        where = error.filename or self.cache.root
        cause = error.strerror or str(error)
        warnings.warn(
            f"specguard cache: cannot write {where} ({cause}); the runs of spec {self.spec.label!r} are kept and "
            "judged, not cached",
            CacheWarning,
            stacklevel=2,
        )
        self.cache = None

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
                message=("thresholds met at a checkpoint | " if run.met_early else "")
                + ("" if run.stop_reason is None else f"{run.stop_reason} | ")
                + message,
            )
        )
