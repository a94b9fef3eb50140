"""Training ahead: the seeds of specs a session will ask for, trained on the slots its foreground leaves idle.

A session that knows its specs before it runs them (``pytest --goal-specs`` over ``sg.goal_specs``,
``specguard run`` over a file's specs) plans them here, in the order it will ask for them: each spec's first
``budget.min_seeds`` seeds that are neither in the run cache nor locked by another process are locked and queued
on the session's :class:`~specguard.parallel.slots.SlotPool`, behind whatever the foreground trains. While a
spec's slower seed trains, the core its faster seed freed trains another spec's.

Planned runs start longest first: ranked by their budget's ceiling in timesteps, the largest first (ties in the
session's order). The one cost known before training is that ceiling (an anytime run may stop earlier); starting
the longest runs first and packing the shorter ones around them (the longest-processing-time rule) keeps one long
seed from starting late and leaving the other cores idle at the session's end. A foreground item that asks for
a run still queued moves it to the front, so the order changes when a run starts, never what it trains.

The foreground asks for a run by its cache key (:meth:`TrainAhead.take`, from
:class:`~specguard.engine.seeds.Runs`): a planned run still queued moves to the front, one training is waited for,
and its outcome is handed over with its lock, exactly as the foreground's own executor would have returned it.
The foreground then stores it, warns about it, reports it ("trained", not "cached") and judges it in the item it
belongs to; what its process wrote comes out there too. Nothing reaches the cache or the user from a slot's thread.

Planning never checks a spec in place: it fingerprints a copy, so the checks' warnings (and refusals) come from
the foreground, in the spec's own item. A spec that cannot be copied or fingerprinted, or whose runs are not
reproducible, is left to the foreground. On :meth:`TrainAhead.close` (the session's end, Ctrl-C), the runs not
asked for are stopped; those that had finished are stored, so nothing trained is lost.
"""

from __future__ import annotations

import copy
import queue
import shutil
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from specguard.cache.fingerprint import fingerprint_spec
from specguard.cache.store import Cache, try_acquire
from specguard.cache.versions import versions
from specguard.engine.worker_task import train_task
from specguard.error import CacheWarning
from specguard.parallel.protocol import Done, Task, TaskOutcome
from specguard.parallel.slots import FOREGROUND, Inbox, SlotPool, Ticket, stop, wait_message
from specguard.spec.spec import Spec
from specguard.training.progress import ProgressEvent, decode_update
from specguard.training.result import RunResult
from specguard.tree.keys import result_keys
from specguard.utils.numerics import numerics_environ

__all__ = ["AHEAD", "Handed", "TrainAhead", "seed_task"]

AHEAD = 1
"""The first element of a planned run's rank: after anything the foreground waits for (rank 0)."""

Progress = Callable[[ProgressEvent], None]


def seed_task(spec: Spec, seed: int, keyed: dict[str, str] | None, *, output: str | None = None) -> Task:
    """The task that trains ``seed`` of ``spec`` (:func:`~specguard.engine.worker_task.train_task`), with the numerics
    its process starts with; ``keyed``: the versions a cached run's key names (None: not cached)."""
    return Task(seed, train_task, (spec, seed, keyed), numerics_environ(spec.numerics), output=output)


@dataclass
class Handed:
    """A run trained ahead, handed to the foreground: its outcome, the cache lock held for it, what it wrote."""

    outcome: TaskOutcome
    lock: Any
    output: str

    def replay_output(self) -> None:
        """Write what the run's process wrote to this process's standard error (the item's capture, under pytest)."""
        if self.output:
            sys.stderr.write(self.output)
            sys.stderr.flush()


@dataclass(eq=False)
class _Planned:
    label: str
    index: int  # the spec's place in the session
    spec_key: str
    key: str
    seed: int
    paths: frozenset[str]
    lock: Any
    output: Path
    ticket: Ticket
    outcome: TaskOutcome | None = None
    ended: bool = False
    taken: bool = False


class TrainAhead:
    """The runs a session planned ahead (module docstring), on ``pool``'s slots, stored in ``cache`` when not taken.

    Args:
        pool: the session's training slots (the foreground's executor shares them).
        cache: the run cache (its locks keep another process from training a planned run at the same time).
        say: the session's progress sink, for the lines of planned runs (shown while the foreground waits).
        lock_timeout: how long another process may wait for a planned run's lock.
    """

    def __init__(self, pool: SlotPool, cache: Cache, *, say: Progress | None = None, lock_timeout: float = 3600.0):
        self.pool = pool
        self.cache = cache
        self.say = say or (lambda event: None)
        self.lock_timeout = lock_timeout
        self._inbox: Inbox[tuple[str, Ticket, Any]] = Inbox()
        self._planned: dict[str, _Planned] = {}  # run key -> its planned run
        self._by_ticket: dict[Ticket, _Planned] = {}
        self._outputs = Path(tempfile.mkdtemp(prefix="specguard-ahead-"))
        self._planning = True

    @property
    def planned(self) -> list[str]:
        """The run keys planned and not yet taken, in the session's order (spec, then seed)."""
        runs = sorted((run.index, run.seed, key) for key, run in self._planned.items() if not run.taken)
        return [key for _, _, key in runs]

    def plan(self, specs: Iterable[Spec]) -> None:
        """Queue the first ``min_seeds`` seeds of each spec that no cache entry or other process holds, to start
        longest ceiling first (the module docstring): planned in that order too, so that a slot idle while the
        rest are planned starts the longest."""
        for index, spec in sorted(enumerate(specs), key=lambda pair: -pair[1].budget.timesteps):
            if not self._planning:
                return
            planned = self._copy_and_fingerprint(spec)
            if planned is None:
                continue
            trained, fingerprint = planned
            keyed = versions()
            paths = frozenset(result_keys(trained.tree))
            for seed in range(trained.budget.min_seeds):
                key = fingerprint.run_key(seed)
                lock = None if key in self._planned else self._lock_free(key, seed, paths)
                if lock is None:
                    continue
                output = self._outputs / f"{key}.out"
                task = seed_task(trained, seed, keyed, output=str(output))
                rank = (AHEAD, -trained.budget.timesteps, index, seed)  # longest ceiling first (module docstring)
                ticket = self.pool.submit(task, rank=rank, inbox=self._inbox)
                run = _Planned(trained.label, index, fingerprint.spec_key, key, seed, paths, lock, output, ticket)
                self._planned[key] = run
                self._by_ticket[ticket] = run

    def _copy_and_fingerprint(self, spec: Spec) -> tuple[Spec, Any] | None:
        """A copy of ``spec`` and its fingerprint, with every warning of the way dropped (the foreground gives
        them, checking the spec itself); None when either fails, or its runs are not reproducible."""
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                trained = copy.deepcopy(spec)
                fingerprint = fingerprint_spec(trained)
        except Exception:  # the user's objects, or a spec the foreground refuses: it says why, in its item
            return None
        return (trained, fingerprint) if fingerprint.reproducible else None

    def _lock_free(self, key: str, seed: int, paths: frozenset[str]) -> Any:
        """The lock of run ``key``, taken now, when it is to be trained here (not cached, not locked); else None."""
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                if self.cache.load_key(key, seed=seed, paths=paths) is not None:
                    return None
                lock = self.cache.lock(key, self.lock_timeout)
                if not try_acquire(lock):
                    return None  # another process trains it
                if self.cache.load_key(key, seed=seed, paths=paths) is not None:  # stored while we looked
                    lock.release()
                    return None
        except OSError:  # the cache cannot be written: the foreground trains without it, and says so
            self._planning = False
            return None
        return lock

    def take(self, key: str) -> Handed | None:
        """The planned run ``key``, once trained: its outcome with its lock; None when it was not planned here (or
        was cancelled). Its spec's other planned runs still queued move to the front with it."""
        run = self._planned.get(key)
        if run is None or run.taken:
            return None
        run.taken = True
        siblings = [r.ticket for r in self._planned.values() if r.spec_key == run.spec_key and not r.ended]
        self.pool.rerank(siblings, FOREGROUND)
        while not run.ended:
            self._pump(wait=True)
        output = _read(run.output)
        if run.outcome is None:
            run.lock.release()
            return None
        return Handed(run.outcome, run.lock, output)

    def pump(self) -> None:
        """Handle the messages already there (progress lines, ends) without waiting."""
        self._pump(wait=False)

    def _pump(self, *, wait: bool) -> None:
        while True:
            message = wait_message(self._inbox) if wait else _next(self._inbox)
            if message is None:
                return
            kind, ticket, value = message
            run = self._by_ticket[ticket]
            if kind == "line":
                self.say(decode_update(run.label, run.seed, value))
            else:
                run.outcome, run.ended = value, True
            if wait:
                return

    def close(self) -> None:
        """Stop the runs not taken; store those that finished (nothing trained is lost); release every lock."""
        self._planning = False
        left = [run for run in self._planned.values() if not run.taken]
        try:
            stop(self.pool, [run.ticket for run in left])
            self.pump()
            for run in left:
                if isinstance(run.outcome, Done):
                    self._store(run, run.outcome)
        finally:
            for run in left:
                run.taken = True
                run.lock.release()
            shutil.rmtree(self._outputs, ignore_errors=True)

    def _store(self, run: _Planned, outcome: Done) -> None:
        """Store a finished run nobody asked for (the session stopped first); a run that cannot be is dropped, with
        a warning naming why (the next session trains it again)."""
        if outcome.value.get("unstored"):
            return
        try:
            result = RunResult.from_dict(outcome.value.get("result"), seed=run.seed, paths=run.paths)
            self.cache.store_files(run.key, result, outcome.value["files"])
        except (ValueError, TypeError, AttributeError, KeyError, OSError) as e:
            warnings.warn(
                f"specguard cache: spec {run.label!r}, seed {run.seed}, trained ahead: not stored ({e})",
                CacheWarning,
                stacklevel=2,
            )


def _next(inbox: Inbox[tuple[str, Ticket, Any]]) -> tuple[str, Ticket, Any] | None:
    try:
        return inbox.get_nowait()
    except queue.Empty:
        return None


def _read(path: Path) -> str:
    try:
        return path.read_text(errors="replace")
    except OSError:
        return ""
