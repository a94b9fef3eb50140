"""Interruptions: SIGTERM as ``KeyboardInterrupt`` around a batch of tasks, and one stop for every batch at once."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

__all__ = ["SigtermGuard", "raise_if_stopping", "stopping_all_tasks"]

STOP_POLL_S = 0.25
"""How often a waiting batch looks whether :func:`stopping_all_tasks` asks it to stop."""

_STOPPING = threading.Event()


@contextlib.contextmanager
def stopping_all_tasks() -> Iterator[None]:
    """While inside, every :func:`run_tasks` of this process, on any thread, stops its children and raises.

    A signal reaches only the main thread. A caller that runs :func:`run_tasks`
    on threads of its own (``specguard reproduce`` trains several specs at once)
    enters this block on its interruption and waits for its threads there: each
    ``run_tasks`` notices within :data:`STOP_POLL_S`, terminates and reaps its
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

    def close(self, cleanup: Callable[[], None]) -> None:
        """Run ``cleanup`` (stop and reap what the guarded block started), then restore the previous handler.

        A SIGTERM during ``cleanup`` does not cut it short: it is raised as
        ``KeyboardInterrupt`` once the cleanup is done and the handler restored.
        """
        self.deferring = True
        try:
            cleanup()
        finally:
            self.deferring = False
            self.restore()
        if self.pending:
            self.pending = False
            raise KeyboardInterrupt("SIGTERM received")

    def restore(self) -> None:
        if self.installed:
            # None: the previous handler was not installed from Python and cannot be put back.
            signal.signal(signal.SIGTERM, signal.SIG_DFL if self.previous is None else self.previous)
            self.installed = False
