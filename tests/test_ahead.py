"""Training ahead: planned runs are locked and trained on free slots, handed to the foreground with their lock
(recorded as trained, not cached), never checked in place, and stored when the session stops before asking."""

from __future__ import annotations

import queue
import time
from pathlib import Path

import pytest
from test_slots import stamp

import specguard as sg
from example_specs import pendulum
from specguard.cache.fingerprint import fingerprint_spec
from specguard.cache.store import Cache, try_acquire
from specguard.engine.ahead import TrainAhead
from specguard.engine.run_spec import RunOptions, run_with
from specguard.parallel.protocol import Done, Task
from specguard.parallel.slots import FOREGROUND, PooledExecutor, SlotPool

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
pytest_plugins = ["pytester"]


def spec(timesteps=128, **kwargs):
    budget = sg.Budget(timesteps=timesteps, min_seeds=2, max_seeds=2, eval_episodes=4, checkpoints=1)
    tree, expect = pendulum.trees["w"], {"pendulum": 0.0}
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=TINY))
    return sg.Spec(pendulum.initial_env, tree, budget=budget, expect=expect, **kwargs)


@pytest.fixture
def slots():
    pool = SlotPool(2)
    yield pool
    pool.close()


def options(cache: Path, pool: SlotPool, ahead: TrainAhead | None) -> RunOptions:
    return RunOptions(workers=2, cache_dir=cache, progress=None, executor=PooledExecutor(pool), ahead=ahead)


@pytest.mark.slow
def test_planned_runs_are_handed_over_with_their_lock_and_recorded_as_trained(tmp_path, slots):
    first, second = spec(), spec(timesteps=192)
    ahead = TrainAhead(slots, Cache(tmp_path))
    ahead.plan([first, second])
    keys = [fingerprint_spec(s).run_key(seed) for s in (first, second) for seed in (0, 1)]
    assert ahead.planned == keys
    assert not try_acquire(Cache(tmp_path).lock(keys[2], 1.0)), "a planned run is locked against other processes"

    handed = ahead.take(keys[2])
    assert handed is not None and isinstance(handed.outcome, Done)
    assert not try_acquire(Cache(tmp_path).lock(keys[2], 1.0)), "the lock travels with the handed run"
    handed.lock.release()

    result = run_with(first, options(tmp_path, slots, ahead))
    assert result.cached == {0: False, 1: False} and result.passed
    assert ahead.take(keys[0]) is None, "a run is handed over once"
    again = run_with(first, options(tmp_path, slots, None))
    assert again.cached == {0: True, 1: True}, "what was handed over was stored by the foreground"
    assert [r.weights_digest for r in again.runs] == [r.weights_digest for r in result.runs]
    ahead.close()


def _wait_for_start(planned, deadline_s=60.0):
    deadline = time.monotonic() + deadline_s
    while not any(run.ticket.started for run in planned) and time.monotonic() < deadline:
        time.sleep(0.05)


@pytest.mark.slow
def test_planned_runs_start_longest_ceiling_first(tmp_path):
    """The longest-processing-time rule: a spec planned later with a larger ceiling starts first (its seeds in
    order), so one long seed does not start last and keep a core busy alone at the session's end."""
    pool = SlotPool(1)
    try:
        inbox: queue.Queue = queue.Queue()
        blocker = pool.submit(Task(9, stamp, (str(tmp_path / "blocker"), 1.0)), rank=FOREGROUND, inbox=inbox)
        while not blocker.started:
            time.sleep(0.01)
        short, long = spec(), spec(timesteps=100_000)
        ahead = TrainAhead(pool, Cache(tmp_path / "cache"))
        ahead.plan([short, long])  # queued behind the blocker, all four: the order is the ranks' alone
        names = {fingerprint_spec(short).spec_key: "short", fingerprint_spec(long).spec_key: "long"}
        _wait_for_start(ahead._planned.values())
        started = [(names[r.spec_key], r.seed) for r in ahead._planned.values() if r.ticket.started]
        assert started == [("long", 0)], f"started first: {started}"
        ahead.close()
    finally:
        pool.close()


@pytest.mark.slow
def test_a_run_another_process_holds_or_the_cache_has_is_not_planned(tmp_path, slots):
    s = spec()
    run_with(s, RunOptions(workers=2, cache_dir=tmp_path, progress=None))
    other = spec(timesteps=192)
    held = Cache(tmp_path).lock(fingerprint_spec(other).run_key(0), 1.0)
    assert try_acquire(held)
    ahead = TrainAhead(slots, Cache(tmp_path))
    ahead.plan([s, other])
    assert ahead.planned == [fingerprint_spec(other).run_key(1)]
    held.release()
    ahead.close()


@pytest.mark.slow  # a slot may start the planned runs' processes before the pool closes
def test_planning_checks_a_copy_so_the_spec_warns_in_its_own_item(tmp_path, slots):
    s = spec()
    ahead = TrainAhead(slots, Cache(tmp_path))
    ahead.plan([s])
    assert len(ahead.planned) == 2
    assert not s.env_factory().checked, "planning checked the spec itself: its warnings would be lost"
    ahead.close()


@pytest.mark.slow
def test_close_stores_the_finished_runs_nobody_asked_for(tmp_path, slots):
    s = spec()
    ahead = TrainAhead(slots, Cache(tmp_path))
    ahead.plan([s])
    deadline = time.monotonic() + 120
    while not all(r.ended for r in ahead._planned.values()) and time.monotonic() < deadline:
        ahead.pump()
        time.sleep(0.1)
    ahead.close()
    assert run_with(s, RunOptions(workers=2, cache_dir=tmp_path, progress=None)).cached == {0: True, 1: True}


@pytest.mark.slow
def test_close_stops_the_runs_still_training_and_releases_their_locks(tmp_path, slots):
    s = spec(timesteps=100_000)
    ahead = TrainAhead(slots, Cache(tmp_path))
    ahead.plan([s])
    start = time.monotonic()
    ahead.close()
    assert time.monotonic() - start < 30
    assert try_acquire(Cache(tmp_path).lock(fingerprint_spec(s).run_key(0), 1.0))


SPECS = """
import multiprocessing
import sys

import gymnasium as gym
import specguard as sg

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}


class Loud(gym.Wrapper):
    def reset(self, **kwargs):
        if multiprocessing.parent_process() is not None:  # in a training process only
            print("from-the-second-spec", file=sys.stderr)
        return self.env.reset(**kwargs)


def make(loud):
    return lambda: Loud(gym.make("Pendulum-v1")) if loud else gym.make("Pendulum-v1")


def spec(steps, loud=False):
    env = sg.InitialEnv(make(loud), features=("x", "y", "omega"))
    tree = sg.Always(sg.Goal("calm", omega=(-8, 8)), name="calm")
    budget = sg.Budget(timesteps=steps, min_seeds=2, eval_episodes=4, checkpoints=1)
    return sg.Spec(env, tree, budget=budget, trainer=sg.SB3(hyperparameters=TINY), expect=0.5)


test_specs = sg.goal_specs({"first": spec(128), "second": spec(192, loud=True)})
"""


def _training_column(text):
    """The table's last column, one cell per spec row (not the word anywhere: CI's cache-key warning says "cached")."""
    table = text.split("specguard goal specs")[-1]
    return [line.split()[-1] for line in table.splitlines() if line.startswith("test_specs.py::")]


def test_the_plugin_trains_ahead_and_reports_each_run_trained_in_its_own_item(pytester):
    pytester.makepyfile(test_specs=SPECS)
    cache = pytester.path / "cache"
    result = pytester.runpytest_inprocess("--goal-specs", f"--goal-specs-cache-dir={cache}", "-rP", "-p", "no:randomly")
    result.assert_outcomes(passed=2)
    text = result.stdout.str()
    trained = _training_column(text)
    assert len(trained) == 2 and "cached" not in trained, f"a run trained ahead is reported as cached: {trained}"
    first, second = text.split("test_specs[second-calm]")[0], text.split("test_specs[second-calm]")[-1]
    assert "from-the-second-spec" in second and "from-the-second-spec" not in first.split("PASSES")[-1]

    again = pytester.runpytest_inprocess("--goal-specs", f"--goal-specs-cache-dir={cache}", "-p", "no:randomly")
    again.assert_outcomes(passed=2)
    assert _training_column(again.stdout.str()) == ["cached", "cached"]


def test_ahead_off_and_a_bad_value(pytester):
    pytester.makepyfile(test_specs=SPECS)
    cache = pytester.path / "cache"
    off = pytester.runpytest_inprocess("--goal-specs", f"--goal-specs-cache-dir={cache}", "--goal-specs-ahead=off")
    off.assert_outcomes(passed=2)
    bad = pytester.runpytest_inprocess("--goal-specs", "--goal-specs-ahead=maybe")
    assert bad.ret == pytest.ExitCode.USAGE_ERROR
    bad.stderr.fnmatch_lines(["*--goal-specs-ahead: expected one of on, off, got 'maybe'*"])
