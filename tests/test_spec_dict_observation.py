"""``Spec(observation="features+env")``: the agent sees the env's own observation beside the features and own state.

The observation is a ``Dict``: the features and the goal tree's own state under ``"spec"`` (so it stays Markov),
the env's own keys beside them (a non-``Dict`` observation under ``"observation"``); the goals are judged on the
features alone. It trains with ``MultiInputPolicy``, is cached and served from the cache, and every place that
stacks observations (the falsifier's lockstep batches, the policy) takes it.
"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import specguard as sg
from specguard.cache.fingerprint import _fields, _trained_fields, fingerprint_spec
from specguard.construction.env import ENV_KEY, SPEC_KEY, stack_observations
from specguard.engine.falsify_run import batch_policy, property_keys
from specguard.engine.result_models import load_normalizer
from specguard.evaluation.policy import policy
from specguard.falsify.search import EpisodeRunner
from specguard.report.show import render_spec
from specguard.training.train import train_run

LENGTH = 5  # cells 0 .. 4; the agent starts at 0


class Corridor(gym.Env):
    """A walk along ``LENGTH`` cells whose observation is a ``Dict``: the cell one-hot, and a clock.

    The position ``x`` is the env's own (``from_env``); action 1 steps right, 0 steps left.
    """

    observation_space = gym.spaces.Dict(
        {"view": gym.spaces.Box(0.0, 1.0, (LENGTH,), np.float32), "clock": gym.spaces.Discrete(64)}
    )
    action_space = gym.spaces.Discrete(2)

    def __init__(self, render_mode=None):
        self.metadata = {"render_modes": ["rgb_array"]}
        self.render_mode = render_mode

    def render(self):
        frame = np.zeros((8, 8 * LENGTH, 3), np.uint8)
        frame[:, 8 * self.x : 8 * self.x + 8] = 255
        return frame

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.x, self.t = 0, 0
        return self._obs(), {}

    def step(self, action):
        self.x = min(LENGTH - 1, max(0, self.x + (1 if int(action) == 1 else -1)))
        self.t += 1
        return self._obs(), 0.0, False, False, {}

    def _obs(self):
        return {"view": np.eye(LENGTH, dtype=np.float32)[self.x], "clock": self.t}


def corridor(**kwargs):
    return gym.wrappers.TimeLimit(Corridor(**kwargs), max_episode_steps=12)


CORRIDOR = sg.InitialEnv(corridor, from_env={"x": lambda env: env.x}, bounds={"x": (0, LENGTH - 1)})
# A constraint gives the tree an own state (its counter): stepping left from the start wastes a step.
TREE = sg.Goal("end", x=(LENGTH - 1, LENGTH - 1)).annotate(sg.Constraint(lambda s, a: int(a) == 0, budget=3))
TINY = {"n_steps": 32, "batch_size": 32, "n_epochs": 1}
BUDGET = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=4, checkpoints=1)


def spec(**kwargs):
    kwargs.setdefault("budget", BUDGET)
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=TINY))
    return sg.Spec(CORRIDOR, TREE, **kwargs)


ACTIONS = [1, 0, 0, 1, 1, 1, 1, 1]


def walk(env, actions=ACTIONS):
    """The observation and info after the reset and after each of ``actions``, with each step's reward and ends."""
    obs, info = env.reset(seed=0)
    seen = [(obs, info, None, False)]
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        seen.append((obs, info, reward, terminated))
        if terminated or truncated:
            break
    return seen


# -- the observation ------------------------------------------------------------------------------------------


def test_the_spec_key_holds_the_features_and_own_state_and_the_env_keys_are_the_envs_own():
    env = sg.make_env(CORRIDOR, TREE, observation="features+env")
    space = env.observation_space
    assert isinstance(space, gym.spaces.Dict) and set(space.spaces) == {SPEC_KEY, "view", "clock"}
    assert space[SPEC_KEY] == sg.make_env(CORRIDOR, TREE).observation_space  # today's Box, as it was
    assert space["view"] == Corridor.observation_space["view"] and space["clock"] == gym.spaces.Discrete(64)
    raw = corridor()
    raw_obs = [raw.reset(seed=0)[0]] + [raw.step(a)[0] for a in ACTIONS[:5]]
    for (obs, *_), own in zip(walk(env, ACTIONS[:5]), raw_obs, strict=True):
        assert obs in space
        assert np.array_equal(obs["view"], own["view"]) and obs["clock"] == own["clock"]
        assert obs[SPEC_KEY][0] == float(np.argmax(own["view"]))  # the feature x: the env's position


def test_the_own_state_stays_in_the_observation_markov():
    env = sg.make_env(CORRIDOR, TREE, observation="features+env")
    counters = [obs[SPEC_KEY][1] for obs, *_ in walk(env)]
    assert len(env.evaluator.slots) == 1
    # The constraint's budget left: 3 at the start, one less after each step left (actions 2 and 3).
    assert counters[:4] == [3.0, 3.0, 2.0, 1.0] and counters[-1] == 1.0


def test_the_goal_tree_reads_the_features_alone():
    flat = walk(sg.make_env(CORRIDOR, TREE))
    beside = walk(sg.make_env(CORRIDOR, TREE, observation="features+env"))
    assert len(flat) == len(beside) and beside[-1][3] is True  # the root goal reached ends both alike
    for (obs, info, reward, ended), (dict_obs, dict_info, dict_reward, dict_ended) in zip(flat, beside, strict=True):
        assert np.array_equal(obs, dict_obs[SPEC_KEY])
        assert (info["goals"], info["safe"], reward, ended) == (
            dict_info["goals"],
            dict_info["safe"],
            dict_reward,
            dict_ended,
        )


def test_an_observation_that_is_no_dict_stands_under_its_own_key():
    pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    env = sg.make_env(pendulum, sg.Goal("spin", omega=(7.0, 8.0)), observation="features+env")
    assert set(env.observation_space.spaces) == {SPEC_KEY, ENV_KEY}
    assert env.observation_space[ENV_KEY] == gym.make("Pendulum-v1").observation_space
    obs, _ = env.reset(seed=3)
    assert np.array_equal(obs[ENV_KEY], gym.make("Pendulum-v1").reset(seed=3)[0])
    assert np.array_equal(obs[SPEC_KEY], obs[ENV_KEY])  # identity features, no own state
    assert gym.make(env.spec).observation_space == env.observation_space  # env.spec re-creates it, Dict and all


def test_minigrid_with_its_image():
    pytest.importorskip("minigrid")
    from example_specs import minigrid_image

    grid = minigrid_image.specs["green_square"]
    assert grid.trainer.policy == "MultiInputPolicy"
    env = grid.make_env()
    obs, _ = env.reset(seed=0)
    assert obs[ENV_KEY].shape == (56, 56, 3) and obs[ENV_KEY].dtype == np.uint8  # NatureCNN takes it
    assert obs[SPEC_KEY].tolist() == [1.0, 1.0, 0.0]  # read from the env object through MiniGrid's wrappers
    obs, *_ = env.step(2)  # forward: one cell right
    assert obs[SPEC_KEY].tolist() == [2.0, 1.0, 0.0]


# -- refused ------------------------------------------------------------------------------------------------


class Talking(Corridor):
    observation_space = gym.spaces.Dict(
        {"view": Corridor.observation_space["view"], "mission": gym.spaces.Text(8), "spec": gym.spaces.Discrete(2)}
    )


def test_an_env_key_stable_baselines3_cannot_take_or_that_clashes_is_refused_one_line_each():
    talking = sg.InitialEnv(Talking, from_env={"x": lambda env: env.x}, bounds={"x": (0, LENGTH - 1)})
    with pytest.raises(sg.error.InvalidSpec) as caught:
        sg.make_env(talking, TREE, observation="features+env")
    lines = str(caught.value).splitlines()
    assert lines[0] == (
        "end: observation='features+env': the env's key 'mission' is a Text, which stable-baselines3 cannot take "
        "in a Dict observation (it takes Box, Discrete, MultiDiscrete and MultiBinary)"
    )
    assert (
        lines[1]
        == "observation='features+env': the env's observation has a key 'spec', where the features and own state go"
    )
    assert "ImgObsWrapper" in lines[2]
    sg.make_env(talking, TREE)  # the features alone: the env's own keys are not the agent's


class Bare(Corridor):
    """A corridor whose observation has a key that is no string, and an empty part (both pass Gymnasium's Dict)."""

    observation_space = gym.spaces.Dict(
        {"view": Corridor.observation_space["view"], 7: gym.spaces.Discrete(2), "nothing": gym.spaces.Box(0, 1, (0,))}
    )


def test_an_env_key_that_is_no_string_or_an_empty_part_is_refused_naming_the_observation():
    bare = sg.InitialEnv(Bare, from_env={"x": lambda env: env.x}, bounds={"x": (0, LENGTH - 1)})
    with pytest.raises(sg.error.InvalidSpec) as caught:
        sg.make_env(bare, TREE, observation="features+env")
    assert str(caught.value).splitlines()[:2] == [
        "end: observation='features+env': the env's observation has a key 7 of type int, and stable-baselines3 takes "
        "only string keys in a Dict observation",
        "observation='features+env': the env's key 'nothing' is an empty Box (shape (0,)): it shows nothing",
    ]
    sg.make_env(bare, TREE)  # the features alone: the env's own keys are not the agent's


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"observation": "env"}, r"Spec 'end': expected observation to be one of features, features\+env, got 'env'"),
        (
            {"baseline": True},
            r"Spec 'end'.observation: baseline=True trains on the initial env's own observation; "
            r"observation='features\+env' is for the constructed env",
        ),
        (
            {"trainer": sg.SB3(policy="MlpPolicy", hyperparameters=TINY)},
            r"Spec 'end'.trainer.policy: the agent's observation is a Dict \(observation='features\+env'\), "
            r"which 'MlpPolicy' does not take; one that does: MultiInputPolicy",
        ),
        (
            {"trainer": sg.SB3("ARS")},
            r"Spec 'end'.trainer.policy: .*which 'MultiInputPolicy' does not take; "
            r"one that does: none: ARS has no policy",
        ),
    ],
)
def test_combinations_that_cannot_work_are_refused(kwargs, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        spec(observation=kwargs.pop("observation", "features+env"), **kwargs)


def test_a_dict_policy_for_the_flat_observation_is_refused_naming_the_one_that_fits():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"the agent's observation is a flat Box .*'MultiInputPolicy' does not"
    ) as e:
        spec(trainer=sg.SB3(policy="MultiInputPolicy", hyperparameters=TINY))
    assert e.value.message.endswith("one that does: MlpPolicy")  # not CnnPolicy: the features are no image


def test_the_default_policy_follows_the_observation():
    assert spec().trainer.policy == "MlpPolicy"
    assert spec(observation="features+env").trainer.policy == "MultiInputPolicy"
    assert (
        spec(observation="features+env", trainer=sg.SB3(algorithm="RecurrentPPO", hyperparameters=TINY)).trainer.policy
        == "MultiInputLstmPolicy"
    )


# -- identity --------------------------------------------------------------------------------------------------


def test_the_observation_is_in_a_runs_key_only_when_it_is_not_the_default():
    default = spec()
    fields = _trained_fields(default, _fields(default, frozenset()))
    assert "observation" not in fields and "policy" not in fields  # the keys of specs before the field: unchanged
    beside = spec(observation="features+env")
    fields = _trained_fields(beside, _fields(beside, frozenset()))
    assert fields["observation"] == "features+env" and "policy" not in fields  # MultiInputPolicy: its default
    one, other = fingerprint_spec(default), fingerprint_spec(beside)
    assert one.run_base != other.run_base and one.spec_key != other.spec_key
    assert other.reproducible  # the probe hashes a Dict observation by its parts, not by object addresses


# -- training, caching, acting ----------------------------------------------------------------------------------


@pytest.mark.slow
def test_a_dict_spec_trains_with_multi_input_policy_is_judged_and_served_from_the_cache(tmp_path):
    from stable_baselines3.common.policies import MultiInputActorCriticPolicy

    first = spec(observation="features+env", expect={"end": 0.5})
    result = sg.run_spec(first, workers=1, cache_dir=tmp_path, progress=None)
    assert [r.timesteps for r in result.runs] == [128] and result.cached == {0: False}
    assert result.runs[0].episodes >= BUDGET.eval_episodes and set(result.runs[0].successes) == {
        "end",
        "end:constraint",
    }
    model = sg.load_model(result, 0)
    assert isinstance(model.policy, MultiInputActorCriticPolicy)
    steps = sg.rollout(result, 0)[0]  # the cached model acts on Dict observations
    assert set(steps[0]["obs"]) == {SPEC_KEY, "view", "clock"}
    again = sg.run_spec(
        spec(observation="features+env", expect={"end": 0.5}), workers=1, cache_dir=tmp_path, progress=None
    )
    assert again.cached == {0: True} and again.runs[0].successes == result.runs[0].successes


@pytest.mark.slow
def test_normalize_normalizes_the_features_and_own_state_only(tmp_path):
    result, model = train_run(spec(observation="features+env", trainer=sg.SB3(normalize=True, hyperparameters=TINY)), 0)
    normalizer = model.get_env()
    assert normalizer.norm_obs_keys == [SPEC_KEY] and set(normalizer.obs_rms) == {SPEC_KEY}
    assert result.timesteps == 128
    cached = sg.run_spec(
        spec(observation="features+env", trainer=sg.SB3(normalize=True, hyperparameters=TINY)),
        workers=1,
        cache_dir=tmp_path,
        progress=None,
    )
    assert set(load_normalizer(cached, 0).obs_rms) == {SPEC_KEY}  # the statistics kept in the cache, per key
    obs = sg.rollout(cached, 0)[0][0]["obs"]  # the cached policy acts through them
    normalized = load_normalizer(cached, 0).normalize_obs(obs)
    assert np.array_equal(normalized["view"], obs["view"]) and not np.array_equal(normalized[SPEC_KEY], obs[SPEC_KEY])


def test_the_falsifiers_lockstep_batches_and_the_policy_take_dict_observations():
    from stable_baselines3 import PPO

    beside = spec(observation="features+env", expect={"end": 0.9})
    model = PPO("MultiInputPolicy", beside.make_env(), seed=0, device="cpu")
    space = sg.StartSpace()  # the corridor's state cannot be set: reset seeds

    def outcomes(batch):
        runner = EpisodeRunner(
            beside.make_env, batch_policy(model, None, True), space, property_keys(beside), batch=batch
        )
        assert runner.scales == {
            "x": (LENGTH - 1) / 2
        }  # half the range of the features' scales, read from the "spec" part
        return runner.run(runner.starts.uniform(np.random.default_rng(0), 8))

    together = outcomes(4)
    assert len(together) == 8 and together == outcomes(1)
    env = beside.make_env()
    observations = [env.reset(seed=s)[0] for s in range(5)]
    rows = stack_observations(observations)
    assert rows[SPEC_KEY].shape == (5, 2) and rows["view"].shape == (5, LENGTH) and rows["clock"].shape == (5,)


def test_a_batch_of_dict_observations_has_as_many_rows_as_envs_not_keys():
    from sb3_contrib import RecurrentPPO

    beside = spec(observation="features+env", trainer=sg.SB3(algorithm="RecurrentPPO", hyperparameters=TINY))
    model = RecurrentPPO("MultiInputLstmPolicy", beside.make_env(), seed=0, device="cpu")
    env = beside.make_env()
    observations = [env.reset(seed=s)[0] for s in range(5)]  # five envs, three keys
    together, alone = policy(model, batch=True), [policy(model) for _ in observations]
    for _ in range(3):  # each row carries its own recurrent state from step to step, as each env alone does
        assert list(together(stack_observations(observations))) == [a(o) for a, o in zip(alone, observations)]


def test_show_draws_the_dict_observation():
    text = render_spec(spec(observation="features+env"))
    assert "observation: a Dict; 'spec': 2 components (features, then the own state of nodes and annotations)" in text
    assert (
        "beside it, the initial env's own observation:\n  'clock': Discrete(64)\n  'view': Box(0.0, 1.0, (5,), float32)"
        in text
    )


def test_dataclass_replace_keeps_the_checks():
    with pytest.raises(sg.error.InvalidSpec, match="baseline=True"):
        dataclasses.replace(spec(observation="features+env"), baseline=True)


def test_a_gif_of_a_policy_acting_on_dict_observations(tmp_path):
    from stable_baselines3 import PPO

    from specguard.report.gifs import write_gif

    beside = spec(observation="features+env")
    model = PPO("MultiInputPolicy", beside.make_env(), seed=0, device="cpu", n_steps=32, batch_size=32)
    gif = write_gif(model, beside, tmp_path / "corridor.gif", max_frames=8)
    assert gif.written and gif.frames >= 2, gif.text
