"""An agent trained with wrappers an rl-zoo3 ``config.yml`` names (``frame_stack``, ``env_wrapper``): applied as
SB3's ``VecFrameStack`` and rl-zoo3 apply them, or refused naming them; a mismatch said in one line."""

from __future__ import annotations

import json
import shutil

import gymnasium as gym
import numpy as np
import pytest
import stable_baselines3 as sb3
from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack, VecNormalize

from specguard.agents.agent import check_fits
from specguard.agents.sources import load_agent
from specguard.agents.wrappers import FrameStack
from specguard.cli.main import main
from specguard.engine.check_agent import agent_envs, agent_wrap, check_agent, seed_base
from specguard.error import AgentError, AgentMismatch
from specguard.evaluation.rollout import episode

SPEC_FILE = """
import specguard as sg

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
balance = sg.Spec(
    CARTPOLE,
    sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance"),
    budget=sg.Budget(timesteps=1, eval_episodes=3, max_eval_episodes=3),
    expect=0.5,
)
"""
_FILE: dict = {}
exec(SPEC_FILE, _FILE)  # the spec the command line reads, as Python's doors take it
SPEC = _FILE["balance"]


@pytest.fixture(scope="module")
def stacked(tmp_path_factory):
    """A PPO trained a few hundred steps on CartPole through VecFrameStack(4), saved as an rl-zoo3 run folder."""
    venv = VecFrameStack(DummyVecEnv([lambda: gym.make("CartPole-v1")]), 4)
    model = sb3.PPO("MlpPolicy", venv, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    run = tmp_path_factory.mktemp("zoo") / "ppo" / "CartPole-v1_1"
    (run / "CartPole-v1").mkdir(parents=True)
    model.save(run / "CartPole-v1.zip")
    (run / "CartPole-v1" / "config.yml").write_text("frame_stack: 4\n")
    return model, run


def raw_replay(model, seed, venv=None):
    """One episode of ``model`` as SB3 plays it: ``venv`` (default: VecFrameStack(4) around the env), reset with
    ``seed``."""
    venv = venv or VecFrameStack(DummyVecEnv([lambda: gym.make("CartPole-v1")]), 4)
    venv.seed(seed)
    obs, actions, done = venv.reset(), [], False
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        actions.append(int(action[0]))
        obs, _, dones, _ = venv.step(action)
        done = bool(dones[0])
    return actions


def test_frame_stack_stacks_on_the_last_axis_with_zeros_at_reset_as_vec_frame_stack():
    ours = FrameStack(gym.make("CartPole-v1"), 3)
    theirs = VecFrameStack(DummyVecEnv([lambda: gym.make("CartPole-v1")]), 3)
    theirs.seed(5)
    assert ours.observation_space == theirs.observation_space
    obs, _ = ours.reset(seed=5)
    np.testing.assert_array_equal(obs, theirs.reset()[0])
    assert not obs[:8].any()
    for action in (0, 1, 1, 0):
        obs = ours.step(action)[0]
        np.testing.assert_array_equal(obs, theirs.step(np.array([action]))[0][0])


@pytest.mark.slow
def test_a_frame_stacked_zoo_agent_acts_as_a_raw_replay_with_vec_frame_stack(stacked):
    model, run = stacked
    agent = load_agent(run)
    assert agent.wrappers is not None and agent.wrappers.text == "frame_stack: 4"
    env = agent_envs(SPEC, "env", agent_wrap(agent, None))()
    check_fits(agent, env.observation_space, env.action_space)
    for i in range(3):
        seed = seed_base(0) + i
        ours = [int(step["action"]) for step in episode(env, agent, seed)]
        assert ours == raw_replay(model, seed)


@pytest.mark.slow
def test_check_agent_and_the_cli_judge_a_frame_stacked_zoo_agent(stacked, tmp_path, capsys):
    _, run = stacked
    outcomes: list[dict[str, int]] = []
    result = check_agent(SPEC, run, cache_dir=None, outcomes=outcomes)
    assert any("config.yml's frame_stack: 4" in note for note in result.notes), result.notes
    assert len(outcomes) == 3
    spec_file = tmp_path / "specs.py"
    spec_file.write_text(SPEC_FILE)
    report = tmp_path / "out.json"
    code = main(["check", f"{spec_file}::balance", "--agent", str(run), "--no-cache", "--json", str(report)])
    assert code in (0, 1), capsys.readouterr()
    (judged,) = json.loads(report.read_text()).values()
    assert judged["runs"][0]["successes"] == result.runs[0].successes  # the same episodes, the same actions


@pytest.mark.slow
def test_a_mismatched_observation_is_one_short_line_whose_hint_names_frame_stack_and_wrap(stacked):
    _, run = stacked
    with pytest.raises(AgentMismatch) as e:
        check_agent(SPEC, run, wrap=lambda env: env, cache_dir=None)
    assert e.value.message == (
        "agent 'PPO (CartPole-v1_1/CartPole-v1.zip)' reads observations of Box(shape=(16,), float32), and the env "
        "gives Box(shape=(4,), float32)"
    )
    assert "frame_stack: 4" in e.value.hint and "wrap=" in e.value.hint and "FrameStack(env, 4)" in e.value.hint


@pytest.mark.slow
def test_an_env_wrapper_is_refused_unless_trusted_and_applied_when_trusted(stacked, tmp_path):
    _, source = stacked
    run = tmp_path / "CartPole-v1_2"
    shutil.copytree(source, run)
    (run / "CartPole-v1" / "config.yml").write_text(
        "env_wrapper:\n- gymnasium.wrappers.TimeLimit:\n    max_episode_steps: 5\nframe_stack: 4\n"
    )
    with pytest.raises(AgentError, match=r"trained with env_wrapper gymnasium\.wrappers\.TimeLimit, which specguard"):
        load_agent(run)
    agent = load_agent(run, trust=True)
    assert agent.wrappers.text == "env_wrapper: gymnasium.wrappers.TimeLimit; frame_stack: 4"
    env = agent_envs(SPEC, "env", agent_wrap(agent, None))()
    check_fits(agent, env.observation_space, env.action_space)
    assert len(episode(env, agent, seed_base(0))) <= 5


@pytest.mark.slow
def test_the_cli_takes_the_wrappers_of_a_python_file_for_an_agent_whose_config_names_none(stacked, tmp_path, capsys):
    _, source = stacked
    bare = tmp_path / "model.zip"  # the zip alone: no config.yml says how it was trained
    shutil.copy(source / "CartPole-v1.zip", bare)
    spec_file, wrappers = tmp_path / "specs.py", tmp_path / "wrappers.py"
    spec_file.write_text(SPEC_FILE)
    wrappers.write_text(
        "from specguard.agents.wrappers import FrameStack\n\ndef stacked(env):\n    return FrameStack(env, 4)\n"
    )
    check = ["check", f"{spec_file}::balance", "--agent", str(bare), "--no-cache"]
    assert main(check) == 2
    assert "reads observations of Box(shape=(16,), float32)" in capsys.readouterr().err
    report = tmp_path / "out.json"
    assert main([*check, "--wrap", f"{wrappers}::stacked", "--json", str(report)]) in (0, 1)
    (judged,) = json.loads(report.read_text()).values()
    expected = check_agent(SPEC, source, cache_dir=None)  # its config's frame_stack: 4, the same wrappers
    assert judged["runs"][0]["successes"] == expected.runs[0].successes
    assert main([*check, "--wrap", f"{wrappers}::nothing"]) == 2
    assert f"wrap '{wrappers}::nothing': {wrappers} defines nothing named 'nothing'" in capsys.readouterr().err


@pytest.mark.slow
def test_a_zoo_agent_trained_normalized_then_stacked_normalizes_each_frame_before_the_stack(tmp_path):
    venv = VecNormalize(DummyVecEnv([lambda: gym.make("CartPole-v1")]))  # rl-zoo3: normalize, then stack
    model = sb3.PPO("MlpPolicy", VecFrameStack(venv, 4), n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    run = tmp_path / "ppo" / "CartPole-v1_1"
    (run / "CartPole-v1").mkdir(parents=True)
    model.save(run / "CartPole-v1.zip")
    venv.save(run / "CartPole-v1" / "vecnormalize.pkl")
    (run / "CartPole-v1" / "config.yml").write_text("frame_stack: 4\nnormalize: true\n")
    agent = load_agent(run)
    assert agent.wrappers.text == "frame_stack: 4, each frame normalized first by vecnormalize.pkl"
    env = agent_envs(SPEC, "env", agent_wrap(agent, None))()
    check_fits(agent, env.observation_space, env.action_space)
    saved = VecNormalize.load(run / "CartPole-v1" / "vecnormalize.pkl", DummyVecEnv([lambda: gym.make("CartPole-v1")]))
    saved.training, saved.norm_reward = False, False
    for i in range(2):
        seed = seed_base(0) + i
        actions = raw_replay(model, seed, VecFrameStack(saved, 4))  # as SB3 plays it
        assert [int(step["action"]) for step in episode(env, agent, seed)] == actions
