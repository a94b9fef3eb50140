"""Features read from ``info`` and from the env itself (``from_info=``, ``from_env=``), beside ``state(obs)``."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import specguard as sg
from specguard.cache.fingerprint import fingerprint_spec
from specguard.construction.env import make_baseline_env
from specguard.report.show import render_spec
from specguard.starts.space import START_OPTION, StartSpace


class LineEnv(gym.Env[np.ndarray, int]):
    """A walk on a line: the observation is a noise component; the position lives on the env (``self.pos``).

    ``info["hit"]`` says whether the walk is at the right end; ``drop_key_at`` leaves the key out from
    that step on (0: already at reset); ``bad_value`` is reported instead of the flag.
    """

    def __init__(self, drop_key_at: int | None = None, bad_value: Any = None) -> None:
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.action_space = gym.spaces.Discrete(2)
        self.drop_key_at = drop_key_at
        self.bad_value = bad_value
        self.pos = 0
        self.t = 0

    def _info(self) -> dict[str, Any]:
        if self.drop_key_at is not None and self.t >= self.drop_key_at:
            return {"other": 1}
        return {"hit": self.bad_value if self.bad_value is not None else self.pos >= 3}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.pos, self.t = 0, 0
        return np.zeros(1, np.float32), self._info()

    def step(self, action: int):
        self.t += 1
        self.pos = max(-3, min(3, self.pos + (1 if action == 1 else -1)))
        return np.array([0.5], np.float32), 0.0, False, self.t >= 20, self._info()


class DictEnv(LineEnv):
    """The same walk with a ``Dict`` observation (an image and a direction), as MiniGrid's."""

    def __init__(self) -> None:
        super().__init__()
        self.observation_space = gym.spaces.Dict(
            {"image": gym.spaces.Box(0, 255, (3, 3, 3), np.uint8), "direction": gym.spaces.Discrete(4)}
        )

    def _obs(self) -> dict[str, Any]:
        return {"image": np.zeros((3, 3, 3), np.uint8), "direction": 0}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        _, info = super().reset(seed=seed, options=options)
        return self._obs(), info

    def step(self, action: int):
        _, r, term, trunc, info = super().step(action)
        return self._obs(), r, term, trunc, info


def line(**kwargs: Any) -> sg.InitialEnv:
    return sg.InitialEnv(
        LineEnv,
        features=("noise",),
        from_info={"hit": "hit"},
        from_env={"x": lambda env: env.pos},
        bounds={"x": (-3, 3), "hit": (0, 1)},
        **kwargs,
    )


RIGHT = sg.Goal("right", x=(3, 3))


def test_info_and_env_features_join_the_observation_after_the_observations_own():
    initial = line()
    assert initial.features == ("noise", "hit", "x")
    env = sg.make_env(initial, RIGHT)
    assert env.observation_space.shape == (3,)
    assert env.observation_space.low.tolist() == [-1.0, 0.0, -3.0]
    obs, info = env.reset(seed=0)
    assert obs.tolist() == [0.0, 0.0, 0.0] and info["goals"] == {"right": False}
    for expected in (1, 2):
        obs, *_ = env.step(1)
        assert obs.tolist() == [0.5, 0.0, float(expected)]
    obs, reward, terminated, _, info = env.step(1)
    assert obs.tolist() == [0.5, 1.0, 3.0]  # the flag as 1.0, the position from the env
    assert terminated and info["goals"] == {"right": True} and reward == 1.0


def test_a_goal_on_an_info_flag_and_a_constraint_on_it():
    tree = sg.Goal("hit", hit=(1, 1)).annotate(sg.Constraint(lambda s, a: s.x < -1, name="left", budget=1))
    for evaluator in ("flat", "reference"):
        env = sg.make_env(line(), tree, evaluator=evaluator)
        env.reset(seed=0)
        rewards = []
        for a in (0, 0, 1, 1, 1, 1, 1):
            _, r, terminated, _, info = env.step(a)
            rewards.append(r)
            if terminated:
                break
        assert info["safe"] == {"hit:left": False} and terminated, evaluator


def test_both_evaluators_agree_on_env_features():
    tree = sg.All(
        RIGHT.annotate(sg.Distance(lambda s: abs(3 - s.x), scale=6.0)), sg.Goal("flag", hit=(1, 1)), name="both"
    )
    runs = {}
    for evaluator in ("flat", "reference"):
        env = sg.make_env(line(), tree, evaluator=evaluator)
        env.reset(seed=0)
        runs[evaluator] = [env.step(a)[:3] for a in (1, 0, 1, 1, 1)]
    assert [(o.tolist(), r, t) for o, r, t in runs["flat"]] == [(o.tolist(), r, t) for o, r, t in runs["reference"]]


def test_a_dict_observation_with_all_features_from_the_env():
    initial = sg.InitialEnv(DictEnv, from_env={"x": lambda env: env.pos}, bounds={"x": (-3, 3)})
    assert initial.features == ("x",)
    env = sg.make_env(initial, RIGHT)
    assert env.observation_space == gym.spaces.Box(-3.0, 3.0, (1,), np.float32)
    env.reset(seed=0)
    for _ in range(3):
        obs, _, terminated, _, _ = env.step(1)
    assert obs.tolist() == [3.0] and terminated
    baseline = make_baseline_env(initial, RIGHT)
    obs, info = baseline.reset(seed=0)
    assert set(obs) == {"image", "direction"} and info["goals"] == {"right": False}


def test_a_dict_observation_with_features_from_state_and_the_env():
    initial = sg.InitialEnv(
        DictEnv,
        features=("direction",),
        state=lambda obs: (obs["direction"],),
        from_env={"x": lambda env: env.pos},
    )
    env = sg.make_env(initial, RIGHT)
    obs, _ = env.reset(seed=0)
    assert obs.tolist() == [0.0, 0.0]


@pytest.mark.parametrize(
    ("drop_key_at", "when"),
    [(0, "at reset"), (3, "at step 3")],
)
def test_a_missing_info_key_names_the_feature_and_the_step(drop_key_at, when):
    env = sg.make_env(line(drop_key_at=drop_key_at), RIGHT) if drop_key_at else None
    if env is None:
        with pytest.raises(sg.error.StateMappingError, match=rf"feature 'hit' reads info\['hit'\].*{when}.*'other'"):
            sg.make_env(line(drop_key_at=drop_key_at), RIGHT).reset(seed=0)
        return
    env.reset(seed=0)
    env.step(1)
    env.step(1)
    with pytest.raises(sg.error.StateMappingError, match=rf"feature 'hit' reads info\['hit'\].*{when}"):
        env.step(1)


@pytest.mark.parametrize("value", ["yes", None, float("nan"), np.array([1.0, 2.0]), [1]])
def test_an_info_value_that_is_not_a_number_or_a_bool_names_the_feature(value):
    env = sg.make_env(line(), RIGHT)
    env.unwrapped.bad_value = value if value is not None else "none"
    with pytest.raises(sg.error.StateMappingError, match=r"feature 'hit' reads info\['hit'\] = .* at reset: expected"):
        env.reset(seed=0)


@pytest.mark.parametrize("digits", [400, 5000])  # past 4300 digits, Python refuses even the int's repr
def test_an_int_past_a_floats_range_names_the_feature_and_the_step_in_bounded_words(digits):
    big = 10 ** (digits - 1)
    env = sg.make_env(line(), RIGHT)
    env.unwrapped.bad_value = big
    with pytest.raises(sg.error.StateMappingError) as e:  # not an OverflowError naming nothing
        env.reset(seed=0)
    assert e.value.message.endswith(
        f"feature 'hit' reads info['hit'] = an int of about {digits} digits, past a float's range, at reset: "
        "expected a finite real number or a bool"
    )
    initial = sg.InitialEnv(LineEnv, features=("noise",), from_env={"x": lambda env: big if env.t == 2 else 0})
    env = sg.make_env(initial, RIGHT)
    env.reset(seed=0)
    env.step(1)
    with pytest.raises(
        sg.error.StateMappingError, match=r"feature 'x' reads from_env\['x'\]\(env\) = an int of about"
    ) as e:
        env.step(1)
    assert "at step 2: expected" in e.value.message and len(e.value.message) < 300


def test_an_env_feature_that_raises_or_returns_a_non_number_names_the_feature_and_the_step():
    initial = sg.InitialEnv(LineEnv, features=("noise",), from_env={"x": lambda env: env.nope})
    with pytest.raises(
        sg.error.StateMappingError,
        match=r"feature 'x' reads from_env\['x'\]\(env\), which raised AttributeError.*at reset",
    ):
        sg.make_env(initial, RIGHT).reset(seed=0)
    initial = sg.InitialEnv(LineEnv, features=("noise",), from_env={"x": lambda env: "left" if env.t == 2 else 0})
    env = sg.make_env(initial, RIGHT)
    env.reset(seed=0)
    env.step(1)
    with pytest.raises(
        sg.error.StateMappingError, match=r"feature 'x' reads from_env\['x'\]\(env\) = 'left' at step 2"
    ):
        env.step(1)


def test_bools_and_numpy_numbers_are_features():
    initial = sg.InitialEnv(
        LineEnv, from_env={"a": lambda env: np.bool_(True), "b": lambda env: np.int64(2), "c": lambda env: True}
    )
    env = sg.make_env(initial, sg.Goal("g", b=(5, 6)))
    obs, _ = env.reset(seed=0)
    assert obs.tolist() == [1.0, 2.0, 1.0]


def test_declarations_are_checked():
    with pytest.raises(sg.error.InitialEnvError, match=r"InitialEnv features"):
        sg.InitialEnv(LineEnv)
    with pytest.raises(sg.error.InitialEnvError, match=r"names must be unique, \['x'\]"):
        sg.InitialEnv(LineEnv, features=("x",), state=lambda o: o, from_env={"x": lambda env: env.pos})
    with pytest.raises(sg.error.InitialEnvError, match=r"from_env: expected .*'x'.* callable"):
        sg.InitialEnv(LineEnv, from_env={"x": 3})
    with pytest.raises(sg.error.InitialEnvError, match=r"from_info: expected .*'hit'.* info key"):
        sg.InitialEnv(LineEnv, from_info={"hit": 3})
    with pytest.raises(sg.error.InitialEnvError, match=r"from_info"):
        sg.InitialEnv(LineEnv, from_info="hit")
    with pytest.raises(sg.error.InitialEnvError, match=r"state.*no features"):
        sg.InitialEnv(LineEnv, state=lambda o: o, from_env={"x": lambda env: env.pos})
    assert sg.InitialEnv(LineEnv, from_info=("hit",)).from_info == (("hit", "hit"),)


def test_the_repr_and_show_name_the_sources():
    initial = line()
    text = repr(initial)
    assert "features=('noise',)" in text
    assert "from_info={'hit': 'hit'}" in text and "from_env={'x': " in text
    shown = render_spec(sg.Spec(initial, RIGHT, budget=sg.Budget(timesteps=2048)))
    assert any(ln.split()[:1] == ["x"] and "3" in ln for ln in shown.splitlines()), shown


def test_the_env_features_functions_are_part_of_the_spec_key():
    def key(initial):
        return fingerprint_spec(sg.Spec(initial, RIGHT, budget=sg.Budget(timesteps=2048))).spec_key

    a = sg.InitialEnv(LineEnv, features=("noise",), from_env={"x": lambda env: env.pos})
    b = sg.InitialEnv(LineEnv, features=("noise",), from_env={"x": lambda env: env.pos + 0})
    c = sg.InitialEnv(LineEnv, features=("noise",), from_env={"x": lambda env: env.pos}, from_info={"hit": "hit"})
    d = sg.InitialEnv(LineEnv, features=("noise",), from_env={"x": lambda env: env.pos}, from_info={"hit": "other"})
    assert len({key(a), key(b), key(c), key(d)}) == 4
    assert key(a) == key(sg.InitialEnv(LineEnv, features=("noise",), from_env={"x": lambda env: env.pos}))


def test_a_falsifier_start_set_on_the_env_is_read_by_the_env_features():
    def set_pos(env, values):
        env.unwrapped.pos = int(values["pos"])
        return np.zeros(1, np.float32)

    env = sg.make_env(line(), RIGHT, starts=StartSpace({"pos": (-3, 3)}, set_state=set_pos))
    obs, _ = env.reset(seed=0, options={START_OPTION: {"pos": 2.0}})
    assert obs.tolist() == [0.0, 0.0, 2.0]
    obs, _, terminated, _, _ = env.step(1)
    assert obs.tolist()[2] == 3.0 and terminated


def test_a_missing_info_key_at_reset_is_refused_before_any_seed_trains():
    # Found once only inside a training worker ("seed 0 failed", exit 1): now the start check's, a SpecError.
    spec = sg.Spec(line(drop_key_at=0), RIGHT, budget=sg.Budget(timesteps=64, min_seeds=1), expect=0.5)
    with pytest.raises(sg.error.StateMappingError, match=r"feature 'hit' reads info\['hit'\].*at reset"):
        sg.run_spec(spec, workers=1, cache_dir=None, progress=None)
