"""The slot pool: the most urgent task first, a core the foreground leaves idle takes work queued ahead, cancelled
tasks leave no process behind, and a task's own output file."""

from __future__ import annotations

import queue
import sys
import time
from pathlib import Path

import pytest

from specguard.parallel.protocol import Done, Failure, Task
from specguard.parallel.slots import FOREGROUND, PooledExecutor, SlotPool, wait_message


def stamp(path: str, seconds: float, *, report: object) -> float:
    """Write the start time to ``path``, sleep, return the end time."""
    Path(path).write_text(repr(time.time()))
    time.sleep(seconds)
    return time.time()


def fail(*, report: object) -> None:
    raise RuntimeError("boom")


def shout(text: str, *, report: object) -> int:
    print(text)
    print(text, file=sys.stderr)
    return 1


@pytest.fixture
def pool():
    made: list[SlotPool] = []

    def make(slots: int) -> SlotPool:
        made.append(SlotPool(slots))
        return made[-1]

    yield make
    for p in made:
        p.close()


def ends(inbox: queue.Queue, count: int) -> list:
    """The next ``count`` "end" messages' (ticket, outcome), in the order they came."""
    got = []
    deadline = time.monotonic() + 60
    while len(got) < count and time.monotonic() < deadline:
        message = wait_message(inbox)
        if message is not None and message[0] == "end":
            got.append(message[1:])
    return got


@pytest.mark.slow
def test_a_free_slot_takes_the_lowest_rank_then_the_first_submitted(pool, tmp_path):
    slots = pool(1)
    inbox: queue.Queue = queue.Queue()
    blocker = slots.submit(Task(9, stamp, (str(tmp_path / "9"), 1.0)), rank=FOREGROUND, inbox=inbox)
    time.sleep(0.3)  # the blocker holds the one slot
    order = [(1, "late"), (0, "now"), (1, "later"), (0, "now too")]
    tickets = {
        name: slots.submit(Task(i, stamp, (str(tmp_path / str(i)), 0.0)), rank=(rank,), inbox=inbox)
        for i, (rank, name) in enumerate(order)
    }
    done = ends(inbox, 5)
    assert [t for t, _ in done] == [blocker, tickets["now"], tickets["now too"], tickets["late"], tickets["later"]]


@pytest.mark.slow
def test_rerank_moves_a_queued_task_to_the_front(pool, tmp_path):
    slots = pool(1)
    inbox: queue.Queue = queue.Queue()
    slots.submit(Task(9, stamp, (str(tmp_path / "9"), 1.0)), rank=FOREGROUND, inbox=inbox)
    time.sleep(0.3)
    first = slots.submit(Task(0, stamp, (str(tmp_path / "0"), 0.0)), rank=(1, 0), inbox=inbox)
    wanted = slots.submit(Task(1, stamp, (str(tmp_path / "1"), 0.0)), rank=(1, 1), inbox=inbox)
    slots.rerank([wanted], FOREGROUND)
    done = ends(inbox, 3)
    assert [t for t, _ in done][1:] == [wanted, first]


@pytest.mark.slow
def test_an_idle_slot_trains_work_queued_ahead_while_the_foreground_batch_waits_for_its_slower_task(pool, tmp_path):
    """The main job's gap: a spec's faster seed ends, and the core it frees trains the next spec's seed at once."""
    slots = pool(2)
    ahead_inbox: queue.Queue = queue.Queue()
    slots.submit(Task(0, stamp, (str(tmp_path / "ahead"), 0.0)), rank=(1,), inbox=ahead_inbox)
    tasks = [Task(0, stamp, (str(tmp_path / "slow"), 2.0)), Task(1, stamp, (str(tmp_path / "fast"), 0.0))]
    outcomes = PooledExecutor(slots).run(tasks)
    slow_end = outcomes[0].value
    ahead_start = float((tmp_path / "ahead").read_text())
    assert ahead_start < slow_end, "the work ahead waited for the foreground's slower task"
    assert [k for k in outcomes] == [0, 1] and all(isinstance(o, Done) for o in outcomes.values())


@pytest.mark.slow
def test_stop_on_ends_the_batch_and_terminates_its_running_task(pool, tmp_path):
    slots = pool(2)
    start = time.monotonic()
    outcomes = PooledExecutor(slots).run(
        [Task(0, fail), Task(1, stamp, (str(tmp_path / "long"), 60.0))], stop_on=lambda failure: True
    )
    assert list(outcomes) == [0] and isinstance(outcomes[0], Failure) and outcomes[0].cause == "RuntimeError: boom"
    assert time.monotonic() - start < 30, "the long task was waited for, not terminated"
    assert not slots._running


@pytest.mark.slow
def test_cancelling_a_running_task_ends_it_without_an_outcome(pool, tmp_path):
    slots = pool(1)
    inbox: queue.Queue = queue.Queue()
    ticket = slots.submit(Task(0, stamp, (str(tmp_path / "long"), 60.0)), rank=FOREGROUND, inbox=inbox)
    queued = slots.submit(Task(1, stamp, (str(tmp_path / "never"), 0.0)), rank=FOREGROUND, inbox=inbox)
    while not (tmp_path / "long").exists():
        time.sleep(0.05)
    running = slots.cancel([ticket, queued])
    assert running == [ticket]
    assert ticket.ended.wait(30)
    assert {t: outcome for t, outcome in ends(inbox, 2)} == {ticket: None, queued: None}
    assert not (tmp_path / "never").exists()


@pytest.mark.slow
def test_close_stops_what_runs_and_what_is_queued(pool, tmp_path):
    slots = SlotPool(1)
    inbox: queue.Queue = queue.Queue()
    ticket = slots.submit(Task(0, stamp, (str(tmp_path / "long"), 60.0)), rank=FOREGROUND, inbox=inbox)
    slots.submit(Task(1, stamp, (str(tmp_path / "never"), 0.0)), rank=FOREGROUND, inbox=inbox)
    while not (tmp_path / "long").exists():
        time.sleep(0.05)
    start = time.monotonic()
    slots.close()
    assert time.monotonic() - start < 30 and ticket.ended.is_set()
    assert not (tmp_path / "never").exists()
    with pytest.raises(RuntimeError, match="closed"):
        slots.submit(Task(2, fail), rank=FOREGROUND, inbox=inbox)


@pytest.mark.slow
def test_a_task_with_an_output_file_writes_there_not_to_the_parent(pool, tmp_path, capfd):
    out = tmp_path / "task.out"
    outcomes = PooledExecutor(pool(1)).run([Task(0, shout, ("hello from the task",), output=str(out))])
    assert outcomes[0] == Done(0, 1)
    assert out.read_text().count("hello from the task") == 2  # its standard output and error
    assert "hello from the task" not in capfd.readouterr().out + capfd.readouterr().err


def test_slots_must_be_positive():
    with pytest.raises(ValueError, match="slots must be >= 1, got 0"):
        SlotPool(0)
