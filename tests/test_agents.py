"""Agents trained elsewhere (specguard/agents/): each source loaded as one policy, each bad input one AgentError."""

from __future__ import annotations

import collections
import shutil
import warnings
import zipfile

import gymnasium as gym
import numpy as np
import pytest
import torch

from specguard.agents.agent import Agent, check_fits
from specguard.agents.sources import load_agent
from specguard.error import AgentError, AgentMismatch, SpecWarning

yaml = pytest.importorskip("yaml")
sb3 = pytest.importorskip("stable_baselines3")
contrib = pytest.importorskip("sb3_contrib")
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize  # noqa: E402

CARTPOLE = gym.make("CartPole-v1")


def _observations(n: int = 40, seed: int = 0) -> list[np.ndarray]:
    env = gym.make("CartPole-v1")
    obs, _ = env.reset(seed=seed)
    out, rng = [], np.random.default_rng(seed)
    for _ in range(n):
        out.append(obs)
        obs, _, terminated, truncated, _ = env.step(int(rng.integers(2)))
        if terminated or truncated:
            obs, _ = env.reset()
    return out


def _model(name: str):
    """A tiny model of ``name`` on CartPole: PPO trained 64 steps, the others as built (acting needs no training)."""
    if name == "PPO":
        model = sb3.PPO("MlpPolicy", "CartPole-v1", n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
        return model.learn(64)
    cls = getattr(sb3, name, None) or getattr(contrib, name)
    if name != "RecurrentPPO":
        return cls("MlpPolicy", "CartPole-v1", seed=0, device="cpu")
    model = cls("MlpLstmPolicy", "CartPole-v1", seed=0, device="cpu")
    with torch.no_grad():  # weights 20 times their initial size: its actions follow its state, as a trained one's
        for parameter in model.policy.parameters():
            parameter.mul_(20)
    return model


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """Per algorithm, its model and the path it was saved at, in a folder whose name says nothing of it."""
    root = tmp_path_factory.mktemp("models")
    out = {}
    for i, name in enumerate(["PPO", "A2C", "DQN", "QRDQN", "RecurrentPPO"]):
        model = _model(name)
        path = root / f"run{i}" / "model.zip"
        path.parent.mkdir()
        model.save(path)
        out[name] = (model, path)
    return out


def _stats(path, shift: float = 3.0, env_id: str = "CartPole-v1") -> VecNormalize:
    """``VecNormalize`` statistics saved at ``path``, far from the raw observations (so normalizing shows)."""
    norm = VecNormalize(DummyVecEnv([lambda: gym.make(env_id)]))
    size = norm.observation_space.shape[0]
    norm.obs_rms.mean = np.full(size, shift)
    norm.obs_rms.var = np.full(size, 0.25)
    norm.save(path)
    return norm


# -- each source acts as its model ---------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("name", ["PPO", "A2C", "DQN", "QRDQN"])
def test_a_zip_acts_as_its_model_predicts(saved, name):
    model, path = saved[name]
    agent = load_agent(path)
    assert agent.algorithm is type(model) and agent.name == f"{name} (model.zip)"
    check_fits(agent, CARTPOLE.observation_space, CARTPOLE.action_space)
    agent.start([CARTPOLE])
    for obs in _observations():
        assert agent(obs) == int(model.predict(obs, deterministic=True)[0])


@pytest.mark.slow
def test_a_vecnormalize_beside_the_zip_normalizes_every_observation(saved, tmp_path):
    model, path = saved["PPO"]
    shutil.copy(path, tmp_path / "model.zip")
    norm = _stats(tmp_path / "vecnormalize.pkl")
    agent = load_agent(tmp_path / "model.zip")
    assert agent.normalizer is not None
    observations = _observations()
    expected = [int(model.predict(norm.normalize_obs(o), deterministic=True)[0]) for o in observations]
    raw = [int(model.predict(o, deterministic=True)[0]) for o in observations]
    assert expected != raw, "the statistics change no action: the test would not see them ignored"
    assert [agent(o) for o in observations] == expected


@pytest.mark.slow
def test_an_rl_zoo_run_folder_loads_its_final_model_statistics_and_settings(saved, tmp_path):
    model, path = saved["PPO"]
    run = tmp_path / "logs" / "ppo" / "CartPole-v1_1"
    (run / "CartPole-v1").mkdir(parents=True)
    shutil.copy(path, run / "CartPole-v1.zip")
    shutil.copy(saved["A2C"][1], run / "best_model.zip")
    norm = _stats(run / "CartPole-v1" / "vecnormalize.pkl")
    config = collections.OrderedDict([("n_envs", 1), ("normalize", True), ("env_kwargs", {"render_mode": None})])
    (run / "CartPole-v1" / "config.yml").write_text(yaml.dump(config))
    args = collections.OrderedDict(
        [("algo", "ppo"), ("env", "CartPole-v1"), ("env_kwargs", {"sutton_barto_reward": True})]
    )
    (run / "CartPole-v1" / "args.yml").write_text(yaml.dump(args))
    agent = load_agent(run)
    assert agent.path == run / "CartPole-v1.zip" and agent.name == "PPO (CartPole-v1_1/CartPole-v1.zip)"
    assert agent.config == dict(config) and agent.env_kwargs == {"sutton_barto_reward": True}
    assert agent.env_id == "CartPole-v1" and agent.batched().env_id == "CartPole-v1"
    obs = _observations()[5]
    assert agent(obs) == int(model.predict(norm.normalize_obs(obs), deterministic=True)[0])


@pytest.mark.slow
def test_a_hub_folder_loads_its_model_beside_other_zips(saved, tmp_path):
    shutil.copy(saved["DQN"][1], tmp_path / "dqn-CartPole-v1.zip")
    with zipfile.ZipFile(tmp_path / "train_eval_metrics.zip", "w") as z:
        z.writestr("evaluations.npz", b"")
    _stats(tmp_path / "vec_normalize.pkl")
    (tmp_path / "config.yml").write_text(yaml.dump(collections.OrderedDict([("batch_size", 64)])))
    (tmp_path / "env_kwargs.yml").write_text(yaml.dump({"sutton_barto_reward": False}))
    agent = load_agent(str(tmp_path))
    assert agent.algorithm is sb3.DQN and agent.normalizer is not None
    assert agent.config == {"batch_size": 64} and agent.env_kwargs == {"sutton_barto_reward": False}


@pytest.mark.slow
@pytest.mark.parametrize("source", ["zip", "memory"])
def test_a_recurrent_agent_carries_its_state_from_step_to_step(saved, source):
    model, path = saved["RecurrentPPO"]
    agent = load_agent(path if source == "zip" else model)
    agent.start([CARTPOLE])
    state, start = None, np.ones(1, dtype=bool)
    observations = _observations(20)
    for obs in observations:
        action, state = model.predict(obs, state=state, episode_start=start, deterministic=True)
        start = np.zeros(1, dtype=bool)
        assert agent(obs) == int(action)
    agent.start([CARTPOLE])  # a new episode: its state starts afresh
    state, start = None, np.ones(1, dtype=bool)
    for obs in observations[::-1]:
        action, state = model.predict(obs, state=state, episode_start=start, deterministic=True)
        start = np.zeros(1, dtype=bool)
        assert agent(obs) == int(action)
    stateless = [
        int(model.predict(o, episode_start=np.ones(1, dtype=bool), deterministic=True)[0]) for o in observations
    ]
    assert stateless != [agent(o) for o in observations], "its state changes no action: the test could not see it lost"


@pytest.mark.slow
def test_a_batch_of_rows_acts_row_by_row(saved):
    model, path = saved["PPO"]
    agent = load_agent(path).batched()
    batch = np.stack(_observations(8))
    agent.start([CARTPOLE] * len(batch))
    assert agent(batch).tolist() == model.predict(batch, deterministic=True)[0].tolist()
    rule = load_agent(lambda obs: int(obs[2] > 0), batch=True)
    assert rule(batch).tolist() == [int(o[2] > 0) for o in batch]


def test_a_predict_object_of_another_library_has_its_actions_checked():
    class Onnx:
        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return np.array(7), state

    agent = load_agent(Onnx())
    check_fits(agent, CARTPOLE.observation_space, CARTPOLE.action_space)
    agent.start([CARTPOLE])
    with pytest.raises(AgentError, match=r"agent 'Onnx' gave the action array\(7\) \(outside the space\)"):
        agent(_observations(1)[0])


# -- a callable -------------------------------------------------------------------------------------------------


def lean(obs):
    return int(obs[2] > 0)


def test_a_callable_acts_and_its_identity_is_its_code():
    agent = load_agent(lean)
    check_fits(agent, CARTPOLE.observation_space, CARTPOLE.action_space)
    agent.start([CARTPOLE])
    assert [agent(o) for o in _observations()] == [lean(o) for o in _observations()]
    assert agent.name == "lean" and agent.observation_space is None
    assert load_agent(lean).identity == agent.identity
    assert load_agent(lambda obs: 0).identity != load_agent(lambda obs: 1).identity


@pytest.mark.slow
def test_identities_tell_files_statistics_and_parameters_apart(saved, tmp_path):
    _, path = saved["PPO"]
    shutil.copy(path, tmp_path / "model.zip")
    bare = load_agent(tmp_path / "model.zip").identity
    assert load_agent(tmp_path / "model.zip").identity == bare
    assert load_agent(tmp_path / "model.zip", deterministic=False).identity != bare
    _stats(tmp_path / "vecnormalize.pkl")
    assert load_agent(tmp_path / "model.zip").identity != bare
    assert load_agent(saved["PPO"][0]).identity != load_agent(saved["A2C"][0]).identity


def test_a_callable_that_raises_is_named_with_its_exception_chained():
    def broken(obs):
        raise KeyError("velocity")

    agent = load_agent(broken)
    with pytest.raises(AgentError, match=r"^agent 'broken' raised KeyError: 'velocity'\n") as info:
        agent(_observations(1)[0])
    assert isinstance(info.value.__cause__, KeyError)


@pytest.mark.parametrize(
    ("space", "action", "problem"),
    [
        (gym.spaces.Discrete(2), 0.5, "a float64, not an integer"),
        (gym.spaces.Discrete(2), 2, "outside the space"),
        (gym.spaces.Discrete(2), [1], r"shape \(1,\), not \(\)"),
        (gym.spaces.Box(-1, 1, (2,)), [0.5], r"shape \(1,\), not \(2,\)"),
        (gym.spaces.Box(-1, 1, (2,)), ["a", "b"], "a <U1, not a number"),
    ],
)
def test_an_action_of_the_wrong_type_or_shape_is_refused_at_the_first_step(space, action, problem):
    agent = load_agent(lambda obs: action)
    check_fits(agent, CARTPOLE.observation_space, space)
    agent.start([None])
    with pytest.raises(AgentError, match=rf"agent '<lambda>' gave the action .* \({problem}\), which is not one of"):
        agent(np.zeros(4))


def test_a_box_action_outside_its_bounds_is_clipped_as_sb3_s_predict_clips_and_warned_once():
    agent = load_agent(lambda obs: np.array([3.0, -0.5]) * (1 + obs[0]))
    check_fits(agent, CARTPOLE.observation_space, gym.spaces.Box(-1, 1, (2,)))
    agent.start([None])
    with pytest.warns(SpecWarning, match=r"agent '<lambda>' gave the action .* outside Box.*clipped to the bounds"):
        assert agent(np.zeros(4)).tolist() == [1.0, -0.5]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # once per agent
        assert agent(np.ones(4)).tolist() == [1.0, -1.0]  # every action, not only the first


@pytest.mark.parametrize("late", [np.array([np.nan, 0.0]), np.array([0.5])])
def test_a_bad_action_after_the_first_step_names_the_agent(late):
    actions = iter([np.array([0.5, 0.5]), late])
    agent = load_agent(lambda obs: next(actions))
    check_fits(agent, CARTPOLE.observation_space, gym.spaces.Box(-1, 1, (2,)))
    agent.start([None])
    agent(np.zeros(4))
    with pytest.raises(AgentError, match=r"agent '<lambda>' gave the action .*which is not one of Box"):
        agent(np.zeros(4))


def test_a_policy_that_calls_sys_exit_is_the_agent_s_failure_not_the_end_of_the_process():
    import sys

    agent = load_agent(lambda obs: sys.exit(0))
    agent.start([None])
    with pytest.raises(AgentError, match=r"agent '<lambda>' called sys.exit\(0\) while acting"):
        agent(np.zeros(4))


# -- bad input, one line each -------------------------------------------------------------------------------------


def _message(call) -> str:
    with pytest.raises(AgentError) as info:
        call()
    return info.value.message


def test_a_path_that_does_not_exist(tmp_path):
    assert (
        _message(lambda: load_agent(tmp_path / "nope.zip")) == f"{str(tmp_path / 'nope.zip')!r}: no such file or folder"
    )
    with pytest.raises(AgentError) as info:
        load_agent("sb3/ppo-CartPole-v1")
    assert info.value.message == "'sb3/ppo-CartPole-v1': no such file or folder"
    assert "Hugging Face Hub repo id? specguard downloads nothing" in info.value.hint


@pytest.mark.slow
def test_a_folder_without_a_model_and_one_with_two(saved, tmp_path):
    (tmp_path / "notes.txt").write_text("")
    assert "holds no stable-baselines3 model" in _message(lambda: load_agent(tmp_path))
    shutil.copy(saved["PPO"][1], tmp_path / "a.zip")
    shutil.copy(saved["A2C"][1], tmp_path / "b.zip")
    assert "holds 2 models (a.zip, b.zip)" in _message(lambda: load_agent(tmp_path))


@pytest.mark.parametrize("content", ["plain text", "zip without data"])
def test_a_file_that_is_not_an_sb3_model(tmp_path, content):
    path = tmp_path / "model.zip"
    if content == "plain text":
        path.write_text("not a zip")
    else:
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("weights.bin", b"\0")
    message = _message(lambda: load_agent(path))
    assert message.startswith(f"{str(path)!r}: not a stable-baselines3 model (") and "\n" not in message


@pytest.mark.slow
def test_an_algorithm_that_does_not_match_the_zip(saved):
    path = saved["PPO"][1]
    assert (
        _message(lambda: load_agent(path, algorithm="DQN"))
        == f"{str(path)!r}: saved by PPO, not by DQN (algorithm='DQN')"
    )
    assert "saved by PPO, not by A2C" in _message(lambda: load_agent(path, algorithm="A2C"))
    assert load_agent(path, algorithm="PPO").algorithm is sb3.PPO


@pytest.mark.slow
def test_statistics_of_another_observation_shape(saved, tmp_path):
    shutil.copy(saved["PPO"][1], tmp_path / "model.zip")
    _stats(tmp_path / "vecnormalize.pkl", env_id="Pendulum-v1")
    message = _message(lambda: load_agent(tmp_path / "model.zip"))
    assert message.startswith(f"{str(tmp_path / 'vecnormalize.pkl')!r}: VecNormalize statistics of observations Box(")
    assert "(3,)" in message and "(4,)" in message


@pytest.mark.slow
def test_check_fits_refuses_another_env_s_spaces_naming_both(saved):
    agent = load_agent(saved["PPO"][1])
    pendulum = gym.make("Pendulum-v1")
    with pytest.raises(AgentMismatch, match=r"reads observations of Box\(.*\(4,\).*and the env gives Box\(.*\(3,\)"):
        check_fits(agent, pendulum.observation_space, CARTPOLE.action_space)
    with pytest.raises(AgentMismatch, match=r"acts in Discrete\(2\), and the env takes Discrete\(3\)"):
        check_fits(agent, CARTPOLE.observation_space, gym.spaces.Discrete(3))


def test_something_that_is_no_agent():
    assert _message(lambda: load_agent(42)) == "cannot load an agent from 42 (a int)"
    assert "names a saved zip's algorithm" in _message(lambda: load_agent(lean, algorithm="PPO"))


def test_an_agent_is_an_episode_policy():
    from specguard.construction.episode_policy import EpisodePolicy

    assert isinstance(load_agent(lean), (Agent, EpisodePolicy))
    assert isinstance(load_agent(lean), EpisodePolicy)


def test_a_policy_defined_in_a_python_file_is_named_file_colon_colon_name(tmp_path):
    policies = tmp_path / "policies.py"
    policies.write_text("def lean(obs):\n    return int(obs[2] > 0)\n\nEPSILON = 0.1\n")
    agent = load_agent(f"{policies}::lean")
    assert agent.name == "lean" and agent(np.array([0.0, 0.0, 0.1, 0.0])) == 1
    assert len(agent.identity) == 64
    for target, culprit in [
        (f"{policies}::absent", "defines nothing named 'absent'; its callables: lean"),
        (f"{tmp_path / 'none.py'}::lean", "no such file"),
    ]:
        with pytest.raises(AgentError, match="^agent .*" + culprit):
            load_agent(target)


class _Actor(torch.nn.Module):
    """A CleanRL- or TorchRL-style actor: a network on the observation tensor, its output as ``form`` says."""

    def __init__(self, form: str) -> None:
        super().__init__()
        self.net, self.form = torch.nn.Linear(4, 2), form

    def forward(self, obs):
        out = torch.tanh(self.net(obs))  # requires grad unless asked without
        if self.form == "tuple":
            return out, out.sum()  # TorchRL's out_keys: (action, log_prob)
        return {"action": out, "log_prob": out.sum()} if self.form == "mapping" else out


@pytest.mark.parametrize("form", ["tensor", "tuple", "mapping"])
def test_a_torch_actor_acts_without_gradients_and_its_action_is_taken_from_its_output(form):
    actor = _Actor(form)
    agent = load_agent(actor)
    check_fits(agent, CARTPOLE.observation_space, gym.spaces.Box(-1, 1, (2,)))
    agent.start([None])
    obs = _observations()[3]
    with torch.no_grad():
        expected = torch.tanh(actor.net(torch.as_tensor(obs))).numpy()
    assert np.allclose(agent(obs), expected)


def test_a_file_colon_colon_name_that_names_another_name_is_refused_not_followed(tmp_path):
    policies = tmp_path / "policies.py"
    policies.write_text(f"me = {str(policies) + '::me'!r}\n")
    message = _message(lambda: load_agent(f"{policies}::me"))
    assert (
        message == f"agent {str(policies) + '::me'!r}: me is the text {str(policies) + '::me'!r}, another FILE.py::NAME"
    )


def test_an_action_numpy_cannot_read_is_refused_in_torch_s_own_words():
    grad = torch.zeros(2, requires_grad=True) * 1.0
    agent = load_agent(lambda obs: [grad, grad.sum()])  # a list, not a tuple: not taken apart for it
    check_fits(agent, CARTPOLE.observation_space, gym.spaces.Box(-1, 1, (2,)))
    agent.start([None])
    with pytest.raises(AgentError, match=r"numpy cannot read it: RuntimeError: .*requires grad"):
        agent(np.zeros(4))
    pair = load_agent(lambda obs: [np.zeros(2), np.zeros(3)])
    check_fits(pair, CARTPOLE.observation_space, gym.spaces.Box(-1, 1, (2,)))
    pair.start([None])
    with pytest.raises(AgentError, match=r"numpy cannot read it: ValueError: .*; a list of 2 values: give the action"):
        pair(np.zeros(4))
