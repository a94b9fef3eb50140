"""The training envs stepped together (specguard.training.vec_env): make_vec_env's steps, without its per-env tax."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.env_util import make_vec_env

import specguard as sg
from example_specs import lunar_lander, mountain_car, pendulum
from specguard.construction.env import SpecEnv
from specguard.training.vec_env import SpecVecEnv, spec_vec_env

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))


def _cartpole_sequence() -> tuple[sg.InitialEnv, sg.Node]:
    from specguard_plugins import Sequence

    right = sg.Goal("right", x=(0.5, None)).annotate(sg.Distance(lambda s: abs(s.x - 0.5), scale=3.0))
    left = sg.Goal("left", x=(None, -0.5))
    return CARTPOLE, Sequence(right, left, sg.Goal("centre", x=(-0.1, 0.1)), name="tour")


def _mountain_car_reach() -> tuple[sg.InitialEnv, sg.Node]:
    # A counter judged on (s, a), so the last state is judged once more when an episode ends.
    flag = sg.Goal("flag", x=(0.45, None)).annotate(sg.Distance(lambda s: max(0.0, 0.45 - s.x), scale=1.8))
    reckless = sg.Constraint(lambda s, a: s.x > -0.45 and abs(s.vel) > 0.004, budget=2, name="reckless")
    return mountain_car.initial_env, flag.annotate(reckless)


class Noting(gym.Wrapper[Any, Any, Any, Any]):
    """An env whose info holds an array it keeps and changes after the step (as an env may reuse its own)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.seen = np.zeros(1)

    def step(self, action: Any) -> Any:
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.seen += 1
        return obs, reward, terminated, truncated, {**info, "seen": self.seen}


CASES = {
    "Pendulum (w): a distance, the observation made of the features": lambda: (
        pendulum.initial_env,
        pendulum.trees["w"],
    ),
    "CartPole: the observation passed on untouched": lambda: (CARTPOLE, sg.Goal("far", x=(2.0, None))),
    "CartPole: a Sequence, own state": _cartpole_sequence,
    "MountainCarContinuous: a reach goal and a constraint": _mountain_car_reach,
    "CartPole: an info the env keeps": lambda: (
        sg.InitialEnv(lambda: Noting(gym.make("CartPole-v1")), features=CARTPOLE.features),
        sg.Goal("far", x=(2.0, None)).annotate(sg.Constraint(lambda s, a: abs(s.theta) > 0.1, budget=2)),
    ),
    "LunarLander (c): three distances, a crash constraint": lambda: (lunar_lander.initial_env, lunar_lander.trees["c"]),
}


def _same_step(a: tuple[Any, ...], b: tuple[Any, ...]) -> None:
    for x, y in zip(a[:3], b[:3]):  # observations, rewards, dones: the same values and types
        assert x.dtype == y.dtype and np.array_equal(x, y)
    for info_a, info_b in zip(a[3], b[3]):
        info_a, info_b = dict(info_a), dict(info_b)
        episode_a, episode_b = info_a.pop("episode", None), info_b.pop("episode", None)  # Monitor's, VecMonitor's
        assert (episode_a is None) == (episode_b is None)
        if episode_a is not None:
            assert episode_b is not None and episode_a["l"] == episode_b["l"]
            assert episode_a["r"] == pytest.approx(episode_b["r"], rel=1e-5, abs=1e-4)  # float32 sums
        assert info_a.keys() == info_b.keys()
        for key, value in info_a.items():
            if isinstance(value, np.ndarray):
                assert value.dtype == info_b[key].dtype and np.array_equal(value, info_b[key]), key
            else:
                assert value == info_b[key] and type(value) is type(info_b[key]), key


@pytest.mark.parametrize("case", CASES)
def test_the_envs_stepped_together_equal_make_vec_envs_step_for_step(case, monkeypatch):
    initial_env, tree = CASES[case]()

    def build() -> gym.Env:
        return sg.make_env(initial_env, tree, check=False)

    reference, together = make_vec_env(build, n_envs=4, seed=3), spec_vec_env(build, n_envs=4, seed=3)
    space = reference.action_space
    space.seed(0)
    actions = [np.stack([space.sample() for _ in range(4)]) for _ in range(600)]
    assert np.array_equal(reference.reset(), together.reset())
    steps = [reference.step(a) for a in actions]
    # The envs stepped together never call SpecEnv.step (each judges its step through advance()).
    monkeypatch.setattr(SpecEnv, "step", lambda *args: pytest.fail("SpecEnv.step called"))
    ended = 0
    for action, expected in zip(actions, steps):
        step = together.step(action)
        _same_step(expected, step)
        ended += int(step[2].sum())
    assert ended >= 4  # episodes ended, so terminal observations and resets were compared too
    reference.close()
    together.close()


def test_an_info_the_initial_env_keeps_is_copied_as_make_vec_env_copies_it():
    initial_env, tree = CASES["CartPole: an info the env keeps"]()
    venv = spec_vec_env(lambda: sg.make_env(initial_env, tree, check=False), n_envs=2, seed=0)
    venv.reset()
    infos = venv.step(np.zeros(2, dtype=np.int64))[3]
    assert infos[0]["seen"].tolist() == [1.0]
    venv.step(np.zeros(2, dtype=np.int64))
    assert infos[0]["seen"].tolist() == [1.0]  # the env's own array went on counting; the step's copy did not


def test_envs_it_cannot_step_into_its_buffer_are_stepped_as_dummy_vec_env_steps_them():
    # A Dict observation ("features+env"): the env makes its observation itself.
    def build() -> gym.Env:
        return sg.make_env(pendulum.initial_env, pendulum.trees["w"], observation="features+env", check=False)

    reference, together = make_vec_env(build, n_envs=2, seed=1), spec_vec_env(build, n_envs=2, seed=1)
    assert isinstance(together.venv, SpecVecEnv)
    first_a, first_b = reference.reset(), together.reset()
    assert all(np.array_equal(first_a[k], first_b[k]) for k in first_a)
    for _ in range(5):
        action = np.full((2, 1), 0.5, dtype=np.float32)
        a, b = reference.step(action), together.step(action)
        assert all(np.array_equal(a[0][k], b[0][k]) for k in a[0]) and np.array_equal(a[1], b[1])


def test_weights_adapt_through_env_method_on_every_env():
    tree = sg.All(sg.Goal("left", x=(None, -1.0)), sg.Goal("upright", theta=(-0.1, 0.1)), weights="auto", name="poised")
    venv = spec_vec_env(lambda: sg.make_env(CARTPOLE, tree, check=False), n_envs=2, seed=0)
    venv.reset()
    venv.env_method("set_weights", {tree.name: (0.25, 0.75)})
    venv.reset()
    assert venv.get_attr("adapted_weights") == [{tree.name: (0.25, 0.75)}] * 2


@pytest.mark.slow
def test_a_model_trains_the_same_weights_on_the_envs_stepped_together():
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger

    initial_env, tree = _mountain_car_reach()

    def build() -> gym.Env:
        return sg.make_env(initial_env, tree, check=False)

    weights = []
    for vectorise in (make_vec_env, spec_vec_env):
        model = PPO("MlpPolicy", vectorise(build, n_envs=2, seed=5), n_steps=128, batch_size=64, seed=5, device="cpu")
        model.set_logger(Logger(folder=None, output_formats=[]))  # no SB3-<time> folder left in the temp dir
        model.learn(total_timesteps=512)
        weights.append([p.detach().clone() for p in model.policy.parameters()])
    assert all(torch.equal(a, b) for a, b in zip(*weights, strict=True))
