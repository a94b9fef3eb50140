"""The SB3 callbacks of a training run, each on its own job, stepped by hand (no training)."""

from __future__ import annotations

import json

import pytest

import specguard as sg
from specguard.training import callback as callbacks
from specguard.training.auto_weights import MIN_EPISODES, WeightAdapter
from specguard.training.callback import (
    AdaptWeights,
    RecordGoalCurve,
    ReportProgress,
    StopTrainingOnMetCheckpoint,
    StopTrainingOnWallClock,
    training_callbacks,
)
from specguard.training.curve import GoalCurve

UP = {"goals": {"root": True}}
DOWN = {"goals": {"root": False}}


class Model:
    """What a callback reads of a model: its steps so far, and its training env."""

    def __init__(self, env=None):
        self.num_timesteps = 0
        self.env = env

    def get_env(self):
        return self.env


class Envs:
    """A training VecEnv that records every ``env_method`` call."""

    def __init__(self):
        self.calls = []

    def env_method(self, name, *args):
        self.calls.append((name, *args))


def stepped(callback, env=None):
    """A function that steps ``callback`` to a step with the envs' ``dones`` and ``infos``, as SB3's loop does."""
    model = Model(env)
    callback.init_callback(model)
    callback.on_training_start({}, {})

    def step(num_timesteps, dones=(), infos=()):
        model.num_timesteps = num_timesteps
        callback.update_locals({"dones": list(dones), "infos": list(infos)})
        return callback.on_step()

    return step


@pytest.fixture
def clock(monkeypatch):
    """The callbacks' clock, set by hand: ``clock[0]`` seconds."""
    now = [0.0]
    monkeypatch.setattr(callbacks.time, "perf_counter", lambda: now[0])
    return now


def test_the_curve_counts_finished_episodes_into_a_point_every_tenth_and_at_each_checkpoint():
    curve = GoalCurve()
    step = stepped(RecordGoalCurve(curve, every=4, checkpoints=[6]))
    step(1, [True, False], [UP, DOWN])  # an episode still running is not counted
    step(2, [True], [{"TimeLimit.truncated": True}])  # nor an env's that reports no goals
    step(4, [True, True], [DOWN, DOWN])
    step(5, [True], [UP])
    step(6)  # a checkpoint
    step(10)  # past two tenths at once: one point, the next at 12
    step(11)
    step(12)
    points = [(p["timesteps"], p["episodes"], p["success"]) for p in curve.points]
    assert points == [(4, 3, {"root": 1 / 3}), (6, 1, {"root": 1.0}), (10, 0, {}), (12, 0, {})]


def test_the_curve_records_safety_rates():
    curve = GoalCurve()
    step = stepped(RecordGoalCurve(curve, every=2))
    unsafe = {"goals": {"root": True}, "safe": {"root:c": False}}
    safe = {"goals": {"root": False}, "safe": {"root:c": True}}
    step(1, [True, False], [unsafe, {}])
    step(2, [True, True], [safe, safe])
    assert curve.points == [{"timesteps": 2, "episodes": 3, "success": {"root": 1 / 3, "root:c": 2 / 3}}]


def auto_tree():
    return sg.All(sg.Goal("up", x=(0.5, None)), sg.Goal("low", x=(None, 0.7)), name="p", weights="auto")


def test_auto_weights_see_every_finished_episode_and_switch_after_a_rollout():
    adapter = WeightAdapter.of(auto_tree())
    envs = Envs()
    weights = AdaptWeights(adapter)
    step = stepped(weights, envs)
    reached = {"goals": {"p": False, "p/up": True, "p/low": False}}
    for n in range(1, MIN_EPISODES):
        step(n, [True, False], [reached, reached])
    weights.on_rollout_end()
    assert envs.calls == []  # too few episodes: the node's own weights hold
    step(MIN_EPISODES, [True], [reached])
    assert envs.calls == [] and adapter.in_force == {"p": (0.5, 0.5)}  # only between rollouts
    weights.on_rollout_end()
    assert envs.calls == [("set_weights", adapter.in_force)]  # "up" reached, "low" not: "low" takes the weight
    assert adapter.in_force["p"] == pytest.approx((0.1 / 1.2, 1.1 / 1.2))


def test_progress_reports_each_tick_and_a_line_at_each_point(clock):
    curve, sent = GoalCurve(), []
    step = stepped(training_callbacks(curve, every=500, total=1000, report=lambda *a: sent.append(a)))
    for n in range(10, 1010, 10):  # a tick every 10 steps; an episode ends in the root goal at each
        clock[0] = n / 1000
        step(n, [True], [UP if n % 20 else DOWN])
    assert [n for _, n, line in sent if line is None] == list(range(10, 1010, 10))  # no heartbeat in 1 s
    lines = [(n, json.loads(line)) for _, n, line in sent if line is not None]
    assert lines == [
        (500, {"steps": 500, "budget": 1000, "elapsed_s": 0.5, "success": 0.5, "episodes": 50}),
        (1000, {"steps": 1000, "budget": 1000, "elapsed_s": 1.0, "success": 0.5, "episodes": 50}),
    ]


def test_a_training_worker_sends_a_line_at_least_every_heartbeat(clock):
    sent: list[tuple] = []
    step = stepped(ReportProgress(GoalCurve(), lambda *a: sent.append(a), total=10_000))
    for n in range(100, 1000, 100):  # ticks every 1% of the budget, inside the first tenth
        clock[0] = n / 10  # 10 s a tick
        step(n, [False], [{}])
    steps = [n for _, n, line in sent if line is not None]
    assert steps == [300, 600, 900]  # every 30 s: a tenth of the budget that takes 90 s is not silent


def test_a_heartbeat_at_a_point_gives_the_numbers_of_the_point(clock):
    curve, sent = GoalCurve(), []
    step = stepped(training_callbacks(curve, every=100, total=1000, report=lambda *a: sent.append(a)))
    step(50, [True], [UP])
    clock[0] = callbacks.HEARTBEAT_S
    step(100, [True], [DOWN])  # a tick, a heartbeat due, and a point: both lines count the tenth's 2 episodes
    lines = [json.loads(line) for _, _, line in sent if line is not None]
    assert [(line["success"], line["episodes"]) for line in lines] == [(0.5, 2), (0.5, 2)]


def test_a_checkpoint_is_looked_at_once_after_its_point_and_a_met_look_stops_training():
    curve, looked = GoalCurve(), []

    def look(n):
        looked.append((n, curve.points[-1]["timesteps"]))  # the point at its step is there
        return n >= 8

    stop = StopTrainingOnMetCheckpoint([4, 8], look)
    step = stepped(training_callbacks(curve, every=100, total=100, stop_on_checkpoint=stop))
    assert [step(n) for n in (2, 5, 6, 7, 9)] == [True, True, True, True, False]
    assert looked == [(5, 5), (9, 9)] and stop.met_early
    assert [p["timesteps"] for p in curve.points] == [5, 9]


def test_the_wall_clock_stops_training_once_its_seconds_passed(clock):
    stop = StopTrainingOnWallClock(max_seconds=60)
    step = stepped(stop)
    clock[0] = 60.0
    assert step(1) and not stop.hit_wall_clock
    clock[0] = 60.5
    assert not step(2) and stop.hit_wall_clock
    never = StopTrainingOnWallClock(max_seconds=None)
    assert stepped(never)(1) and not never.hit_wall_clock


def test_a_run_holds_the_callbacks_it_needs_in_their_order():
    stop, clock_cap = StopTrainingOnMetCheckpoint([5], lambda n: False), StopTrainingOnWallClock(max_seconds=1)
    adapter = WeightAdapter.of(auto_tree())
    every = training_callbacks(
        GoalCurve(adapter),
        every=10,
        total=100,
        report=lambda *a: None,
        adapter=adapter,
        stop_on_checkpoint=stop,
        stop_on_wall_clock=clock_cap,
    )
    assert [type(c) for c in every.callbacks] == [
        RecordGoalCurve,
        AdaptWeights,
        ReportProgress,
        StopTrainingOnMetCheckpoint,
        StopTrainingOnWallClock,
    ]
    assert [type(c) for c in training_callbacks(GoalCurve(), every=10, total=100).callbacks] == [RecordGoalCurve]
