"""Every state is judged, the last included (docs/semantics.md, "The last state").

A constraint is judged on ``(s_t, a_t)``; the state an episode ends in has no action of its own, so it is
judged once more with the action that led to it, whether the env terminated, truncated or the spec ended it.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from specguard_plugins import Avoid

import specguard as sg
from specguard.contract.replay import ReplayEnv
from specguard.evaluation.episodes import evaluate

EVALUATORS = ("flat", "reference")


class FallEnv(gym.Env[np.ndarray, int]):
    """``x`` grows by 1 a step from 0; the env terminates once ``x > 2`` (a pendulum that falls)."""

    observation_space = gym.spaces.Box(-np.inf, np.inf, shape=(1,), dtype=np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.x = 0.0
        return np.array([self.x], np.float32), {}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        self.x += 1.0
        return np.array([self.x], np.float32), 0.0, self.x > 2.0, False, {}


FALLEN = sg.Constraint(lambda s, a: s.x > 2.0, name="fallen")


def fall_env(evaluator: str, *annotations: sg.Constraint) -> sg.SpecEnv:
    tree = sg.Goal("far", x=(100.0, None)).annotate(*(annotations or (FALLEN,)))
    return sg.make_env(sg.InitialEnv(FallEnv, features=("x",)), tree, evaluator=evaluator)


def episode(env: gym.Env, action: int = 0) -> list[tuple[Any, ...]]:
    """``(obs, reward, terminated, truncated, info)`` of every step of one episode."""
    env.reset(seed=0)
    steps = []
    while not steps or not (steps[-1][2] or steps[-1][3]):
        steps.append(env.step(action))
    return steps


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_the_state_the_env_terminates_on_is_judged(evaluator: str) -> None:
    steps = episode(fall_env(evaluator))
    assert [s[0].tolist() for s in steps] == [[1.0, 1.0], [2.0, 1.0], [3.0, 0.0]]  # x, then the counter
    *before, (_, reward, terminated, _, info) = steps
    assert all(s[4]["safe"] == {"far:fallen": True} for s in before)
    assert terminated and info["safe"] == {"far:fallen": False}
    assert info["reward_terms"]["far:fallen"] == -1.0 and reward == -1.0  # the penalty is paid on the last step


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_the_last_state_of_a_truncated_episode_is_judged(evaluator: str) -> None:
    tree = sg.Goal("far", x=(100.0, None)).annotate(FALLEN)
    env = sg.SpecEnv(ReplayEnv([[0.0], [1.0], [5.0]]), tree=tree, features=("x",), evaluator=evaluator)
    (*_, (obs, reward, terminated, truncated, info)) = episode(env)
    assert truncated and terminated  # the judgement spends the counter: the state is in T, as any spent counter
    assert obs.tolist() == [5.0, 0.0] and reward == -1.0 and info["safe"] == {"far:fallen": False}


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_the_last_state_gets_the_action_that_led_to_it(evaluator: str) -> None:
    seen: list[tuple[float, int]] = []

    def fallen(s: Any, a: Any) -> bool:
        seen.append((s.x, int(a)))
        return False

    episode(fall_env(evaluator, sg.Constraint(fallen, name="fallen")), action=1)
    assert seen == [(0.0, 1), (1.0, 1), (2.0, 1), (3.0, 1)]  # (s_t, a_t) for t < T, then (s_T, a_T-1)


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_a_counter_does_not_go_below_zero(evaluator: str) -> None:
    always = sg.Constraint(lambda s, a: True, budget=2, name="always")
    steps = episode(fall_env(evaluator, always))
    # (s0, a0) and (s1, a1) spend the budget, the spec ends the episode at s2, whose own violation finds none left.
    assert [(s[0].tolist(), s[1], s[2]) for s in steps] == [([1.0, 1.0], -1.0, False), ([2.0, 0.0], -1.0, True)]
    assert steps[-1][4]["safe"] == {"far:always": False}


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_the_spec_ending_the_episode_judges_its_last_state(evaluator: str) -> None:
    tree = sg.Goal("two", x=(2.0, None)).annotate(sg.Constraint(lambda s, a: s.x >= 2.0, name="high"))
    steps = episode(sg.make_env(sg.InitialEnv(FallEnv, features=("x",)), tree, evaluator=evaluator))
    assert [s[2] for s in steps] == [False, True]  # the root goal ends it at x = 2, which the constraint forbids
    assert steps[-1][4]["safe"] == {"two:high": False} and steps[-1][4]["reward_terms"]["two:high"] == -1.0


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_avoid_judges_the_last_state_once(evaluator: str) -> None:
    """``Avoid`` judges every ``s'``: the last state by the step into it, not a second time."""
    tree = sg.Goal("far", x=(100.0, None)).annotate(Avoid({"x": (3.0, None)}, budget=2, name="edge"))
    steps = episode(sg.make_env(sg.InitialEnv(FallEnv, features=("x",)), tree, evaluator=evaluator))
    assert [(s[1], s[0].tolist()) for s in steps] == [(0.0, [1.0, 2.0]), (0.0, [2.0, 2.0]), (-1.0, [3.0, 1.0])]
    assert steps[-1][4]["safe"] == {"far:edge": False}


def test_the_safety_rate_counts_episodes_that_end_in_a_violation() -> None:
    counts = evaluate(lambda obs: 0, fall_env("flat"), 3, range(3))
    assert counts["far:fallen"] == 0  # no episode without a violation: a safety rate of 0%
