"""Where runs train: the local process pool (default) or a Dask cluster, chosen by address.

The engine hands an executor a batch of tasks (one per seed) and gets back one
outcome per task: :class:`~specguard.parallel.protocol.Done` or
:class:`~specguard.parallel.protocol.Failure`. The driver keeps the cache: it looks runs
up before submitting, submits only missing seeds, and stores what comes back
(results and model bytes), so cluster workers need no shared filesystem.

* ``"local"``: :func:`specguard.parallel.workers.run_tasks`, one process per
  seed on this machine.
* ``"tcp://host:8786"`` (any Dask scheduler address: ``tcp``, ``tls``, ``ws``,
  ``wss``, ``ucx``): the seeds run as tasks on that Dask cluster (a
  ``dask scheduler`` with ``dask worker``s, a ``dask-jobqueue`` SLURM cluster,
  a ``LocalCluster``). Needs the ``cluster`` extra (``distributed``).

Why Dask and not Ray: see docs/guide/pytest-plugin.md, "Scaling out" (measured on this machine).

Example:
    >>> check_address("local"), check_address("tcp://127.0.0.1:8786")
    ('local', 'tcp://127.0.0.1:8786')
"""

from __future__ import annotations

import contextlib
import time
import uuid
from collections.abc import Callable, Sequence
from typing import Any, Protocol

from specguard.error import ExecutorError
from specguard.parallel.protocol import Failure, Position, Task, TaskOutcome, TaskRunner, outcome_of
from specguard.parallel.signals import SigtermGuard, raise_if_stopping
from specguard.parallel.workers import run_tasks

__all__ = ["LOCAL", "DaskExecutor", "Executor", "ExecutorError", "LocalExecutor", "check_address", "make_executor"]

LOCAL = "local"
DASK_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx", "inproc")
_POLL_S = 0.25
ADDRESS_EXPECTED = "expected 'local' or a Dask scheduler address such as 'tcp://host:8786'"


class Executor(Protocol):
    """Runs a batch of tasks and returns one outcome per finished task, in task order.

    ``on_outcome(key, outcome)`` is called as each task ends (the engine stores a
    finished seed at once, so an interrupted batch keeps it), ``stop_on`` after it.
    """

    def run(
        self,
        tasks: Sequence[Task],
        *,
        on_line: Callable[[int, str], None] | None = None,
        stop_on: Callable[[Failure], bool] | None = None,
        on_outcome: Callable[[int, TaskOutcome], None] | None = None,
    ) -> dict[int, TaskOutcome]: ...

    def close(self) -> None: ...


def check_address(address: object) -> str:
    """The one parser of executor addresses: ``"local"`` or ``scheme://host:port`` of a Dask scheduler.

    Raises:
        ExecutorError: anything else, with what was expected.
    """
    if isinstance(address, str):
        text = address.strip()
        if text == LOCAL:
            return text
        scheme, sep, rest = text.partition("://")
        if sep and scheme in DASK_SCHEMES and rest:
            return text
    raise ExecutorError(f"executor: {ADDRESS_EXPECTED} (schemes: {', '.join(DASK_SCHEMES)}), got {address!r}")


def make_executor(address: str, *, workers: int) -> Executor:
    """The executor for ``address``; for a cluster, connected (so a bad address fails before anything trains).

    Args:
        address: ``"local"`` or a Dask scheduler address.
        workers: parallel processes of the local pool (a cluster has its own).
    """
    if check_address(address) == LOCAL:
        return LocalExecutor(workers)
    return DaskExecutor(address)


class LocalExecutor:
    """One process per task on this machine (:func:`~specguard.parallel.workers.run_tasks`), at most ``workers``."""

    def __init__(self, workers: int) -> None:
        self.workers = workers

    def run(
        self,
        tasks: Sequence[Task],
        *,
        on_line: Callable[[int, str], None] | None = None,
        stop_on: Callable[[Failure], bool] | None = None,
        on_outcome: Callable[[int, TaskOutcome], None] | None = None,
    ) -> dict[int, TaskOutcome]:
        return run_tasks(tasks, max_workers=self.workers, on_line=on_line, stop_on=stop_on, on_outcome=on_outcome)

    def close(self) -> None:
        pass


def _on_cluster(fn: Callable[..., Any], args: tuple[Any, ...], queue: str, key: int) -> tuple[Any, ...]:
    """A task's body on a Dask worker: run it, forward its reports to the driver's queue, return its outcome."""
    from distributed import Queue

    reports = Queue(queue)
    return TaskRunner(lambda message: reports.put([key, *message[1:]]))(fn, args)


class DaskExecutor:
    """Tasks as Dask futures on the cluster whose scheduler is at ``address``.

    A task that raises gives a :class:`~specguard.parallel.protocol.Failure` with its
    phase, step and cause, as locally. A worker that dies mid-task is handled by
    Dask: the scheduler retries the task on another worker up to its
    ``distributed.scheduler.allowed-failures`` (default 3), then the seed fails
    alone with ``KilledWorker``. Progress lines reach the driver live through a
    ``distributed.Queue``. On Ctrl-C or SIGTERM the driver cancels every
    future; a task already running on a worker cannot be interrupted by Dask
    and finishes there, its result dropped.

    Raises:
        ExecutorError: ``distributed`` is not installed, or no scheduler
            answers at ``address`` within ``timeout`` seconds.
    """

    def __init__(self, address: str, *, timeout: float = 10.0) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise ExecutorError(
                f"executor {address!r}: Dask's 'distributed' is not installed; "
                'install specguard with the cluster extra: pip install "specguard[cluster]"'
            ) from None
        self.address = address
        self.submitted = 0  # tasks sent to the cluster, for tests and reports
        try:
            self.client = Client(address, timeout=timeout, set_as_default=False)
        except (OSError, TimeoutError) as e:
            raise ExecutorError(
                f"executor {address!r}: no Dask scheduler answered within {timeout:g} s ({type(e).__name__}: {e}); "
                "start one with `dask scheduler` and `dask worker ADDRESS`, or use --executor local"
            ) from None

    def run(
        self,
        tasks: Sequence[Task],
        *,
        on_line: Callable[[int, str], None] | None = None,
        stop_on: Callable[[Failure], bool] | None = None,
        on_outcome: Callable[[int, TaskOutcome], None] | None = None,
    ) -> dict[int, TaskOutcome]:
        from distributed import Queue

        if not tasks:
            return {}
        batch = uuid.uuid4().hex
        queue = Queue(f"specguard-{batch}", client=self.client)
        where = {t.key: Position() for t in tasks}
        futures = {
            self.client.submit(_on_cluster, t.fn, t.args, queue.name, t.key, key=f"specguard-{batch}-{t.key}"): t.key
            for t in tasks
        }
        self.submitted += len(futures)
        outcomes: dict[int, TaskOutcome] = {}
        pending = set(futures)
        guard = SigtermGuard()
        guard.install()

        def cancel_pending() -> None:
            if pending:
                self.client.cancel(list(pending), force=True)
            with contextlib.suppress(Exception):
                queue.close()

        try:
            while pending:
                self._drain(queue, where, on_line)
                finished = [f for f in pending if f.done()]
                if not finished:
                    time.sleep(_POLL_S)  # seeds take minutes: polling costs nothing that matters
                    raise_if_stopping()  # the finally below cancels what is pending
                for future in finished:
                    pending.discard(future)
                    key = futures[future]
                    outcome = self._outcome(future, key, where[key])
                    outcomes[key] = outcome
                    if on_outcome is not None:
                        self._drain(queue, where, on_line)  # its last progress lines before its result
                        on_outcome(key, outcome)
                    if isinstance(outcome, Failure) and stop_on is not None and stop_on(outcome):
                        return {t.key: outcomes[t.key] for t in tasks if t.key in outcomes}
            self._drain(queue, where, on_line)
            return {t.key: outcomes[t.key] for t in tasks if t.key in outcomes}
        finally:
            guard.close(cancel_pending)

    @staticmethod
    def _drain(queue: Any, where: dict[int, Position], on_line: Callable[[int, str], None] | None) -> None:
        for key, phase, step, line in queue.get(batch=True):
            where[key].move(phase, step)
            if line is not None and on_line is not None:
                on_line(key, line)

    @staticmethod
    def _outcome(future: Any, key: int, where: Position) -> TaskOutcome:
        if future.status == "finished":
            return outcome_of(key, future.result())
        error = future.exception()
        cause = f"cluster worker failed ({type(error).__name__}: {error})"
        return where.failure(key, cause.splitlines()[0])

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.close()
