"""Run tasks in processes of their own, one process per task, so that each task fails alone.

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

Each process starts as a spawned one does (a fresh interpreter's state: it imports the
main script again, reads the parent's working directory, ``sys.path`` and environment),
but where the platform has it (Linux, macOS) it is forked from a *fork server*, a process
started once per parent that imported the heavy libraries every task needs
(:data:`PRELOAD`: torch, stable-baselines3, gymnasium) before it forked anything: a task
then starts in milliseconds instead of the seconds those imports take (Python 3.14 made the
fork server Linux's default for the same reason). The server itself never runs a task, so no
torch thread pool or task state is ever forked. Elsewhere (Windows) processes are spawned.

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
import signal
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from multiprocessing import reduction
from multiprocessing.connection import Connection, wait
from multiprocessing.context import BaseContext
from multiprocessing.process import BaseProcess
from typing import Any

import cloudpickle

from specguard.error import InvalidSpec
from specguard.parallel.protocol import Failure, Position, Task, TaskOutcome, TaskRunner, one_line, outcome_of
from specguard.parallel.signals import STOP_POLL_S, SigtermGuard, raise_if_stopping
from specguard.utils.numerics import started_with, with_libm
from specguard.utils.parsing import parse_count

__all__ = ["parse_workers", "resolve_workers", "run_tasks"]

_STOP_GRACE_S = 2.0
"""How long a terminated child gets to exit before it is killed."""

_EXIT_GRACE_S = 10.0
"""How long a child that has sent its outcome gets to exit on its own before it is terminated."""

PRELOAD = ("torch", "stable_baselines3", "gymnasium")
"""Libraries the fork server imports once, before it forks any task's process (one not installed is skipped).

Installed libraries only: specguard's own modules load in each task's process, from the sources on disk when it
starts, as a spawned process would (a run's cache key names a digest of those sources,
:mod:`specguard.cache.versions`). A library upgraded while the server lives is caught by the task's version check,
which compares the versions loaded with the ones installed.
"""

_MAX_MESSAGES_PER_WAKEUP = 64
"""Messages read from one live child before the others get their turn (a chatty task must not starve them)."""


def parse_workers(value: object) -> int | str:
    """The one worker-count rule: ``"auto"`` or a count (:func:`specguard.utils.parsing.parse_count`).

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


class _ParentStdio:
    """The parent's standard output and error as they are when a task starts, for the task's process to write to.

    A spawned process inherits them. One forked by the fork server would write to the server's, which are the
    parent's when the server started: under pytest, the capture of whichever test started it, so a task's
    warnings and a native crash's last words would be lost. Pickled for the fork server, the two descriptors
    travel with the task (``multiprocessing.reduction.DupFd``); :meth:`adopt` puts them in place.
    """

    def __init__(self, fds: tuple[Any, ...] = ()) -> None:
        self.fds = fds

    def __reduce__(self) -> tuple[Any, ...]:
        fds: list[Any] = []
        for fd in (1, 2):
            try:
                os.fstat(fd)
            except OSError:  # closed in the parent: the process keeps the server's
                fds.append(None)
            else:
                fds.append(reduction.DupFd(fd))
        return (_ParentStdio, (tuple(fds),))

    def adopt(self) -> None:
        for fd, dup in zip((1, 2), self.fds, strict=False):
            if dup is not None:
                new = dup.detach()
                os.dup2(new, fd)
                os.close(new)


def _child_main(
    conn: Connection, payload: bytes, environ: dict[str, str], stdio: _ParentStdio | None, output: str | None = None
) -> None:
    """Process entry point: unpickle ``(fn, args)``, run it and send its reports and outcome to the parent.

    ``environ`` and ``stdio`` are the parent's environment and standard streams when the task started (a
    forked process has the fork server's, taken when the server started; ``stdio`` is ``None`` for a spawned
    one, which inherits the parent's). ``output``: the task's own file for both streams (:attr:`Task.output`).
    """
    _exit_when_parent_dies()
    if stdio is not None:
        stdio.adopt()
    if output is not None:
        _write_to(output)
    started_with(os.environ)  # what glibc read as this process started (a fork server's), before the parent's
    if os.environ != environ:
        os.environ.clear()
        os.environ.update(environ)
    runner = TaskRunner(conn.send)
    try:
        conn.send(("started",))  # past the start-up (the main module imported): a death from now on is the task's
        try:
            fn, args = cloudpickle.loads(payload)
        except BaseException as e:
            message: tuple[Any, ...] = ("error", "start", None, one_line(e), traceback.format_exc(), None)
        else:
            message = runner(fn, args)
        try:
            conn.send(message)  # pickles first: an unpicklable value sends nothing, then an error
        except Exception as e:
            conn.send(("error", runner.at.phase, runner.at.step, one_line(e), traceback.format_exc(), None))
    finally:
        conn.close()


def _write_to(path: str) -> None:
    """This process's standard output and error (the descriptors and Python's streams) appended to ``path``."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    for target in (1, 2):
        os.dup2(fd, target)
    os.close(fd)


# ---------------------------------------------------------------------------------------------------------------------
# Parent side


@dataclass
class _Child:
    """A started task: its process, the read end of its pipe and what the parent knows so far."""

    task: Task
    process: BaseProcess
    conn: Connection
    at: Position = field(default_factory=Position)
    eof: bool = False
    started: bool = False  # its process reached _child_main (it sends "started" first)
    deadline: float | None = None  # set once its outcome or EOF arrived: when it is terminated if still alive


def _died(child: _Child) -> Failure:
    code = child.process.exitcode
    if code is not None and code < 0:
        try:
            how = f"killed by signal {signal.Signals(-code).name}"
        except ValueError:
            how = f"killed by signal {-code}"
    else:
        how = f"exit code {code}"
    script = None if child.started or code != 1 else _unguarded_script()
    if script is not None:
        return child.at.failure(
            child.task.key,
            f"worker process died ({how}) while starting: the script {script} runs run_spec at import: "
            "put it under if __name__ == '__main__':",
        )
    return child.at.failure(child.task.key, f"worker process died ({how})")


def _unguarded_script() -> str | None:
    """The parent's main script, when it is one (``python script.py``: a ``__file__``, no ``__spec__``), which a
    worker imports again as it starts (spawn, fork server): a worker that exits with code 1 before it reaches
    :func:`_child_main` then most likely ran the script's ``run_spec`` at import and was refused a process of its
    own (multiprocessing's bootstrapping error), which an ``if __name__ == "__main__":`` guard prevents. ``None``
    otherwise (``python -m``, an interactive session, pytest's own main module).
    """
    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if main is None or getattr(main, "__spec__", None) is not None or not isinstance(path, str):
        return None
    return path


def _read(child: _Child, on_line: Callable[[int, str], None] | None, limit: int | None) -> TaskOutcome | None:
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
            return child.at.failure(child.task.key, f"result could not be read: {one_line(e)}", traceback.format_exc())
        kind = message[0]
        if kind == "started":
            child.started = True
        elif kind == "report":
            _, phase, step, line = message
            child.at.move(phase, step)
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


def _context() -> BaseContext:
    """The fork server where the platform has one, with :data:`PRELOAD` (module docstring); else spawn.

    Spawn too where this process's fork server was already running, started by someone else (SB3's
    ``SubprocVecEnv`` starts it): its tasks would keep its environment, without libm's portable variants.
    """
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(PRELOAD))  # read when this process's server starts, at its first task
    return context if _start_fork_server() else multiprocessing.get_context("spawn")


_OWN_SERVER: list[int] = []  # the fork server's pid, where specguard started it (with libm's portable variants)


def _start_fork_server() -> bool:
    """Start this process's fork server, if it is not running, with libm's portable variants (glibc reads
    ``GLIBC_TUNABLES`` as a process starts; a forked task keeps its server's): :mod:`specguard.utils.numerics`.
    Whether the server running is specguard's own: ``False`` where another started it first."""
    from multiprocessing import forkserver

    server: Any = forkserver._forkserver  # the process's one server (multiprocessing keeps no public handle)
    running = getattr(server, "_forkserver_pid", None)
    if running is not None and running not in _OWN_SERVER:
        return False
    with _environ(with_libm(os.environ)):
        forkserver.ensure_running()
    pid = getattr(server, "_forkserver_pid", None)
    if pid is not None and pid not in _OWN_SERVER:
        _OWN_SERVER.append(pid)
    return True


@contextlib.contextmanager
def _environ(environ: Mapping[str, str]) -> Iterator[None]:
    """This process's environment is ``environ`` inside the block (a process started there inherits it)."""
    before = dict(os.environ)
    if before == environ:
        yield
        return
    os.environ.clear()
    os.environ.update(environ)
    try:
        yield
    finally:
        os.environ.clear()
        os.environ.update(before)


def _start(context: BaseContext, task: Task, payload: bytes) -> _Child:
    reader, writer = context.Pipe(duplex=False)
    process = context.Process(  # type: ignore[attr-defined]
        target=_child_main,
        args=(
            writer,
            payload,
            {**os.environ, **task.environ},
            _ParentStdio() if context.get_start_method() == "forkserver" and task.output is None else None,
            task.output,
        ),
        name=f"specguard-task-{task.key}",
        daemon=False,
    )
    spawned = context.get_start_method() != "forkserver"
    try:
        with _environ(with_libm({**os.environ, **task.environ}) if spawned else os.environ):  # read as it starts
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
    on_outcome: Callable[[int, TaskOutcome], None] | None = None,
    cancel: threading.Event | None = None,
) -> dict[int, TaskOutcome]:
    """Run every task in a process of its own (module docstring), at most ``max_workers`` at once.

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
        cancel: once set (from any thread), the children still running are terminated and the outcomes so far
            are returned, within :data:`~specguard.parallel.signals.STOP_POLL_S` (a pool's slot drops a task it
            no longer needs: :mod:`specguard.parallel.slots`).

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

    context = _context()
    pending = deque(tasks)
    children: list[_Child] = []
    outcomes: dict[int, TaskOutcome] = {}
    guard = SigtermGuard()
    guard.install()

    def stop_children() -> None:
        _stop(children)
        _release(children)

    try:
        while pending or children:
            if cancel is not None and cancel.is_set():
                return _in_task_order(tasks, outcomes)  # the finally below stops and reaps the children
            while pending and len(children) < max_workers:
                with guard.deferred():  # a started child is always registered, hence always stopped
                    task = pending.popleft()
                    children.append(_start(context, task, payloads[task.key]))

            deadlines = [c.deadline for c in children if c.deadline is not None]
            timeout = min([STOP_POLL_S, *(max(0.0, d - time.monotonic()) for d in deadlines)])
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
        guard.close(stop_children)  # a SIGTERM during the cleanup is raised once the children are gone


def _in_task_order(tasks: Sequence[Task], outcomes: dict[int, TaskOutcome]) -> dict[int, TaskOutcome]:
    return {t.key: outcomes[t.key] for t in tasks if t.key in outcomes}
