"""A pool of training slots shared by everything one process trains: the item in the foreground first, work ahead
after it.

Each slot is a thread that runs one task at a time in a process of its own
(:func:`~specguard.parallel.workers.run_tasks` with one worker), the most urgent queued task first: the lowest
``rank``, then the first submitted. What a task reports and how it ended come back as messages on the queue it was
submitted with (its *inbox*), to be handled by the thread that waits on it: the cache, the progress lines and the
warnings stay on the caller's thread, never on a slot's.

:class:`PooledExecutor` is the :class:`~specguard.parallel.executors.Executor` over a pool: a batch of seeds
submitted at the foreground's rank, waited for on the calling thread. :mod:`specguard.engine.ahead` queues the
seeds of specs not yet asked for at a lower rank, so that a core the foreground leaves idle (a spec's faster seed
stopped at an earlier checkpoint) trains the next spec's seeds.

Example:
    >>> import queue
    >>> from specguard.parallel.protocol import Task
    >>> pool = SlotPool(2)
    >>> executor = PooledExecutor(pool)
    >>> executor.run([Task(key=0, fn=lambda x, report: 2 * x, args=(21,))])
    {0: Done(key=0, value=42)}
    >>> pool.close()
"""

from __future__ import annotations

import heapq
import itertools
import queue
import threading
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from specguard.parallel.protocol import Failure, Task, TaskOutcome, one_line
from specguard.parallel.signals import STOP_POLL_S, SigtermGuard, raise_if_stopping
from specguard.parallel.workers import run_tasks

__all__ = ["FOREGROUND", "Inbox", "PooledExecutor", "SlotPool", "Ticket", "stop", "wait_message"]

FOREGROUND: tuple[int, ...] = (0,)
"""The rank of what an item waits for now: before any work queued ahead (whose ranks start with 1)."""

Inbox = queue.Queue
"""Where a task's messages arrive: ``("line", ticket, line)`` for each progress line it reports, then one
``("end", ticket, outcome)``, the outcome ``None`` for a task cancelled before it ended."""


@dataclass(eq=False)
class Ticket:
    """A task submitted to a pool: where its messages go, how urgent it is, and whether it was cancelled."""

    task: Task
    rank: tuple[Any, ...]
    inbox: Inbox[tuple[str, Ticket, Any]]
    cancel: threading.Event = field(default_factory=threading.Event)
    started: bool = False
    ended: threading.Event = field(default_factory=threading.Event)  # its "end" message was sent


class SlotPool:
    """``slots`` threads, each running one task at a time in a process of its own, the most urgent first.

    Args:
        slots: the most tasks running at once (>= 1): the process's training processes.
    """

    def __init__(self, slots: int) -> None:
        if slots < 1:
            raise ValueError(f"slots must be >= 1, got {slots}")
        self.slots = slots
        self._queued: list[tuple[tuple[Any, ...], int, Ticket]] = []
        self._running: set[Ticket] = set()
        self._order = itertools.count()
        self._cond = threading.Condition()
        self._threads: list[threading.Thread] = []
        self._closed = False

    def submit(self, task: Task, *, rank: tuple[Any, ...], inbox: Inbox[tuple[str, Ticket, Any]]) -> Ticket:
        """Queue ``task``; a free slot starts it once no queued task ranks before it."""
        ticket = Ticket(task, rank, inbox)
        with self._cond:
            if self._closed:
                raise RuntimeError("the slot pool is closed")
            heapq.heappush(self._queued, (rank, next(self._order), ticket))
            if len(self._threads) < self.slots:
                thread = threading.Thread(target=self._slot, name=f"specguard-slot-{len(self._threads)}", daemon=True)
                self._threads.append(thread)
                thread.start()
            self._cond.notify()
        return ticket

    def rerank(self, tickets: Iterable[Ticket], rank: tuple[Any, ...]) -> None:
        """Give ``tickets`` that are still queued ``rank`` (e.g. :data:`FOREGROUND`: an item waits for them)."""
        chosen = set(tickets)
        with self._cond:
            self._queued = [((rank if ticket in chosen else r), order, ticket) for r, order, ticket in self._queued]
            heapq.heapify(self._queued)
            for ticket in chosen:
                ticket.rank = rank

    def cancel(self, tickets: Iterable[Ticket]) -> list[Ticket]:
        """Drop ``tickets``: a queued one never starts (its "end" comes at once), a running one's process is
        terminated within :data:`~specguard.parallel.signals.STOP_POLL_S`. Returns the ones that were running."""
        chosen = [t for t in tickets if not t.ended.is_set()]
        with self._cond:
            for ticket in chosen:
                ticket.cancel.set()
            dropped = [t for _, _, t in self._queued if t in set(chosen)]
            self._queued = [entry for entry in self._queued if entry[2] not in set(dropped)]
            heapq.heapify(self._queued)
            running = [t for t in chosen if t in self._running]
        for ticket in dropped:
            self._end(ticket, None)
        return running

    def close(self) -> None:
        """Cancel every task, queued or running, and wait for every slot's thread (and its process) to end."""
        with self._cond:
            self._closed = True
            tickets = [t for _, _, t in self._queued] + list(self._running)
        self.cancel(tickets)
        with self._cond:
            self._cond.notify_all()
        for thread in self._threads:
            thread.join()

    def _slot(self) -> None:
        while True:
            with self._cond:
                while not self._queued and not self._closed:
                    self._cond.wait()
                if not self._queued:
                    return
                _, _, ticket = heapq.heappop(self._queued)
                ticket.started = True
                self._running.add(ticket)
            outcome: TaskOutcome | None = None
            try:
                if not ticket.cancel.is_set():
                    outcomes = run_tasks(
                        [ticket.task],
                        max_workers=1,
                        on_line=_forward(ticket),
                        cancel=ticket.cancel,
                    )
                    outcome = outcomes.get(ticket.task.key)
            except BaseException as e:  # the task could not be shipped, or every task of the process was stopped
                if not ticket.cancel.is_set():
                    outcome = Failure(ticket.task.key, "start", None, one_line(e), traceback.format_exc())
            finally:
                with self._cond:
                    self._running.discard(ticket)
                self._end(ticket, outcome)

    @staticmethod
    def _end(ticket: Ticket, outcome: TaskOutcome | None) -> None:
        ticket.inbox.put(("end", ticket, outcome))
        ticket.ended.set()


def _forward(ticket: Ticket) -> Callable[[int, str], None]:
    """``on_line`` for ``ticket``'s task: each line to its inbox."""

    def put(_key: int, line: str) -> None:
        ticket.inbox.put(("line", ticket, line))

    return put


def wait_message(inbox: Inbox[tuple[str, Ticket, Any]]) -> tuple[str, Ticket, Any] | None:
    """The next message of ``inbox``, or None after :data:`~specguard.parallel.signals.STOP_POLL_S` without one
    (the caller's thread then sees Ctrl-C, and an interruption of every task, at once)."""
    try:
        return inbox.get(timeout=STOP_POLL_S)
    except queue.Empty:
        raise_if_stopping()
        return None


class PooledExecutor:
    """An :class:`~specguard.parallel.executors.Executor` whose tasks run on a :class:`SlotPool`'s slots, at the
    foreground's rank; the batch is waited for on the calling thread, which handles every line and outcome.

    On any exception in the caller (Ctrl-C; SIGTERM, turned into ``KeyboardInterrupt`` in the main thread) and when
    ``stop_on`` stops the batch, its tasks still queued are dropped and those running are terminated and waited for.
    """

    def __init__(self, pool: SlotPool, *, rank: tuple[Any, ...] = FOREGROUND) -> None:
        self.pool = pool
        self.rank = rank

    def run(
        self,
        tasks: Sequence[Task],
        *,
        on_line: Callable[[int, str], None] | None = None,
        stop_on: Callable[[Failure], bool] | None = None,
        on_outcome: Callable[[int, TaskOutcome], None] | None = None,
    ) -> dict[int, TaskOutcome]:
        keys = [t.key for t in tasks]
        if len(set(keys)) != len(keys):
            raise ValueError(f"task keys must be unique, got {keys}")
        inbox: Inbox[tuple[str, Ticket, Any]] = queue.Queue()
        tickets = [self.pool.submit(task, rank=self.rank, inbox=inbox) for task in tasks]
        outcomes: dict[int, TaskOutcome] = {}
        left = len(tickets)
        guard = SigtermGuard()
        guard.install()
        try:
            while left:
                message = wait_message(inbox)
                if message is None:
                    continue
                kind, ticket, value = message
                if kind == "line":
                    if on_line is not None:
                        on_line(ticket.task.key, value)
                    continue
                left -= 1
                if value is None:
                    continue
                outcomes[ticket.task.key] = value
                if on_outcome is not None:
                    on_outcome(ticket.task.key, value)
                if isinstance(value, Failure) and stop_on is not None and stop_on(value):
                    break
            return {key: outcomes[key] for key in keys if key in outcomes}
        finally:
            guard.close(lambda: stop(self.pool, tickets))

    def close(self) -> None:
        pass


def stop(pool: SlotPool, tickets: Iterable[Ticket]) -> None:
    """Cancel ``tickets`` and wait until every one that was running has ended (its process reaped)."""
    for ticket in pool.cancel(tickets):
        ticket.ended.wait()
