"""The SB3 callbacks of a training run, each on its own job, stepped by hand (no training); then the user's callbacks
and the per-goal logs in real (tiny) training runs, at every door."""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path

import pytest
from stable_baselines3.common.callbacks import BaseCallback

import specguard as sg
from specguard.error import TrainingError
from specguard.training import callback as callbacks
from specguard.training.auto_weights import MIN_EPISODES, WeightAdapter
from specguard.training.callback import (
    AdaptWeights,
    LogGoals,
    RecordGoalCurve,
    ReportProgress,
    StopTrainingOnMetCheckpoint,
    StopTrainingOnWallClock,
    UserCallback,
    training_callbacks,
)
from specguard.training.curve import GoalCurve

UP = {"goals": {"root": True}}
DOWN = {"goals": {"root": False}}


class Model:
    """What a callback reads of a model: its steps so far, and its training env."""

    def __init__(self, env=None):
        from stable_baselines3.common.logger import Logger

        self.num_timesteps = 0
        self.env = env
        self.logger = Logger(folder=None, output_formats=[])

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


def test_goals_are_logged_per_rollout_and_per_evaluation_through_sb3s_logger():
    log = LogGoals()
    step = stepped(log)
    safe = {"goals": {"root": True, "root/a": False}, "safe": {"root:cool": True}}
    unsafe = {"goals": {"root": False, "root/a": False}, "safe": {"root:cool": False}}
    step(1, [True, True, False], [safe, unsafe, {}])
    step(2, [True], [safe])
    log.on_rollout_end()
    records = log.logger.name_to_value
    assert dict(records) == {
        "specguard/goal/root": pytest.approx(2 / 3),
        "specguard/goal/root/a": 0.0,
        "specguard/safe/root/cool": pytest.approx(2 / 3),
    }
    log.logger.dump(2)
    log.on_rollout_end()  # a rollout that finished no episode records nothing
    assert dict(log.logger.name_to_value) == {}
    log.evaluated(3, {"root": 27, "root:cool": 30}, 30)
    assert dict(log.logger.name_to_value) == {
        "specguard/eval/goal/root": 0.9,
        "specguard/eval/safe/root/cool": 1.0,
        "specguard/eval/episodes": 30,
    }
    log.evaluated(4, {"root": 3}, 30, write=True)  # the final evaluation: written at once
    assert dict(log.logger.name_to_value) == {}


def test_a_users_callback_acts_as_alone_and_an_error_names_it():
    from stable_baselines3.common.callbacks import BaseCallback

    class Seen(BaseCallback):
        def __init__(self):
            super().__init__()
            self.seen = []

        def _on_step(self):
            self.seen.append((self.num_timesteps, len(self.locals["infos"])))
            return self.num_timesteps < 3

        def _on_rollout_end(self):
            self.seen.append("rollout end")

    seen = Seen()
    step = stepped(UserCallback(seen, "Spec 'x', seed 0"))
    assert step(1, [False], [{}]) is True and step(3, [False], [{}]) is False
    assert seen.seen == [(1, 1), (3, 1)] and seen.model is not None

    class Broken(BaseCallback):
        def _on_step(self):
            raise KeyError("curriculum stage 3")

    step = stepped(UserCallback(Broken(), "Spec 'x', seed 0"))
    with pytest.raises(
        TrainingError,
        match=r"^Spec 'x', seed 0, callback .*Broken, in on_step at step 5: it raised "
        r"KeyError: 'curriculum stage 3'",
    ):
        step(5)


def test_logging_and_the_users_callbacks_come_last():
    from stable_baselines3.common.callbacks import BaseCallback

    class Mine(BaseCallback):
        def _on_step(self):
            return True

    user = UserCallback(Mine(), "run")
    every = training_callbacks(GoalCurve(), every=10, total=100, log=LogGoals(), user=[user])
    assert [type(c) for c in every.callbacks] == [RecordGoalCurve, LogGoals, UserCallback]


# -- the user's callbacks and the logs, in real training runs -------------------------------------------------------

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
BALANCE = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")
QUICK = sg.Budget(timesteps=256, min_seeds=2, max_seeds=2, eval_episodes=4, max_eval_episodes=4)


QUICK_HP = {"n_steps": 64, "batch_size": 32}


def quick_spec(**kwargs):
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=QUICK_HP))
    return sg.Spec(CARTPOLE, BALANCE, budget=QUICK, expect=0.01, **kwargs)


class MarkTraining(BaseCallback):
    """Leaves a file named after its process and the steps it trained, when training ends."""

    def __init__(self, folder):
        super().__init__()
        self.folder = folder

    def _on_step(self):
        return True

    def _on_training_end(self):
        (Path(self.folder) / f"{os.getpid()}-{self.num_timesteps}").write_text("trained")


class Raises(BaseCallback):
    def _on_step(self):
        raise RuntimeError("the curriculum has no stage 2")


def scalars(folder):
    """Every scalar of the TensorBoard event files under ``folder``, by run subfolder and tag."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    found = {}
    for events in sorted(Path(folder).rglob("events.out.tfevents.*")):
        accumulator = EventAccumulator(str(events.parent))
        accumulator.Reload()
        run = events.parent.relative_to(folder).as_posix()
        found[run] = {tag: [e.value for e in accumulator.Scalars(tag)] for tag in accumulator.Tags()["scalars"]}
    return found


@pytest.mark.slow
def test_a_users_callback_runs_in_every_training_worker(tmp_path):
    result = sg.run_spec(
        quick_spec(trainer=sg.SB3(callbacks=[functools.partial(MarkTraining, tmp_path)], hyperparameters=QUICK_HP)),
        workers=2,
        cache_dir=None,
        progress=None,
    )
    assert not result.errors
    marks = sorted(p.name for p in tmp_path.iterdir())
    assert len(marks) == 2 and all(m.endswith("-256") for m in marks)
    assert str(os.getpid()) not in {m.split("-")[0] for m in marks}  # in the workers, not here


@pytest.mark.slow
def test_a_callback_that_raises_fails_its_seeds_in_one_line_naming_it():
    result = sg.run_spec(
        quick_spec(trainer=sg.SB3(callbacks=[Raises], hyperparameters=QUICK_HP)),
        workers=1,
        cache_dir=None,
        progress=None,
    )
    assert sorted(result.errors) == [0, 1] and not result.passed
    for error in result.errors.values():
        assert "callback" in error and "Raises" in error and "the curriculum has no stage 2" in error
        assert "\n" not in error and "environment" not in error


def test_callbacks_are_part_of_the_spec_identity_and_the_log_folder_is_not(tmp_path):
    from specguard.cache.fingerprint import fingerprint_spec

    plain = quick_spec()
    keys = {
        fingerprint_spec(s).spec_key
        for s in (
            plain,
            quick_spec(trainer=sg.SB3(callbacks=[MarkTraining], hyperparameters=QUICK_HP)),
            quick_spec(trainer=sg.SB3(callbacks=[Raises], hyperparameters=QUICK_HP)),
        )
    }
    assert len(keys) == 3
    logged = plain.as_run(tensorboard_log=tmp_path)
    assert logged.trainer.tensorboard_log == str(tmp_path)
    assert fingerprint_spec(logged) == fingerprint_spec(plain)


def test_a_callback_that_is_no_factory_is_refused_where_the_spec_is_made():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"callbacks\[0\].*expected a callable returning an SB3 BaseCallback"
    ):
        quick_spec(trainer=sg.SB3(callbacks=[3], hyperparameters=QUICK_HP))
    with pytest.raises(sg.error.InvalidSpec, match="expected a list of callback factories"):
        quick_spec(trainer=sg.SB3(callbacks=MarkTraining, hyperparameters=QUICK_HP))


def test_tensorboard_needs_its_package_in_one_line(tmp_path, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "tensorboard" else real(name, *a))
    with pytest.raises(sg.error.InvalidSpec, match="needs the tensorboard package, which is not installed"):
        quick_spec().as_run(tensorboard_log=tmp_path)


def checkpoints_of_the_run(root, seed, spec):
    """The docs' per-run checkpoint saver: one folder per spec and seed."""
    from stable_baselines3.common.callbacks import CheckpointCallback

    return CheckpointCallback(save_freq=128, save_path=str(Path(root) / spec.label / f"seed_{seed}"))


@pytest.mark.slow
def test_a_factory_that_takes_the_seed_and_spec_gets_them_so_each_run_writes_its_own_folder(tmp_path):
    from specguard.training.train import train_run

    spec = quick_spec(
        trainer=sg.SB3(callbacks=[functools.partial(checkpoints_of_the_run, str(tmp_path))], hyperparameters=QUICK_HP)
    )
    for seed in (0, 1):
        train_run(spec, seed)
    saved = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*.zip"))
    assert saved == [f"balance/seed_{seed}/rl_model_{steps}_steps.zip" for seed in (0, 1) for steps in (128, 256)]


def test_a_factory_is_given_only_the_run_arguments_its_signature_names_and_a_partial_left_free():
    from specguard.training.train import _run_arguments

    class Run:
        seed, spec = 3, "the spec"

    def both(seed, spec): ...
    def anything(**kwargs): ...

    assert _run_arguments(both, Run) == {"seed": 3, "spec": "the spec"}
    assert _run_arguments(functools.partial(both, seed=9), Run) == {"spec": "the spec"}
    assert _run_arguments(anything, Run) == {} and _run_arguments(MarkTraining, Run) == {}


def test_a_tensorboard_folder_that_cannot_be_made_is_refused_in_one_line_naming_it(tmp_path):
    file = tmp_path / "file.txt"
    file.write_text("")
    refused = {
        file: f"got {str(file)!r}, which is a file",
        file / "runs": f"got {str(file / 'runs')!r}, which lies below the file {str(file)!r}",
        "runs\0": "got 'runs\\x00', which holds a NUL character",
        "r" * 300: "which is too long (a name over 255 bytes)",
        42: "expected tensorboard_log to be a folder, got 42",
    }
    for folder, message in refused.items():
        with pytest.raises(sg.error.InvalidSpec) as spec_error:
            quick_spec(trainer=sg.SB3(tensorboard_log=folder, hyperparameters=QUICK_HP))
        with pytest.raises(sg.error.InvalidSpec) as door_error:
            quick_spec().as_run(tensorboard_log=folder)
        for error in (spec_error, door_error):
            assert message in str(error.value).splitlines()[0], str(error.value)


@pytest.mark.slow
def test_run_spec_writes_each_goals_curve_to_tensorboard_one_folder_per_spec_and_seed(tmp_path):
    result = sg.run_spec(
        quick_spec(), workers=2, cache_dir=tmp_path / "cache", progress=None, tensorboard_log=tmp_path / "tb"
    )
    assert not result.errors
    found = scalars(tmp_path / "tb")
    assert sorted(found) == ["balance/seed_0_1", "balance/seed_1_1"]
    for tags in found.values():
        assert {
            "specguard/goal/balance",
            "specguard/goal/balance/upright",
            "specguard/eval/goal/balance",
            "rollout/ep_len_mean",
        } <= set(tags)
        assert all(0 <= v <= 1 for v in tags["specguard/goal/balance/upright"])
    # The final evaluation is the run's own figure, written last.
    run = result.runs[0]
    assert found["balance/seed_0_1"]["specguard/eval/goal/balance"][-1] == run.successes["balance"] / run.episodes
    # A run found in the cache trains nothing and writes nothing.
    again = sg.run_spec(
        quick_spec(), workers=1, cache_dir=tmp_path / "cache", progress=None, tensorboard_log=tmp_path / "tb2"
    )
    assert all(again.cached.values()) and not (tmp_path / "tb2").exists()


def test_specguard_run_and_pytest_write_tensorboard_logs(tmp_path, pytester, monkeypatch):
    from specguard.cli.main import main

    specs = tmp_path / "cartpole_specs.py"
    specs.write_text(
        "import specguard as sg\n"
        "cartpole = sg.InitialEnv('CartPole-v1', features=('x', 'v', 'theta', 'omega'))\n"
        "balance = sg.Always(sg.Goal('upright', theta=(-0.2, 0.2)), name='balance')\n"
        "budget = sg.Budget(timesteps=128, min_seeds=1, max_seeds=1, eval_episodes=4, checkpoints=1)\n"
        "tiny = {'n_steps': 64, 'batch_size': 32}\n"
        "spec = sg.Spec(cartpole, balance, budget=budget, expect=0.0, trainer=sg.SB3(hyperparameters=tiny))\n"
    )
    assert (
        main(["run", str(specs), "--no-cache", "--quiet", "--workers", "1", "--tensorboard-log", str(tmp_path / "cli")])
        == 0
    )
    assert list(scalars(tmp_path / "cli")) == ["balance/seed_0_1"]
    pytester.makepyfile(test_cartpole=specs.read_text() + "\n\n@sg.goal_spec()\ndef test_balance():\n    return spec\n")
    outcome = pytester.runpytest(
        "--goal-specs",
        "--goal-specs-no-cache",
        "--goal-specs-workers=1",
        f"--goal-specs-tensorboard-log={tmp_path / 'pytest'}",
    )
    outcome.assert_outcomes(passed=1)
    assert list(scalars(tmp_path / "pytest")) == ["balance/seed_0_1"]
    assert "specguard/goal/balance" in scalars(tmp_path / "pytest")["balance/seed_0_1"]


def scalar_events(folder, tag):
    """``(step, value)`` of every event of scalar ``tag`` in the one run folder of TensorBoard logs under ``folder``."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (events,) = {e.parent for e in Path(folder).rglob("events.out.tfevents.*")}
    accumulator = EventAccumulator(str(events))
    accumulator.Reload()
    return [(e.step, e.value) for e in accumulator.Scalars(tag)] if tag in accumulator.Tags()["scalars"] else []


@pytest.mark.slow
def test_a_met_checkpoint_is_written_to_tensorboard_at_its_step(tmp_path):
    # A look at step 128 meets every threshold (>= 0) and stops training in the middle of SB3's second rollout,
    # after SB3's last write: the look is the run's result, and TensorBoard has it at its step.
    budget = sg.Budget(timesteps=256, min_seeds=1, max_seeds=1, eval_episodes=4, max_eval_episodes=4, checkpoints=2)
    spec = sg.Spec(
        CARTPOLE, BALANCE, budget=budget, expect=0.0, trainer=sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32})
    )
    result = sg.run_spec(spec, workers=1, cache_dir=None, progress=None, tensorboard_log=tmp_path)
    (run,) = result.runs
    assert run.met_early and run.timesteps == 128
    looked = run.successes["balance"] / run.episodes
    assert scalar_events(tmp_path, "specguard/eval/goal/balance")[-1] == (128, pytest.approx(looked))
    # The training episodes of the rollout cut short are written too: the training curve keeps its last point.
    assert scalar_events(tmp_path, "specguard/goal/balance")[-1][0] == 128


class Forgetful(BaseCallback):
    """A callback whose ``_on_step`` forgot its ``return True``."""

    def _on_step(self):
        pass


def test_a_users_callback_that_stops_training_is_recorded_and_one_that_returns_none_warns():
    class Enough(BaseCallback):
        def _on_step(self):
            return self.num_timesteps < 3

    enough = UserCallback(Enough(), "Spec 'x', seed 0")
    step = stepped(enough)
    assert step(1) is True and enough.stopped_at is None
    assert step(3) is False and enough.stopped_at == 3 and not enough.returned_none
    forgetful = UserCallback(Forgetful(), "Spec 'x', seed 0")
    step = stepped(forgetful)
    with pytest.warns(
        sg.error.SpecWarning,
        match=r"^Spec 'x', seed 0, callback Forgetful: its _on_step returned None at step 1, which SB3 takes as "
        r"False: training stopped there",
    ):
        assert step(1) is False
    assert forgetful.stopped_at == 1 and forgetful.returned_none


@pytest.mark.slow
def test_a_callback_that_stops_training_says_so_in_the_result_the_table_the_failure_and_junit(tmp_path):
    from stable_baselines3.common.callbacks import StopTrainingOnMaxEpisodes

    from specguard.pytest_plugin.judge import judge_goal
    from specguard.report.table import table

    one_episode = functools.partial(StopTrainingOnMaxEpisodes, max_episodes=1)
    result = sg.run_spec(
        quick_spec(trainer=sg.SB3(callbacks=[one_episode], hyperparameters=QUICK_HP)),
        workers=1,
        cache_dir=None,
        progress=None,
    )
    for run in result.runs:
        assert run.stop_reason == f"stopped by StopTrainingOnMaxEpisodes at {run.timesteps} of 256 steps"
        assert 0 < run.timesteps < 256
    tiny = {"n_steps": 64, "batch_size": 32}
    spec = sg.Spec(
        CARTPOLE, BALANCE, budget=QUICK, expect=0.99, trainer=sg.SB3(hyperparameters=tiny, callbacks=[Forgetful])
    )
    result = sg.run_spec(spec, workers=1, cache_dir=tmp_path, progress=None)
    said = "stopped by Forgetful at 1 of 256 steps: its _on_step returned None, which SB3 takes as False"
    assert [r.stop_reason for r in result.runs] == [said, said] and [r.timesteps for r in result.runs] == [1, 1]
    assert f"seed 0: training {said}" in table(result).splitlines()
    check = judge_goal(result, spec, "balance", "test_x")
    assert f"  seed 1: training {said}" in check.message().splitlines()
    assert dict(check.junit_properties())["stopped"] == f"seed 0: {said}; seed 1: {said}"
    # The reason is the run's: kept in the cache, and read back from a result's JSON.
    again = sg.run_spec(spec, workers=1, cache_dir=tmp_path, progress=None)
    assert all(again.cached.values()) and [r.stop_reason for r in again.runs] == [said, said]
    assert sg.SpecResult.from_dict(result.to_dict()).runs == result.runs


def test_a_run_stored_before_stop_reasons_were_recorded_still_reads():
    from specguard.training.result import RunResult

    run = RunResult(spec="p", seed=0, timesteps=64, episodes=4, successes={"p": 1}, train_seconds=1.0)
    old = run.to_dict()
    del old["stop_reason"]
    assert RunResult.from_dict(old, seed=0, paths=["p"]) == run
    with pytest.raises(ValueError, match="stop_reason 3 is neither a string nor null"):
        RunResult.from_dict({**old, "stop_reason": 3}, seed=0, paths=["p"])
