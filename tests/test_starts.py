"""Start spaces: the built-in setters put each classic-control env in the start asked for; bad spaces are refused."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from specguard.error import InvalidSpec, UnknownFeature
from specguard.starts.space import BUILTIN_SETTERS, START_OPTION, StartSpace


def start(env_id, values, **space):
    env = gym.make(env_id)
    starts = StartSpace(**space).resolve(env)
    wrapped = starts.wrap(env)
    obs, _ = wrapped.reset(seed=0, options={START_OPTION: values})
    return wrapped, obs


@pytest.mark.parametrize(
    ("env_id", "values", "expected"),
    [
        ("CartPole-v1", {"x": 1.0, "v": -0.5, "theta": 0.1, "omega": 0.3}, [1.0, -0.5, 0.1, 0.3]),
        ("Pendulum-v1", {"theta": math.pi / 2, "omega": 2.0}, [0.0, 1.0, 2.0]),
        (
            "Acrobot-v1",
            {"theta1": math.pi, "theta2": 0.0, "omega1": 1.0, "omega2": -1.0},
            [-1.0, 0.0, 1.0, 0.0, 1.0, -1.0],
        ),
        ("MountainCar-v0", {"position": 0.3, "velocity": 0.01}, [0.3, 0.01]),
        ("MountainCarContinuous-v0", {"position": -1.0, "velocity": -0.02}, [-1.0, -0.02]),
    ],
)
def test_each_builtin_setter_starts_its_env_in_the_state_asked_for(env_id, values, expected):
    env, obs = start(env_id, values)
    np.testing.assert_allclose(obs, expected, atol=1e-6)
    nxt = env.step(env.action_space.sample())[0]  # the dynamics go on from there
    assert np.all(np.isfinite(nxt)) and not np.allclose(nxt, gym.make(env_id).reset(seed=0)[0])


def test_without_a_start_the_env_resets_as_usual():
    env = StartSpace().resolve(gym.make("CartPole-v1")).wrap(gym.make("CartPole-v1"))
    np.testing.assert_array_equal(env.reset(seed=3)[0], gym.make("CartPole-v1").reset(seed=3)[0])


def test_ranges_left_out_keep_the_envs_own_reset_range():
    starts = StartSpace({"x": (-1.0, 1.0)}).resolve(gym.make("CartPole-v1"))
    assert starts.names == ("x", "v", "theta", "omega")
    assert starts.low.tolist() == [-1.0, -0.05, -0.05, -0.05] and starts.high.tolist() == [1.0, 0.05, 0.05, 0.05]
    points = starts.uniform(np.random.default_rng(0), 500)
    assert points.shape == (500, 4) and np.all(points >= starts.low) and np.all(points <= starts.high)
    assert points[:, 0].min() < -0.9 and points[:, 0].max() > 0.9


@pytest.mark.parametrize(
    ("env_id", "values", "attributes"),
    [
        ("CartPole-v1", {"length": 0.8, "masspole": 0.3}, {"length": 0.8, "total_mass": 1.3, "polemass_length": 0.24}),
        ("Pendulum-v1", {"g": 3.7}, {"g": 3.7}),
        ("Acrobot-v1", {"link_mass_2": 2.0}, {"LINK_MASS_2": 2.0}),
        ("MountainCar-v0", {"gravity": 0.003}, {"gravity": 0.003}),
        ("MountainCarContinuous-v0", {"power": 0.001}, {"power": 0.001}),
    ],
)
def test_a_start_space_may_range_over_the_envs_physical_parameters(env_id, values, attributes):
    space = StartSpace({n: (v, v) for n, v in values.items()})
    starts = space.resolve(gym.make(env_id))
    assert set(starts.names[-len(values) :]) == set(values)  # after the state variables, only those declared
    point = starts.uniform(np.random.default_rng(0), 1)[0]
    env, _ = start(env_id, starts.values(point), ranges={n: (v, v) for n, v in values.items()})
    fresh = gym.make(env_id).unwrapped
    for attribute, value in attributes.items():
        assert getattr(env.unwrapped, attribute) == pytest.approx(value)
        assert getattr(fresh, attribute) != pytest.approx(value)  # set on that env alone, not on its class


def test_a_parameter_range_must_lie_above_zero():
    with pytest.raises(InvalidSpec, match=r"the range of the parameter 'length' is \(0, 1\): expected values > 0"):
        StartSpace({"length": (0.0, 1.0)}).resolve(gym.make("CartPole-v1"))


def test_every_builtin_default_lies_within_its_bounds():
    for setter in BUILTIN_SETTERS.values():
        assert set(setter.default) == set(setter.bounds) == set(setter.names)
        for name, (lo, hi) in setter.default.items():
            assert setter.bounds[name][0] <= lo <= hi <= setter.bounds[name][1]


def test_an_unknown_variable_is_named_with_the_known_ones():
    known = "x, v, theta, omega, gravity, masscart, masspole, length, force_mag"
    with pytest.raises(UnknownFeature, match=rf"'theta_dot', which its setter does not know; known: {known}"):
        StartSpace({"theta_dot": (0, 1)}).resolve(gym.make("CartPole-v1"))


def test_a_range_outside_the_bounds_names_both():
    with pytest.raises(
        InvalidSpec,
        match=r"CartPole-v1: the range of 'theta' is \(-0.5, 0.5\), outside its bounds \(-0.418879, 0.418879\)",
    ):
        StartSpace({"theta": (-0.5, 0.5)}).resolve(gym.make("CartPole-v1"))


@pytest.mark.parametrize(
    ("ranges", "message"),
    [
        ({"x": (1.0, -1.0)}, r"finite with lo <= hi, got \(1.0, -1.0\)"),
        ({"x": (0.0, math.inf)}, r"expected the high end of 'x' to be a finite number, got inf"),
        ({"x": "wide"}, r"a pair \(lo, hi\) of numbers, got 'wide'"),
    ],
)
def test_a_malformed_range_is_refused_with_its_value(ranges, message):
    with pytest.raises(InvalidSpec, match=message):
        StartSpace(ranges)


def test_an_env_that_cannot_be_set_searches_its_reset_seeds_and_says_so():
    env = gym.make("LunarLander-v3")
    starts = StartSpace().resolve(env)
    assert starts.how == "reset seeds" and "cannot be set, so reset seeds are searched" in starts.note
    wrapped = starts.wrap(env)
    obs, _ = wrapped.reset(options={START_OPTION: starts.values(np.array([7.0]))})
    np.testing.assert_array_equal(obs, gym.make("LunarLander-v3").reset(seed=7)[0])
    with pytest.raises(InvalidSpec, match=r"its state cannot be set .* yet the start space gives ranges for x"):
        StartSpace({"x": (0, 1)}).resolve(env)


def test_the_set_state_hook_and_reset_options_start_any_env():
    def set_state(env, values):
        env.unwrapped.state = np.array([values["theta"], 0.0])
        return env.unwrapped._get_obs()

    _, obs = start("Pendulum-v1", {"theta": 0.0}, ranges={"theta": (-1, 1)}, set_state=set_state)
    np.testing.assert_allclose(obs, [1.0, 0.0, 0.0], atol=1e-6)
    _, obs = start(
        "Pendulum-v1", {"x_init": 0.0, "y_init": 0.0}, ranges={"x_init": (0, 1), "y_init": (0, 1)}, reset_options=True
    )
    np.testing.assert_allclose(obs, [1.0, 0.0, 0.0], atol=1e-6)  # Pendulum draws within +-x_init: 0 is upright, still
    with pytest.raises(InvalidSpec, match="not both"):
        StartSpace({"a": (0, 1)}, set_state=set_state, reset_options=True)
    with pytest.raises(InvalidSpec, match="needs the ranges of its variables"):
        StartSpace(set_state=set_state).resolve(gym.make("Pendulum-v1"))


@pytest.mark.parametrize(
    ("ranges", "message"),
    [
        ({"x": ("0", "1")}, r"StartSpace: expected the low end of 'x' to be a finite number, got '0'"),
        ({"x": (0.0, "1")}, r"StartSpace: expected the high end of 'x' to be a finite number, got '1'"),
        ({"x": (False, True)}, r"StartSpace: expected the low end of 'x' to be a finite number, got False"),
        ({"x": (0, np.bool_(True))}, r"expected the high end of 'x' to be a finite number, got np.True_"),
        ({"x": "01"}, r"StartSpace: the range of 'x' must be a pair \(lo, hi\) of numbers, got '01'"),
        ({"x": (0, 1, 2)}, r"the range of 'x' must be a pair \(lo, hi\) of numbers, got \(0, 1, 2\)"),
        ({"x": {0: 1, 1: 2}}, r"the range of 'x' must be a pair \(lo, hi\) of numbers, got \{0: 1, 1: 2\}"),
        ({5: (0, 1)}, r"StartSpace: expected a variable's name to be a non-empty string, got 5"),
        ({None: (0, 1)}, r"StartSpace: expected a variable's name to be a non-empty string, got None"),
        ({"": (0, 1)}, r"StartSpace: expected a variable's name to be a non-empty string, got ''"),
        ({1: (0, 1), "1": (2, 3)}, r"StartSpace: expected a variable's name to be a non-empty string, got 1"),
    ],
)
def test_bounds_and_names_are_never_coerced(ranges, message):
    with pytest.raises(InvalidSpec, match=message):
        StartSpace(ranges)


@pytest.mark.parametrize("value", ["no", 1, None, "False"])
def test_reset_options_is_a_bool(value):
    with pytest.raises(InvalidSpec, match=rf"StartSpace: expected reset_options to be True or False, got {value!r}"):
        StartSpace({"a": (0, 1)}, reset_options=value)


def test_a_range_may_be_any_pair_of_real_numbers():
    space = StartSpace({"x": [np.float32(-0.5), 1], "y": np.array([0.0, 0.25])})
    assert space.ranges == (("x", -0.5, 1.0), ("y", 0.0, 0.25))
    assert all(type(v) is float for _, lo, hi in space.ranges for v in (lo, hi))
