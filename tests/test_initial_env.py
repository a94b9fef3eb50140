"""InitialEnv: declaration, base env construction and validation errors."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import specguard as sg


def test_declaring_builds_nothing_and_reads_well():
    env = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"), g=9.81)
    assert env.features == ("x", "y", "omega")
    assert repr(env) == "InitialEnv('Pendulum-v1', features=('x', 'y', 'omega'), g=9.81)"
    base = env.make()
    assert base.unwrapped.g == 9.81
    base.close()


def test_unknown_env_id():
    with pytest.raises(sg.error.InitialEnvError, match=r"InitialEnv 'Pendulum-v9': no such Gymnasium environment id"):
        sg.InitialEnv("Pendulum-v9", features=("x",))
    with pytest.raises(sg.error.InitialEnvError, match=r"InitialEnv 'NoSuchEnv-v0': no such Gymnasium environment id"):
        sg.InitialEnv("NoSuchEnv-v0", features=("x",))


@pytest.mark.parametrize("features", [(), "xy", ("x", "x"), ("x", "1y"), ("_x",), ("class",), [3]])
def test_bad_feature_names(features):
    with pytest.raises(sg.error.InitialEnvError, match=r"InitialEnv features"):
        sg.InitialEnv("Pendulum-v1", features=features)


def test_mappings_must_be_callable():
    with pytest.raises(sg.error.InitialEnvError, match=r"expected state to be callable"):
        sg.InitialEnv("Pendulum-v1", features=("x",), state=3)


def test_factory_must_return_an_env():
    env = sg.InitialEnv(lambda: "not an env", features=("x",))
    with pytest.raises(sg.error.InitialEnvError, match=r"the factory returned str, expected a gymnasium.Env"):
        env.make()


def test_env_must_be_id_or_factory():
    with pytest.raises(sg.error.InitialEnvError, match=r"expected an env id or a factory"):
        sg.InitialEnv(42, features=("x",))


def test_bounds_are_checked_and_used():
    with pytest.raises(sg.error.InitialEnvError, match=r"bounds name unknown feature 'z'; known features: x, y"):
        sg.InitialEnv("Pendulum-v1", features=("x", "y"), state=lambda o: o[:2], bounds={"z": (0, 1)})
    with pytest.raises(sg.error.InitialEnvError, match=r"bounds for 'x' must satisfy lo <= hi"):
        sg.InitialEnv("Pendulum-v1", features=("x", "y"), state=lambda o: o[:2], bounds={"x": (1, 0)})
    env = sg.InitialEnv("Pendulum-v1", features=("x", "y"), state=lambda o: o[:2], bounds={"x": (-1, 1)})
    lo, hi = env.feature_bounds(gym.spaces.Box(-5, 5, (3,)))
    assert lo.tolist() == [-1.0, -np.inf] and hi.tolist() == [1.0, np.inf]


def test_identity_state_takes_bounds_from_the_observation_space():
    env = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    lo, hi = env.feature_bounds(env.make().observation_space)
    assert lo.tolist() == [-1.0, -1.0, -8.0] and hi.tolist() == [1.0, 1.0, 8.0]


def test_identity_state_bounds_need_one_feature_per_component():
    env = sg.InitialEnv("CartPole-v1", features=("a", "b", "c", "d", "e"))
    with pytest.raises(sg.error.StateMappingError, match=r"InitialEnv 'CartPole-v1': .* 5 features .* 4 components"):
        env.feature_bounds(gym.spaces.Box(-1, 1, (4,)))
    with pytest.raises(sg.error.StateMappingError, match=r"Hint: name exactly 4 features"):
        env.check_observation_space(gym.spaces.Box(-1, 1, (4,)))
    env.check_observation_space(gym.spaces.Box(-1, 1, (5,)))
    mapped = sg.InitialEnv("CartPole-v1", features=("a",), state=lambda o: o[:1])
    mapped.check_observation_space(gym.spaces.Discrete(3))  # state() maps any observation


def test_action_space_must_be_a_space():
    with pytest.raises(sg.error.InitialEnvError, match=r"expected action_space to be a gymnasium Space"):
        sg.InitialEnv("Pendulum-v1", features=("x",), action_space=(0, 1))
