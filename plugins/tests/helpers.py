"""Shared helpers of the plugin tests: replaying a fixed trajectory through the constructed env."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import specguard as sg
from specguard.testing import ReplayEnv

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))


def replay_env(tree: sg.Node, trajectory: Sequence[Sequence[float]], features: Sequence[str] = ("x",)) -> gym.Env:
    """The constructed env of ``tree`` over a :class:`ReplayEnv` of ``trajectory``."""
    return sg.make_env(sg.InitialEnv(lambda: ReplayEnv(trajectory), features=tuple(features)), tree)


def replay(
    tree: sg.Node, trajectory: Sequence[Sequence[float]], features: Sequence[str] = ("x",)
) -> tuple[dict[str, Any], list[tuple[Any, ...]]]:
    """Reset, then step until the episode ends: ``(reset info, [(obs, reward, terminated, truncated, info), ...])``.

    ``obs`` is a list of Python floats (features, then own state).
    """
    env = replay_env(tree, trajectory, features)
    obs, info = env.reset(seed=0)
    steps = [(obs.tolist(), None, False, False, info)]
    while True:
        obs, reward, terminated, truncated, info = env.step(0)
        assert type(reward) is float
        steps.append((obs.tolist(), reward, terminated, truncated, info))
        if terminated or truncated:
            break
    env.close()
    return steps[0][4], steps[1:]


def rewards(steps: list[tuple[Any, ...]]) -> list[float]:
    return [s[1] for s in steps]


def both_checkers(tree: sg.Node) -> None:
    """Gymnasium's and stable-baselines3's env checkers on ``tree`` over CartPole-v1."""
    env = sg.make_env(CARTPOLE, tree)
    gym_check_env(env, skip_render_check=True)  # also re-creates the env from env.spec
    sb3_check_env(env, warn=False)
    env.reset(seed=0)
    env.action_space.seed(0)
    for _ in range(30):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        assert type(reward) is float and type(terminated) is bool and type(truncated) is bool
        assert sum(info["reward_terms"].values()) == pytest.approx(reward)
        if terminated or truncated:
            env.reset()
    env.close()
