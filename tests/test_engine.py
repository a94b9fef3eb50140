"""run_spec: parallel seeds, sequential stopping, verdicts, errors kept per seed."""

from __future__ import annotations

import json

import gymnasium as gym
import pytest

import specguard as sg
from example_specs import pendulum
from specguard.engine import resolve_workers

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}


def spec(tree="w", **kwargs):
    kwargs.setdefault("budget", sg.Budget(timesteps=128, min_seeds=2, max_seeds=4, eval_episodes=4))
    kwargs.setdefault("hyperparameters", TINY)
    return sg.Spec(pendulum.initial_env, pendulum.trees[tree], **kwargs)


def test_clearly_missed_goal_stops_after_the_minimum_seeds(tmp_path):
    # 128 steps of PPO never hold the pendulum up in 95% of episodes: missed in both runs.
    result = sg.run_spec(spec(expect={"pendulum": 0.95}), workers=2, cache_dir=tmp_path, progress=None)
    assert [r.seed for r in result.runs] == [0, 1]
    goal = result.goals["pendulum"]
    assert goal.verdict == "failed" and goal.required == 4
    assert not result.passed
    assert json.loads(json.dumps(result.to_dict()))["goals"]["pendulum"]["verdict"] == "failed"
    assert "pendulum" in result.table() and "failed" in result.table()


def test_trivially_met_goal_passes_with_a_quorum(tmp_path):
    s = spec(expect={"stabilization": 0.0}, quorum=2)
    result = sg.run_spec(s, workers=1, cache_dir=None, progress=None)
    assert result.passed
    assert result.goals["pendulum/stabilization"].runs == ["met", "met"]
    assert len(result.runs) == 2


def test_open_quorum_trains_more_seeds(tmp_path):
    # Quorum 3 of 4 with a goal met by every run: after 2 runs the quorum is open, one more settles it.
    s = spec(expect={"stabilization": 0.0}, quorum=3)
    result = sg.run_spec(s, workers=2, cache_dir=None, progress=None)
    assert result.passed and len(result.runs) == 3


class FailsOnSeed(gym.Wrapper):
    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self.first_seed = seed
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        if getattr(self, "first_seed", None) == 1:
            raise RuntimeError("boom")
        return self.env.step(action)


def make_failing():
    return FailsOnSeed(gym.make("Pendulum-v1"))


def test_a_failing_seed_keeps_the_others(tmp_path):
    initial = sg.InitialEnv(make_failing, features=("x", "y", "omega"))
    s = sg.Spec(initial, pendulum.trees["b"], budget=sg.Budget(timesteps=128, eval_episodes=2), hyperparameters=TINY)
    lines = []
    result = sg.run_spec(s, workers=2, cache_dir=tmp_path, progress=lines.append)
    assert [r.seed for r in result.runs] == [0]
    assert "seed 1, training step" in result.errors[1] and "RuntimeError: boom" in result.errors[1]
    assert not result.passed
    assert any("seed 1 failed" in line for line in lines)


def test_spec_errors_from_workers_reach_the_caller(tmp_path):
    with pytest.raises(sg.InvalidSpec, match=r"Spec 'pendulum'.algorithm: DQN cannot act in a Box action space"):
        sg.run_spec(spec(algorithm="DQN"), workers=1, cache_dir=None, progress=None)


def test_workers():
    assert resolve_workers(3) == 3
    assert resolve_workers("auto") >= 1
    with pytest.raises(sg.SpecError, match="workers: expected an integer >= 1 or 'auto', got 0"):
        resolve_workers(0)
