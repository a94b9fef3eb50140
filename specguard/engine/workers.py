"""Run tasks in spawned processes, one process per task, so that each task fails alone.

Why not ``concurrent.futures.ProcessPoolExecutor`` (or loky): when one worker of
such a pool dies (killed by the OOM killer, a segfault in a native library), the
whole executor breaks, every pending future raises ``BrokenProcessPool`` and the
results of the other seeds are lost. A SIGTERM to the parent left a worker
training and then blocked for ever on a pipe nobody read, and errors arrived as
chains of ``_RemoteTraceback``. Here every task gets its own process and its own
pipe, so:

* a task that raises gives a :class:`Failure` with a one-line cause, the child's
  traceback text and, where it can be pickled, the exception itself;
* a process that dies without a result (a signal, ``os._exit``) gives a
  :class:`Failure` naming the signal or exit code and the last phase and step the
  task reported, while the other tasks go on and keep their results;
* the parent waits on the pipes and on the processes' sentinels at once, so a
  dead child is noticed at once, never waited for on a pipe;
* on SIGTERM (in the main thread it is turned into ``KeyboardInterrupt``) or on
  any other exception in the parent, every running child is terminated, then
  killed if it does not stop, and reaped: no child is left behind;
* a child whose parent dies (even by SIGKILL, where no cleanup can run) notices
  it on ``multiprocessing.parent_process().sentinel`` and exits.

Progress travels over the same pipe: the task calls ``report(phase, step, line)``
and the parent prints, so lines of parallel tasks never interleave mid-line.
``fn`` and its arguments are shipped with cloudpickle (they may hold lambdas);
results and exceptions come back with plain pickling.

Example:
    >>> outcomes = run_tasks([Task(key=0, fn=lambda x, report: 2 * x, args=(21,))], max_workers=1)
    >>> outcomes
    {0: Done(key=0, value=42)}
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import pickle
import signal
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from multiprocessing.context import SpawnContext
from multiprocessing.process import BaseProcess
from types import FrameType
from typing import Any

import cloudpickle

from specguard.error import InvalidSpec
from specguard.validation import parse_count

__all__ = [
    "Done",
    "Failure",
    "Outcome",
    "Report",
    "Task",
    "TaskRunner",
    "outcome_of",
    "parse_workers",
    "raise_if_stopping",
    "resolve_workers",
    "run_tasks",
    "stopping_all_tasks",
]

Report = Callable[[str, int | None, str | None], None]
"""``report(phase, step, line)``: tells the parent where the task is; ``line`` is a progress line or None."""

_STOP_GRACE_S = 2.0
"""How long a terminated child gets to exit before it is killed."""

_EXIT_GRACE_S = 10.0
"""How long a child that has sent its outcome gets to exit on its own before it is terminated."""

_STOP_POLL_S = 0.25
"""How often a waiting :func:`run_tasks` looks whether :func:`stopping_all_tasks` asks it to stop."""

_STOPPING = threading.Event()

_MAX_MESSAGES_PER_WAKEUP = 64
"""Messages read from one live child before the others get their turn (a chatty task must not starve them)."""


@contextlib.contextmanager
def stopping_all_tasks() -> Iterator[None]:
    """While inside, every :func:`run_tasks` of this process, on any thread, stops its children and raises.

    A signal reaches only the main thread. A caller that runs :func:`run_tasks`
    on threads of its own (``specguard reproduce`` trains several specs at once)
    enters this block on its interruption and waits for its threads there: each
    ``run_tasks`` notices within :data:`_STOP_POLL_S`, terminates and reaps its
    children, stores nothing and raises ``KeyboardInterrupt``. Leaving the block
    lets later calls run again.
    """
    _STOPPING.set()
    try:
        yield
    finally:
        _STOPPING.clear()


def raise_if_stopping() -> None:
    """Raise ``KeyboardInterrupt`` inside :func:`stopping_all_tasks`, for loops that wait on tasks."""
    if _STOPPING.is_set():
        raise KeyboardInterrupt("stopped: the process was interrupted")


def parse_workers(value: object) -> int | str:
    """The one worker-count rule: ``"auto"`` or a count (:func:`specguard.validation.parse_count`).

    Raises:
        InvalidSpec: anything else, with what was expected (a ``SpecError``,
            which each door makes its own usage error: the CLI's and the
            pytest plugin's option errors; ``run_spec`` raises it as it is).
    """
    if value == "auto":
        return "auto"
    try:
        return parse_count(value, "or 'auto': one per usable core")
    except ValueError as e:
        raise InvalidSpec("workers", str(e)) from None


def resolve_workers(value: object, *, share: int = 1) -> int:
    """Parallel processes for ``value``: ``"auto"`` is the usable cores divided among ``share`` sharers.

    Under pytest-xdist, ``share`` is the number of xdist workers, so they do not
    oversubscribe the cores between them.

    Raises:
        InvalidSpec: see :func:`parse_workers`.
    """
    parsed = parse_workers(value)
    if parsed != "auto":
        assert isinstance(parsed, int)
        return parsed
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, cores // max(1, share))


@dataclass(frozen=True)
class Task:
    """One unit of work, run in a process of its own.

    Args:
        key: identifies the task in the outcomes (e.g. the seed); unique within one :func:`run_tasks` call.
        fn: called in the child as ``fn(*args, report=report)``; shipped with cloudpickle, so it may be a lambda.
        args: positional arguments of ``fn``, shipped with cloudpickle too.
    """

    key: int
    fn: Callable[..., Any]
    args: tuple[Any, ...] = ()


@dataclass(frozen=True)
class Failure:
    """A task that raised, or whose process died before it sent a result.

    Args:
        key: the task's key.
        phase: the last phase the task reported (``"start"`` before any report).
        step: the last step the task reported, if any.
        cause: one line, e.g. ``"RuntimeError: boom"`` or ``"worker process died (killed by signal SIGKILL)"``.
        traceback: the child's formatted traceback, ``""`` when the process died.
        exception: the child's exception when it could be pickled back, else None.
    """

    key: int
    phase: str
    step: int | None
    cause: str
    traceback: str = ""
    exception: BaseException | None = None


@dataclass(frozen=True)
class Done:
    """A task that returned.

    Args:
        key: the task's key.
        value: what ``fn`` returned.
    """

    key: int
    value: Any


Outcome = Done | Failure


# ---------------------------------------------------------------------------------------------------------------------
# Child side


def _exit_when_parent_dies() -> None:
    """Start a daemon thread that ends this process as soon as its parent is gone.

    The parent holds the write end of a pipe whose read end is ``parent_process().sentinel``; the
    sentinel becomes readable when the parent exits for any reason, SIGKILL included.
    """
    parent = multiprocessing.parent_process()
    if parent is None:
        return
    sentinel = parent.sentinel

    def watch() -> None:
        wait([sentinel])
        os._exit(1)

    threading.Thread(target=watch, name="specguard-parent-watch", daemon=True).start()


def _one_line(error: BaseException) -> str:
    """``"TypeName: first line of the message"`` (just the type name when the message is empty)."""
    try:
        lines = str(error).strip().splitlines()
    except Exception:  # a broken __str__ must not hide the error itself
        lines = []
    return f"{type(error).__name__}: {lines[0]}" if lines else type(error).__name__


def _pickled_exception(error: BaseException) -> bytes | None:
    """The exception pickled for the parent, or None when it cannot be pickled.

    cloudpickle rather than pickle, so that exception classes the parent shipped by value
    (defined in ``__main__`` or a module registered by value) come back as the parent's own class.
    """
    try:
        data: bytes = cloudpickle.dumps(error)
    except Exception:
        return None
    return data


class TaskRunner:
    """Runs one task where it was sent (a child process here, a cluster worker elsewhere).

    Tracks the phase and step the task last reported, passes each report to
    ``send`` (``("report", phase, step, line)``), and turns the task's end into
    one message: ``("done", value)`` or ``("error", phase, step, cause,
    traceback_text, pickled_exception_or_None)``, as :func:`outcome_of` reads it.
    """

    def __init__(self, send: Callable[[tuple[Any, ...]], None]) -> None:
        self.send = send
        self.phase = "start"
        self.step: int | None = None
        self._lock = threading.Lock()  # report may be called from several threads of the task

    def report(self, phase: str, step: int | None = None, line: str | None = None) -> None:
        with self._lock:
            self.phase, self.step = phase, step
            self.send(("report", phase, step, line))

    def __call__(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> tuple[Any, ...]:
        try:
            return ("done", fn(*args, report=self.report))
        except BaseException as e:  # SystemExit and KeyboardInterrupt are a task's failure too
            return ("error", self.phase, self.step, _one_line(e), traceback.format_exc(), _pickled_exception(e))


def outcome_of(key: int, message: tuple[Any, ...]) -> Outcome:
    """The outcome a :class:`TaskRunner` message stands for."""
    if message[0] == "done":
        return Done(key=key, value=message[1])
    _, phase, step, cause, text, pickled = message
    exception: BaseException | None = None
    if pickled is not None:
        with contextlib.suppress(Exception):  # e.g. an exception class whose __init__ takes other arguments
            loaded = pickle.loads(pickled)
            if isinstance(loaded, BaseException):
                exception = loaded
    return Failure(key=key, phase=phase, step=step, cause=cause, traceback=text, exception=exception)


def _child_main(conn: Connection, payload: bytes) -> None:
    """Process entry point: unpickle ``(fn, args)``, run it and send its reports and outcome to the parent."""
    _exit_when_parent_dies()
    runner = TaskRunner(conn.send)
    try:
        try:
            fn, args = cloudpickle.loads(payload)
        except BaseException as e:
            message: tuple[Any, ...] = ("error", "start", None, _one_line(e), traceback.format_exc(), None)
        else:
            message = runner(fn, args)
        try:
            conn.send(message)  # pickles first: an unpicklable value sends nothing, then an error
        except Exception as e:
            conn.send(("error", runner.phase, runner.step, _one_line(e), traceback.format_exc(), None))
    finally:
        conn.close()


# ---------------------------------------------------------------------------------------------------------------------
# Parent side


@dataclass
class _Child:
    """A started task: its process, the read end of its pipe and what the parent knows so far."""

    task: Task
    process: BaseProcess
    conn: Connection
    phase: str = "start"
    step: int | None = None
    eof: bool = False
    deadline: float | None = None  # set once its outcome or EOF arrived: when it is terminated if still alive


class SigtermGuard:
    """Turns SIGTERM into ``KeyboardInterrupt`` while installed (main thread only, else it does nothing).

    While ``deferring``, a SIGTERM is only noted (``pending``): a child being started is
    registered before the interruption is raised, and cleanup is not cut short.
    """

    def __init__(self) -> None:
        self.installed = False
        self.previous: Any = None
        self.deferring = False
        self.pending = False

    def install(self) -> None:
        if threading.current_thread() is threading.main_thread():
            self.previous = signal.signal(signal.SIGTERM, self._handle)
            self.installed = True

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.deferring:
            self.pending = True
        else:
            raise KeyboardInterrupt(f"{signal.Signals(signum).name} received")

    @contextlib.contextmanager
    def deferred(self) -> Iterator[None]:
        """Note a SIGTERM arriving inside the block; raise ``KeyboardInterrupt`` on leaving it."""
        self.deferring = True
        try:
            yield
        finally:
            self.deferring = False
        if self.pending:
            self.pending = False
            raise KeyboardInterrupt("SIGTERM received")

    def restore(self) -> None:
        if self.installed:
            # None: the previous handler was not installed from Python and cannot be put back.
            signal.signal(signal.SIGTERM, signal.SIG_DFL if self.previous is None else self.previous)
            self.installed = False


def _died(child: _Child) -> Failure:
    code = child.process.exitcode
    if code is not None and code < 0:
        try:
            how = f"killed by signal {signal.Signals(-code).name}"
        except ValueError:
            how = f"killed by signal {-code}"
    else:
        how = f"exit code {code}"
    return Failure(key=child.task.key, phase=child.phase, step=child.step, cause=f"worker process died ({how})")


def _read(child: _Child, on_line: Callable[[int, str], None] | None, limit: int | None) -> Outcome | None:
    """Read up to ``limit`` (None: all) messages that are already there; return the outcome if it came."""
    count = 0
    while not child.eof and (limit is None or count < limit) and child.conn.poll():
        count += 1
        try:
            message = child.conn.recv()
        except (EOFError, OSError):
            child.eof = True
            break
        except Exception as e:  # the result could not be unpickled here; the stream itself is intact
            return Failure(
                key=child.task.key,
                phase=child.phase,
                step=child.step,
                cause=f"result could not be read: {_one_line(e)}",
                traceback=traceback.format_exc(),
            )
        kind = message[0]
        if kind == "report":
            _, child.phase, child.step, line = message
            if line is not None and on_line is not None:
                on_line(child.task.key, line)
        elif kind in ("done", "error"):
            return outcome_of(child.task.key, message)
    return None


def _stop(children: Sequence[_Child]) -> None:
    """Terminate, then kill, every child still running, and reap them all."""
    for child in children:
        if child.process.is_alive():
            child.process.terminate()
    deadline = time.monotonic() + _STOP_GRACE_S
    for child in children:
        child.process.join(max(0.0, deadline - time.monotonic()))
    for child in children:
        if child.process.exitcode is None:
            child.process.kill()
            child.process.join()


def _release(children: Sequence[_Child]) -> None:
    """Close the pipes and process handles of reaped children."""
    for child in children:
        child.conn.close()
        child.process.close()


def _start(context: SpawnContext, task: Task, payload: bytes) -> _Child:
    reader, writer = context.Pipe(duplex=False)
    process = context.Process(
        target=_child_main, args=(writer, payload), name=f"specguard-task-{task.key}", daemon=False
    )
    try:
        process.start()
    except BaseException:
        reader.close()
        raise
    finally:
        writer.close()  # the child has its own copy; ours would keep the pipe from ever reaching EOF
    return _Child(task=task, process=process, conn=reader)


def run_tasks(
    tasks: Sequence[Task],
    *,
    max_workers: int,
    on_line: Callable[[int, str], None] | None = None,
    stop_on: Callable[[Failure], bool] | None = None,
    on_outcome: Callable[[int, Outcome], None] | None = None,
) -> dict[int, Outcome]:
    """Run every task in a spawned process of its own, at most ``max_workers`` at once.

    A task that raises, or whose process dies, becomes a :class:`Failure`; the others keep running.
    On any exception in the parent (SIGTERM in the main thread arrives as ``KeyboardInterrupt``),
    every child still running is terminated and reaped before the exception propagates; so it is
    inside :func:`stopping_all_tasks`, from any thread.

    Args:
        tasks: the tasks; their keys must be distinct.
        max_workers: the most child processes alive at once (>= 1). The next task starts as soon as one ends.
        on_line: called in the parent as ``on_line(key, line)`` for each line a task reports, in order per task.
        stop_on: called with each failure as it arrives; when it returns True, the other children are
            terminated and the outcomes so far are returned at once (unfinished tasks are absent).
        on_outcome: called in the parent as ``on_outcome(key, outcome)`` as each task ends, before
            ``stop_on`` sees it, so a caller can keep a finished task's result even if the batch is
            interrupted later.

    Returns:
        The outcome of each finished task by key, in the order of ``tasks``.

    Raises:
        ValueError: ``max_workers`` < 1 or duplicate keys.
        TypeError, pickle.PicklingError: a task's ``fn`` or ``args`` cannot be pickled (before any process starts).
        KeyboardInterrupt: SIGTERM or SIGINT received, or :func:`stopping_all_tasks` entered (after the
            children were stopped).
    """
    if max_workers < 1:
        raise ValueError(f"max_workers must be >= 1, got {max_workers}")
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise ValueError(f"task keys must be unique, got {keys}")
    payloads = {t.key: cloudpickle.dumps((t.fn, t.args)) for t in tasks}  # an unpicklable task fails before any start

    context = multiprocessing.get_context("spawn")  # torch and forked state do not mix
    pending = deque(tasks)
    children: list[_Child] = []
    outcomes: dict[int, Outcome] = {}
    guard = SigtermGuard()
    guard.install()
    try:
        while pending or children:
            while pending and len(children) < max_workers:
                with guard.deferred():  # a started child is always registered, hence always stopped
                    task = pending.popleft()
                    children.append(_start(context, task, payloads[task.key]))

            deadlines = [c.deadline for c in children if c.deadline is not None]
            timeout = min([_STOP_POLL_S, *(max(0.0, d - time.monotonic()) for d in deadlines)])
            waitables: list[Any] = [c.conn for c in children if not c.eof]
            waitables += [c.process.sentinel for c in children]
            ready = set(wait(waitables, timeout))
            raise_if_stopping()  # the finally below stops and reaps the children

            for child in list(children):
                dead = child.process.sentinel in ready
                if child.conn in ready or dead:
                    outcome = _read(child, on_line, None if dead else _MAX_MESSAGES_PER_WAKEUP)
                    if outcome is not None:
                        outcomes[child.task.key] = outcome
                        child.deadline = time.monotonic() + _EXIT_GRACE_S
                        if on_outcome is not None:
                            on_outcome(child.task.key, outcome)
                        if isinstance(outcome, Failure) and stop_on is not None and stop_on(outcome):
                            return _in_task_order(tasks, outcomes)
                    elif child.eof and child.deadline is None:
                        child.deadline = time.monotonic() + _EXIT_GRACE_S  # closed its pipe: it should be exiting
                expired = child.deadline is not None and time.monotonic() >= child.deadline
                if not (dead or expired):
                    continue
                _stop([child])  # already exited (dead), or finished but lingering (expired): reap it either way
                children.remove(child)
                failure = None if child.task.key in outcomes else _died(child)
                _release([child])
                if failure is not None:
                    outcomes[child.task.key] = failure
                    if on_outcome is not None:
                        on_outcome(child.task.key, failure)
                    if stop_on is not None and stop_on(failure):
                        return _in_task_order(tasks, outcomes)
        return _in_task_order(tasks, outcomes)
    finally:
        guard.deferring = True  # a second SIGTERM must not cut the cleanup short
        try:
            _stop(children)
            _release(children)
        finally:
            guard.deferring = False
            guard.restore()
        if guard.pending:  # SIGTERM during the cleanup: honour it now that the children are gone
            raise KeyboardInterrupt("SIGTERM received")


def _in_task_order(tasks: Sequence[Task], outcomes: dict[int, Outcome]) -> dict[int, Outcome]:
    return {t.key: outcomes[t.key] for t in tasks if t.key in outcomes}
