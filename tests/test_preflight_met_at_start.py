"""A spec met without acting is reported before training: the mirror of ``UnreachableGoal``.

A root goal that holds at every sampled start (seeded resets) is refused; one
that holds at some starts warns with its share; the verdict says how many
evaluation episodes started inside the root goal.
"""

from __future__ import annotations

import dataclasses
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import specguard as sg
from specguard.cli.main import main
from specguard.construction.env import make_baseline_env
from specguard.construction.preflight import START_SAMPLES
from specguard.error import GoalMetAtStart, InvalidSpec, SpecWarning
from specguard.spec.spec import check_spec

TINY = {"n_steps": 32, "batch_size": 32, "n_epochs": 1}


class Drift(gym.Env[np.ndarray, int]):
    """``x`` starts uniform in ``[start_low, 1)`` and moves by +-0.1 per step; 20 steps an episode."""

    observation_space = gym.spaces.Box(-2.0, 2.0, (1,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def __init__(self, start_low: float = 0.0) -> None:
        self.start_low = start_low
        self.x = 0.0
        self.t = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.x, self.t = float(self.np_random.uniform(self.start_low, 1.0)), 0
        return np.array([self.x], np.float32), {}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.x = float(np.clip(self.x + (0.1 if action else -0.1), -2.0, 2.0))
        self.t += 1
        return np.array([self.x], np.float32), 0.0, False, self.t >= 20, {}


def always_inside() -> Drift:
    return Drift(start_low=0.6)  # every start is in x >= 0.5


def sometimes_inside() -> Drift:
    return Drift(start_low=0.0)  # about half the starts are in x >= 0.5


def never_inside() -> Drift:
    return Drift(start_low=-1.0)  # then moved below 0.5 by the goal chosen


def share_inside(factory, low: float) -> int:
    """How many of the sampled starts (seeds 0 .. START_SAMPLES - 1) have ``x >= low``, counted here directly."""
    env = factory()
    return sum(env.reset(seed=i)[0][0] >= np.float32(low) for i in range(START_SAMPLES))


UP = sg.Goal("up", x=(0.5, None))


def test_a_root_goal_met_at_every_start_is_refused_naming_goal_and_share():
    initial = sg.InitialEnv(always_inside, features=("x",))
    with pytest.raises(GoalMetAtStart) as e:
        sg.make_env(initial, UP)
    assert isinstance(e.value, InvalidSpec) and e.value.where == "up"
    assert f"holds at all {START_SAMPLES} of {START_SAMPLES} sampled starts" in str(e.value)
    assert "Hint: " in str(e.value) and "outside" in e.value.hint
    with pytest.raises(GoalMetAtStart, match="up"):  # the baseline refuses what the constructed env refuses
        make_baseline_env(initial, UP)


def test_a_root_goal_met_at_some_starts_warns_with_its_share():
    initial = sg.InitialEnv(sometimes_inside, features=("x",))
    inside = share_inside(sometimes_inside, 0.5)
    assert 0 < inside < START_SAMPLES
    with pytest.warns(SpecWarning) as caught:
        sg.make_env(initial, UP).close()
    (warning,) = [w for w in caught if issubclass(w.category, SpecWarning)]
    assert f"up holds at {inside} of {START_SAMPLES} sampled starts ({inside / START_SAMPLES:.0%})" in str(
        warning.message
    )
    assert warning.filename == __file__  # the line that built the env


def test_the_warning_of_a_spec_points_at_the_users_line_too():
    spec = sg.Spec(sg.InitialEnv(sometimes_inside, features=("x",)), UP, budget=sg.Budget(timesteps=64), expect=0.5)
    with pytest.warns(SpecWarning) as caught:
        spec.make_env().close()  # through Spec.make_env: the user's line, not one inside specguard/spec
    (warning,) = [w for w in caught if issubclass(w.category, SpecWarning)]
    assert warning.filename == __file__


def test_only_the_root_goal_matters_and_a_goal_met_nowhere_is_silent():
    initial = sg.InitialEnv(always_inside, features=("x",))
    tree = sg.All(sg.Goal("start", x=(0.5, None)), sg.Goal("far", x=(1.5, None)), name="both")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a child met at the start is how many trees begin: no warning
        sg.make_env(initial, tree).close()
        sg.make_env(sg.InitialEnv(never_inside, features=("x",)), sg.Goal("far", x=(1.5, None))).close()


def test_the_sampled_starts_leave_the_built_env_unseeded():
    # The starts are sampled on an env of their own: the one handed out resets as a fresh env would.
    initial = sg.InitialEnv(never_inside, features=("x",))
    starts = {float(sg.make_env(initial, sg.Goal("far", x=(1.5, None))).reset()[0][0]) for _ in range(4)}
    assert len(starts) == 4


def test_run_spec_refuses_before_training(tmp_path):
    initial = sg.InitialEnv(always_inside, features=("x",))
    spec = sg.Spec(
        initial, UP, budget=sg.Budget(timesteps=64, min_seeds=1, eval_episodes=2), trainer=sg.SB3(hyperparameters=TINY)
    )
    events = []
    with pytest.raises(GoalMetAtStart, match="up"):
        sg.run_spec(spec, workers=1, cache_dir=None, progress=events.append)
    assert not events  # no seed started


def test_specguard_run_refuses_in_one_line_with_status_2(tmp_path, capsys):
    path = tmp_path / "starts_inside.py"
    path.write_text(
        "import gymnasium as gym\n"
        "import specguard as sg\n"
        "env = lambda: gym.make('CartPole-v1')\n"
        "spec = sg.Spec(sg.InitialEnv(env, features=('x', 'v', 'theta', 'omega')), sg.Goal('up', x=(-1, 1)),\n"
        "    budget=sg.Budget(timesteps=64, min_seeds=1, eval_episodes=2), expect=0.5)\n"
    )
    assert main(["run", str(path), "--no-cache", "--quiet", "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert "up" in err and f"all {START_SAMPLES} of {START_SAMPLES} sampled starts" in err


@pytest.mark.slow
def test_the_verdict_counts_evaluation_episodes_that_started_in_the_root_goal():
    from specguard.evaluation.episodes import EVAL_SEED_BASE, EVAL_SEED_STRIDE

    initial = sg.InitialEnv(sometimes_inside, features=("x",))
    budget = sg.Budget(timesteps=64, min_seeds=1, max_seeds=1, eval_episodes=6, checkpoints=1)
    spec = sg.Spec(initial, UP, budget=budget, expect=0.1, trainer=sg.SB3(hyperparameters=TINY))
    with pytest.warns(SpecWarning):
        result = sg.run_spec(spec, workers=1, cache_dir=None, progress=None)
    (run,) = result.runs
    env = sometimes_inside()
    first = EVAL_SEED_BASE + run.seed * EVAL_SEED_STRIDE
    expected = sum(env.reset(seed=first + i)[0][0] >= np.float32(0.5) for i in range(run.episodes))
    assert expected > 0  # the evaluation seeds of seed 0 do start inside the goal: the count is tested
    assert run.started_in_goal == expected
    assert f"{expected} of {run.episodes} evaluation episodes started inside the root goal 'up'" in sg.table(result)
    assert result.to_dict()["runs"][0]["started_in_goal"] == expected


def test_the_notes_say_nothing_when_no_episode_started_in_the_root_goal():
    from specguard.engine.judging import episode_notes
    from specguard.training.result import RunResult

    run = RunResult(spec="s", seed=0, timesteps=1, episodes=3, successes={"up": 1}, train_seconds=0.0)
    assert episode_notes(None, [run]) == []
    started = dataclasses.replace(run, started_in_goal=2)
    assert episode_notes(None, [started]) == [
        "2 of 3 evaluation episodes started inside the root goal 'up': met before the policy acted"
    ]


def test_a_spec_is_checked_once_however_many_envs_it_builds():
    spec = sg.Spec(sg.InitialEnv(sometimes_inside, features=("x",)), UP, budget=sg.Budget(timesteps=64), expect=0.5)
    with pytest.warns(SpecWarning) as caught:
        check_spec(spec)  # as Gymnasium's check_env: explicit, once
        for _ in range(3):
            spec.make_env().close()
        assert spec.env_factory() is spec.env_factory()  # one factory: compiled once
    assert len([w for w in caught if issubclass(w.category, SpecWarning)]) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pickle.loads(pickle.dumps(spec)).make_env().close()  # a worker receives it checked: no warning again


def test_check_false_builds_without_the_checks_and_check_spec_refuses():
    spec = sg.Spec(sg.InitialEnv(always_inside, features=("x",)), UP, budget=sg.Budget(timesteps=64), expect=0.5)
    spec.make_env(check=False).close()  # met at every start, but not checked: built, as disable_env_checker
    sg.make_env(spec.initial_env, UP, check=False).close()
    with pytest.raises(GoalMetAtStart):
        check_spec(spec)
    with pytest.raises(GoalMetAtStart):
        spec.make_env()
