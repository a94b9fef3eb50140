"""What travels between the parent and a task's process (or a cluster worker): tasks, reports, outcomes.

A task reports ``report(phase, step, line)`` as it goes and ends in one message,
``("done", value)`` or ``("error", phase, step, cause, traceback, exception)``,
which :func:`outcome_of` turns into a :class:`Done` or a :class:`Failure`.
"""

from __future__ import annotations

import contextlib
import pickle
import threading
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import cloudpickle

__all__ = [
    "Done",
    "Failure",
    "Position",
    "Report",
    "Task",
    "TaskOutcome",
    "TaskRunner",
    "one_line",
    "outcome_of",
    "pickled_exception",
]

Report = Callable[[str, int | None, str | None], None]
"""``report(phase, step, line)``: tells the parent where the task is; ``line`` is a progress line or None."""


@dataclass(frozen=True)
class Task:
    """One unit of work, run in a process of its own.

    Args:
        key: identifies the task in the outcomes (e.g. the seed); unique within one :func:`run_tasks` call.
        fn: called in the child as ``fn(*args, report=report)``; shipped with cloudpickle, so it may be a lambda.
        args: positional arguments of ``fn``, shipped with cloudpickle too.
        environ: environment variables the task's process starts with, beside the parent's (what a library reads
            once, at its first use: :func:`specguard.utils.numerics.numerics_environ`); an executor whose workers
            outlive a task (a cluster's) cannot set them, and the task checks them itself.
        output: a file the task's process writes its standard output and error to (appended), instead of the
            parent's: a task run ahead of the item it belongs to keeps what it wrote for that item
            (:mod:`specguard.engine.ahead`); a cluster's workers keep their own.
    """

    key: int
    fn: Callable[..., Any]
    args: tuple[Any, ...] = ()
    environ: Mapping[str, str] = field(default_factory=dict)
    output: str | None = None


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


TaskOutcome = Done | Failure


@dataclass
class Position:
    """Where a task last said it was: its phase (``"start"`` before any report) and step.

    The one tracker of a task's position: in the process that runs it
    (:class:`TaskRunner`), in the parent reading its pipe, and on the driver
    of a cluster; a :class:`Failure` is made from it.
    """

    phase: str = "start"
    step: int | None = None

    def move(self, phase: str, step: int | None) -> None:
        self.phase, self.step = phase, step

    def failure(self, key: int, cause: str, traceback: str = "", exception: BaseException | None = None) -> Failure:
        """A :class:`Failure` of task ``key`` here."""
        return Failure(key=key, phase=self.phase, step=self.step, cause=cause, traceback=traceback, exception=exception)


def one_line(error: BaseException) -> str:
    """``"TypeName: first line of the message"`` (just the type name when the message is empty)."""
    try:
        lines = str(error).strip().splitlines()
    except Exception:  # a broken __str__ must not hide the error itself
        lines = []
    return f"{type(error).__name__}: {lines[0]}" if lines else type(error).__name__


def pickled_exception(error: BaseException) -> bytes | None:
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
        self.at = Position()
        self._lock = threading.Lock()  # report may be called from several threads of the task

    def report(self, phase: str, step: int | None = None, line: str | None = None) -> None:
        with self._lock:
            self.at.move(phase, step)
            self.send(("report", phase, step, line))

    def __call__(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> tuple[Any, ...]:
        try:
            return ("done", fn(*args, report=self.report))
        except BaseException as e:  # SystemExit and KeyboardInterrupt are a task's failure too
            return ("error", self.at.phase, self.at.step, one_line(e), traceback.format_exc(), pickled_exception(e))


def outcome_of(key: int, message: tuple[Any, ...]) -> TaskOutcome:
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
