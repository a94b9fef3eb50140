"""specguard.parallel.workers: one process per task, each failing alone, none left behind.

The task functions below live in this module. ``tests/`` is not a package, so the module is
registered with cloudpickle to be pickled by value: the spawned children get the functions
themselves and never import this file (``test_module_functions_ship_by_value`` checks it).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from typing import Any

import cloudpickle
import numpy as np
import pytest

from specguard.error import InvalidSpec
from specguard.parallel.protocol import Done, Failure, Report, Task, TaskOutcome
from specguard.parallel.signals import stopping_all_tasks
from specguard.parallel.workers import parse_workers, resolve_workers, run_tasks

cloudpickle.register_pickle_by_value(sys.modules[__name__])

REPO = Path(__file__).resolve().parents[1]


# ---------------------------------------------------------------------------------------------------------------------
# Task functions (run in the children)


def sleep_then_return(value: int, seconds: float, *, report: Report) -> tuple[int, float, float]:
    start = time.time()
    time.sleep(seconds)
    return value, start, time.time()


def count_lines(key: int, n: int, *, report: Report) -> int:
    for i in range(n):
        report("train", i, f"task {key} line {i}")
    report("eval", None, None)
    return n


def wait_for_file(path: str, timeout: float, *, report: Report) -> str:
    deadline = time.monotonic() + timeout
    while not os.path.exists(path):
        if time.monotonic() > deadline:
            raise TimeoutError(f"{path} never appeared")
        time.sleep(0.05)
    return "saw it"


def _explode(step: int) -> None:
    raise ValueError(f"boom at {step}\nsecond line of the message")


def raise_after_report(*, report: Report) -> None:
    report("fit", 7, None)
    _explode(7)


class ShippedError(Exception):
    """Defined here, so shipped by value to the child: it must come back as this very class."""


def raise_shipped(*, report: Report) -> None:
    raise ShippedError("custom")


class UnpicklableError(Exception):
    """Pickles, but cannot be unpickled: ``__init__`` takes two arguments, ``args`` holds one."""

    def __init__(self, a: int, b: int) -> None:
        super().__init__(f"a={a} b={b}")


def raise_unpicklable(*, report: Report) -> None:
    raise UnpicklableError(1, 2)


def kill_self(*, report: Report) -> None:
    report("train", 3, None)
    os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(30)


def exit_3(*, report: Report) -> None:
    report("load", None, None)
    os._exit(3)


def return_a_lambda(*, report: Report) -> Any:
    report("done-ish", 1, None)
    return lambda: 1


def apply(f: Any, x: int, *, report: Report) -> Any:
    return f(x)


def module_is_imported(*, report: Report) -> bool:
    return __name__ in sys.modules


def write_pid_then_sleep(pid_file: str, done_file: str, *, report: Report) -> None:
    Path(pid_file).write_text(str(os.getpid()))
    time.sleep(30)
    Path(done_file).write_text("finished")


def fail_once_file_exists(path: str, *, report: Report) -> None:
    report("check", 0, None)
    _wait_for(lambda: Path(path).exists(), 20)
    raise RuntimeError("spec error that every seed would hit")


def touch(path: str, *, report: Report) -> None:
    Path(path).write_text("ran")


def read_environment(name: str, *, report: Report) -> str | None:
    return os.environ.get(name)


def write_to_stderr(text: str, *, report: Report) -> None:
    print(text, file=sys.stderr, flush=True)


def libraries_loaded(*, report: Report) -> dict[str, bool]:
    """Which heavy libraries the process had imported before the task ran (the fork server's preload)."""
    return {name: name in sys.modules for name in ("torch", "stable_baselines3", "gymnasium")}


# ---------------------------------------------------------------------------------------------------------------------
# Helpers (run in the test process)


def _wait_for(condition: Any, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return bool(condition())


def _pid_gone(pid: int) -> bool:
    """The process no longer exists (reaped)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


def _pid_exited(pid: int) -> bool:
    """The process has exited: reaped, or a zombie waiting for a reaper that is not ours."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return True
    return "\nState:\tZ" in status


def _failure(outcome: TaskOutcome) -> Failure:
    assert isinstance(outcome, Failure), outcome
    return outcome


# ---------------------------------------------------------------------------------------------------------------------
# Tests


@pytest.mark.slow
def test_results_of_all_tasks_by_key_in_task_order_at_most_max_workers_at_once() -> None:
    tasks = [
        Task(10, sleep_then_return, (100, 0.3)),
        Task(11, sleep_then_return, (101, 3.0)),
        Task(12, sleep_then_return, (102, 0.3)),
        Task(13, sleep_then_return, (103, 0.0)),
    ]
    outcomes = run_tasks(tasks, max_workers=2)
    assert list(outcomes) == [10, 11, 12, 13]  # task order, not completion order
    assert all(isinstance(o, Done) and o.key == k for k, o in outcomes.items())
    values = {k: o.value for k, o in outcomes.items() if isinstance(o, Done)}
    assert [values[k][0] for k in (10, 11, 12, 13)] == [100, 101, 102, 103]
    spans = [values[k][1:] for k in (10, 11, 12, 13)]
    for start, _ in spans:
        assert sum(s <= start < e for s, e in spans) <= 2  # never more than max_workers running
    # task 12 took the place of task 10 as soon as it ended, without waiting for the slow task 11
    assert values[12][1] < values[11][2]
    assert multiprocessing.active_children() == []


@pytest.mark.slow
def test_progress_lines_reach_on_line_in_order_per_key() -> None:
    lines: list[tuple[int, str]] = []
    outcomes = run_tasks(
        [Task(0, count_lines, (0, 30)), Task(1, count_lines, (1, 30))],
        max_workers=2,
        on_line=lambda key, line: lines.append((key, line)),
    )
    assert outcomes == {0: Done(0, 30), 1: Done(1, 30)}
    for key in (0, 1):
        assert [line for k, line in lines if k == key] == [f"task {key} line {i}" for i in range(30)]
    assert len(lines) == 60  # the report without a line was not passed on


@pytest.mark.slow
def test_exception_is_a_one_line_failure_and_the_other_result_is_kept() -> None:
    seen: list[Failure] = []

    def stop_on(failure: Failure) -> bool:
        seen.append(failure)
        return False

    outcomes = run_tasks(
        [Task(0, raise_after_report), Task(1, sleep_then_return, (5, 0.5))], max_workers=2, stop_on=stop_on
    )
    failure = _failure(outcomes[0])
    assert failure.cause == "ValueError: boom at 7"
    assert (failure.phase, failure.step) == ("fit", 7)
    assert "_explode" in failure.traceback and "second line of the message" in failure.traceback
    assert isinstance(failure.exception, ValueError)
    assert str(failure.exception).startswith("boom at 7")
    assert seen == [failure]
    done = outcomes[1]
    assert isinstance(done, Done) and done.value[0] == 5


@pytest.mark.slow
def test_exception_class_shipped_by_value_comes_back_as_that_class() -> None:
    failure = _failure(run_tasks([Task(0, raise_shipped)], max_workers=1)[0])
    assert failure.cause == "ShippedError: custom"
    assert (failure.phase, failure.step) == ("start", None)
    assert type(failure.exception) is ShippedError


@pytest.mark.slow
def test_exception_that_cannot_be_unpickled_still_gives_cause_and_traceback() -> None:
    failure = _failure(run_tasks([Task(0, raise_unpicklable)], max_workers=1)[0])
    assert failure.cause == "UnpicklableError: a=1 b=2"
    assert "raise_unpicklable" in failure.traceback
    assert failure.exception is None


@pytest.mark.slow
def test_a_task_reads_the_environment_the_parent_has_when_it_starts(monkeypatch: pytest.MonkeyPatch) -> None:
    run_tasks([Task(0, touch, (os.devnull,))], max_workers=1)  # the fork server, if any, started before the change
    monkeypatch.setenv("SPECGUARD_TEST_VALUE", "set after the first task")
    assert run_tasks([Task(1, read_environment, ("SPECGUARD_TEST_VALUE",))], max_workers=1) == {
        1: Done(1, "set after the first task")
    }
    monkeypatch.delenv("SPECGUARD_TEST_VALUE")
    assert run_tasks([Task(2, read_environment, ("SPECGUARD_TEST_VALUE",))], max_workers=1) == {2: Done(2, None)}


@pytest.mark.slow
def test_a_task_writes_to_the_parents_stderr_of_when_it_starts(tmp_path: Path) -> None:
    run_tasks([Task(0, touch, (os.devnull,))], max_workers=1)  # the fork server, if any, holds other descriptors
    saved = os.dup(2)
    try:
        with open(tmp_path / "stderr.txt", "w") as f:
            os.dup2(f.fileno(), 2)
            outcomes = run_tasks([Task(1, write_to_stderr, ("a line from the task",))], max_workers=1)
    finally:
        os.dup2(saved, 2)
        os.close(saved)
    assert outcomes == {1: Done(1, None)}
    assert "a line from the task" in (tmp_path / "stderr.txt").read_text()


@pytest.mark.slow
@pytest.mark.skipif("forkserver" not in multiprocessing.get_all_start_methods(), reason="spawned: no fork server")
def test_tasks_start_with_the_heavy_libraries_already_imported() -> None:
    loaded = run_tasks([Task(0, libraries_loaded)], max_workers=1)[0]
    assert loaded == Done(0, {"torch": True, "stable_baselines3": True, "gymnasium": True})


@pytest.mark.slow
@pytest.mark.skipif("forkserver" not in multiprocessing.get_all_start_methods(), reason="spawned: no fork server")
def test_a_fork_server_someone_else_started_first_is_not_used_for_portable_tasks() -> None:
    # SB3's SubprocVecEnv starts the process's fork server without libm's portable variants; a task it forked
    # would keep that environment (and a portable run refuse to train). specguard spawns its tasks instead.
    script = textwrap.dedent(
        """
        import os
        from multiprocessing import forkserver
        os.environ.pop("GLIBC_TUNABLES", None)
        forkserver.ensure_running()
        from specguard.parallel.protocol import Task
        from specguard.parallel.workers import _context, run_tasks
        from specguard.utils.numerics import hold_numerics, numerics_environ
        print(_context().get_start_method())
        portable = numerics_environ("portable")
        task = Task(0, lambda report: hold_numerics("portable", "task", lambda: "DEFAULT"), (), portable)
        print(run_tasks([task], max_workers=1)[0].value)
        """
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.stdout.split() == ["spawn", "portable"], done.stderr


@pytest.mark.slow
def test_killed_worker_fails_alone_with_its_last_phase_and_step() -> None:
    outcomes = run_tasks([Task(0, kill_self), Task(1, sleep_then_return, (1, 1.0))], max_workers=2)
    failure = _failure(outcomes[0])
    assert failure.cause == "worker process died (killed by signal SIGKILL)"
    assert (failure.phase, failure.step) == ("train", 3)
    assert failure.traceback == "" and failure.exception is None
    assert isinstance(outcomes[1], Done)


@pytest.mark.slow
def test_exit_code_of_a_worker_that_exits_without_result() -> None:
    outcomes = run_tasks([Task(0, exit_3), Task(1, sleep_then_return, (1, 0.0))], max_workers=1)
    failure = _failure(outcomes[0])
    assert failure.cause == "worker process died (exit code 3)"
    assert (failure.phase, failure.step) == ("load", None)
    assert isinstance(outcomes[1], Done)  # started after the death, with max_workers=1


@pytest.mark.slow
def test_unpicklable_result_is_a_failure_of_that_task() -> None:
    failure = _failure(run_tasks([Task(0, return_a_lambda)], max_workers=1)[0])
    assert "\n" not in failure.cause and "lambda" in failure.cause
    assert (failure.phase, failure.step) == ("done-ish", 1)


@pytest.mark.slow
def test_lambdas_travel_and_module_functions_ship_by_value() -> None:
    outcomes = run_tasks(
        [
            Task(0, apply, (lambda x: x + 1, 41)),
            Task(1, lambda x, report: x * 2, (21,)),
            Task(2, module_is_imported),
        ],
        max_workers=2,
    )
    assert outcomes == {0: Done(0, 42), 1: Done(1, 42), 2: Done(2, False)}


@pytest.mark.slow
def test_stop_on_returns_at_once_and_terminates_the_others(tmp_path: Path) -> None:
    pid_file, done_file, never = tmp_path / "pid", tmp_path / "done", tmp_path / "never"
    start = time.monotonic()
    outcomes = run_tasks(
        [
            Task(0, write_pid_then_sleep, (str(pid_file), str(done_file))),
            Task(1, fail_once_file_exists, (str(pid_file),)),
            Task(2, touch, (str(never),)),
        ],
        max_workers=2,
        stop_on=lambda failure: failure.cause.startswith("RuntimeError"),
    )
    assert time.monotonic() - start < 10
    assert list(outcomes) == [1]
    assert _failure(outcomes[1]).cause == "RuntimeError: spec error that every seed would hit"
    assert _pid_gone(int(pid_file.read_text()))  # terminated and reaped
    time.sleep(0.2)
    assert not done_file.exists() and not never.exists()
    assert multiprocessing.active_children() == []


@pytest.mark.slow
def test_sigterm_handler_is_restored_and_non_main_threads_leave_signals_alone() -> None:
    before = signal.getsignal(signal.SIGTERM)
    assert run_tasks([Task(0, sleep_then_return, (1, 0.0))], max_workers=1)[0].key == 0
    assert signal.getsignal(signal.SIGTERM) is before

    result: list[dict[int, TaskOutcome]] = []
    errors: list[BaseException] = []

    def target() -> None:
        try:
            result.append(run_tasks([Task(0, count_lines, (0, 2))], max_workers=1))
        except BaseException as e:
            errors.append(e)

    thread = threading.Thread(target=target)
    thread.start()
    thread.join(30)
    assert errors == [] and result == [{0: Done(0, 2)}]


@pytest.mark.slow
def test_stopping_all_tasks_stops_run_tasks_on_another_thread_and_then_lets_calls_run(tmp_path: Path) -> None:
    pid_file, done_file = tmp_path / "pid", tmp_path / "done"
    errors: list[BaseException] = []

    def target() -> None:
        try:
            run_tasks([Task(0, write_pid_then_sleep, (str(pid_file), str(done_file)))], max_workers=1)
        except BaseException as e:
            errors.append(e)

    thread = threading.Thread(target=target)
    thread.start()
    assert _wait_for(lambda: pid_file.exists() and pid_file.read_text() != "", 30), "the child never started"
    with stopping_all_tasks():
        thread.join(20)  # the child sleeps 30 s: only the stop ends the thread this soon
    assert not thread.is_alive()
    assert [type(e) for e in errors] == [KeyboardInterrupt]
    assert _pid_gone(int(pid_file.read_text())) and not done_file.exists()
    assert multiprocessing.active_children() == []
    assert run_tasks([Task(0, sleep_then_return, (1, 0.0))], max_workers=1)[0].key == 0  # left: calls run again


def test_invalid_arguments(tmp_path: Path) -> None:
    marker = str(tmp_path / "ran")
    with pytest.raises(ValueError, match="max_workers"):
        run_tasks([Task(0, touch, (marker,))], max_workers=0)
    with pytest.raises(ValueError, match="unique"):
        run_tasks([Task(0, touch, (marker,)), Task(0, touch, (marker,))], max_workers=1)
    assert run_tasks([], max_workers=1) == {}
    with pytest.raises(TypeError, match="lock"):  # an unpicklable task fails before any process starts
        run_tasks([Task(0, touch, (marker,)), Task(1, apply, (threading.Lock(), 1))], max_workers=1)
    assert not Path(marker).exists() and multiprocessing.active_children() == []


# ---------------------------------------------------------------------------------------------------------------------
# A parent process that is signalled: run in a subprocess, with its task in an importable module


HELPER = """
import os, time
from pathlib import Path


def write_pid_then_sleep(pid_file, *, report):
    report("train", 0, None)
    Path(pid_file).write_text(str(os.getpid()))
    time.sleep(60)
"""

PARENT = """
import signal, sys
import sg_worker_helper
from specguard.parallel.protocol import Task
from specguard.parallel.workers import run_tasks, parse_workers, resolve_workers

try:
    run_tasks([Task(0, sg_worker_helper.write_pid_then_sleep, (sys.argv[1],))], max_workers=1)
except KeyboardInterrupt:
    print("interrupted; handler restored:", signal.getsignal(signal.SIGTERM) is signal.SIG_DFL, flush=True)
    sys.exit(5)
print("run_tasks returned", flush=True)
"""


def _start_parent(tmp_path: Path) -> tuple[subprocess.Popen[str], int]:
    (tmp_path / "sg_worker_helper.py").write_text(textwrap.dedent(HELPER))
    pid_file = tmp_path / "child.pid"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), str(tmp_path)])}
    parent = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(PARENT), str(pid_file)],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    if not _wait_for(lambda: pid_file.exists() and pid_file.read_text() != "", 30):
        parent.kill()
        pytest.fail(f"the child never started: {parent.communicate()[0]}")
    return parent, int(pid_file.read_text())


@pytest.mark.slow
def test_sigterm_to_the_parent_stops_its_child_and_the_parent_exits(tmp_path: Path) -> None:
    parent, child_pid = _start_parent(tmp_path)
    start = time.monotonic()
    parent.send_signal(signal.SIGTERM)
    try:
        output, _ = parent.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        parent.kill()
        os.kill(child_pid, signal.SIGKILL)
        pytest.fail("the parent did not exit within 10 s of SIGTERM")
    assert time.monotonic() - start < 10
    assert parent.returncode == 5, output
    assert "interrupted; handler restored: True" in output
    assert _wait_for(lambda: _pid_gone(child_pid), 2), "the child outlived its parent"


@pytest.mark.slow
def test_child_exits_by_itself_when_its_parent_is_killed(tmp_path: Path) -> None:
    parent, child_pid = _start_parent(tmp_path)
    parent.kill()  # SIGKILL: no cleanup runs in the parent
    parent.wait(10)
    try:
        assert _wait_for(lambda: _pid_exited(child_pid), 10), "the orphaned child kept running"
    finally:
        if not _pid_exited(child_pid):
            os.kill(child_pid, signal.SIGKILL)


@pytest.mark.parametrize(("value", "parsed"), [("auto", "auto"), (3, 3), ("2", 2), (" 4 ", 4), (np.int64(2), 2)])
def test_parse_workers(value, parsed):
    assert parse_workers(value) == parsed


@pytest.mark.parametrize("value", [0, -1, "0", "two", 1.5, True, None, "", "05"])
def test_parse_workers_refuses(value):
    # "05" went through str.isdigit here while checkpoint counts refused it: one rule now (utils.options.parse_count)
    message = r"^workers: expected an integer >= 1 \(or 'auto': one per usable core\), got "
    with pytest.raises(InvalidSpec, match=message):
        parse_workers(value)
    with pytest.raises(InvalidSpec, match=message):  # one error type, a SpecError: each door makes it its usage error
        resolve_workers(value, share=2)


def test_run_spec_resolves_workers_by_the_same_function(tmp_path):
    import specguard as sg
    import specguard.engine.run_spec
    from example_specs import pendulum

    assert specguard.engine.run_spec.resolve_workers is resolve_workers  # the one rule, not a second
    spec = sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(timesteps=10), expect=0.5)
    with pytest.raises(sg.SpecError, match=r"workers: expected an integer >= 1 .*got True"):
        sg.run_spec(spec, workers=True, cache_dir=tmp_path)  # refused before anything trains


def test_reproduce_resolves_workers_by_the_same_function():
    from specguard.engine.reproduce import reproduce

    # it clamped with max(1, workers): 0 and -3 trained one spec at a time, "auto" raised a TypeError
    with pytest.raises(InvalidSpec, match=r"workers: expected an integer >= 1 .*got 0"):
        reproduce([], workers=0)


def test_auto_shares_the_cores():
    cores = resolve_workers("auto")
    assert cores >= 1
    assert resolve_workers("auto", share=cores) == 1
    assert resolve_workers("auto", share=cores * 4) == 1  # never 0
    assert resolve_workers(5, share=8) == 5  # an explicit count is taken as given


@pytest.mark.slow
def test_each_outcome_reaches_the_caller_as_its_task_ends(tmp_path):
    # Task 1 ends only once the parent has been told of task 0: an outcome held back to the batch's end fails it.
    marker = tmp_path / "task 0 ended"
    seen: list[tuple[int, TaskOutcome]] = []

    def on_outcome(key: int, outcome: TaskOutcome) -> None:
        seen.append((key, outcome))
        if key == 0:
            marker.write_text("")

    tasks = [Task(0, sleep_then_return, (0, 0.0)), Task(1, wait_for_file, (str(marker), 60.0))]
    outcomes = run_tasks(tasks, max_workers=2, on_outcome=on_outcome)
    assert isinstance(outcomes[1], Done) and outcomes[1].value == "saw it"
    assert [key for key, _ in seen] == [0, 1] and dict(seen) == outcomes


UNGUARDED = """
from specguard.parallel.protocol import Task
from specguard.parallel.workers import run_tasks

def double(x, *, report):
    return 2 * x

print(run_tasks([Task(0, double, (1,))], max_workers=1)[0].cause, flush=True)
"""


@pytest.mark.slow
def test_a_worker_dead_at_the_import_of_an_unguarded_script_names_the_script(tmp_path: Path) -> None:
    script = tmp_path / "unguarded.py"
    script.write_text(textwrap.dedent(UNGUARDED))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=120)
    assert done.stdout.strip().splitlines()[-1] == (
        f"worker process died (exit code 1) while starting: the script {script} runs run_spec at import: "
        "put it under if __name__ == '__main__':"
    ), done.stdout + done.stderr
