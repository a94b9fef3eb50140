"""An agent's files are decoded without running the code they may hold (specguard/agents/decode.py), and every
damaged or crafted file is one AgentError naming it: at the Python door, and at the command line's."""

from __future__ import annotations

import base64
import contextlib
import json
import os
import pickle
import shutil
import zipfile

import gymnasium as gym
import numpy as np
import pytest

from specguard.agents.decode import MAX_DATA_BYTES, read_data
from specguard.agents.sources import load_agent
from specguard.error import AgentError

sb3 = pytest.importorskip("stable_baselines3")
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize  # noqa: E402


class _Plant:
    """Unpickled, it makes the folder ``path``: the proof that a file ran code."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (os.mkdir, (self.path,))


@pytest.fixture(scope="module")
def model_zip(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "model.zip"
    sb3.PPO("MlpPolicy", "CartPole-v1", n_steps=64, batch_size=64, seed=0, device="cpu").save(path)
    return path


def _with_data(source, target, change) -> None:
    """A copy of the zip ``source`` at ``target`` whose ``data`` (as JSON text) ``change`` rewrote."""
    with zipfile.ZipFile(source) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    entries["data"] = change(entries["data"].decode()).encode()
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
        for name, content in entries.items():
            z.writestr(name, content)


def _planted(source, target, marker, field="ep_info_buffer") -> None:
    def change(text):
        data = json.loads(text)
        data[field] = {":type:": "<class 'x'>", ":serialized:": base64.b64encode(pickle.dumps(_Plant(str(marker))))}
        data[field][":serialized:"] = data[field][":serialized:"].decode()
        return json.dumps(data)

    _with_data(source, target, change)


def _message(call) -> str:
    with pytest.raises(AgentError) as info:
        call()
    assert "\n" not in info.value.message
    return info.value.message


# -- code in a file runs only when trusted --------------------------------------------------------------------


@pytest.mark.parametrize("field", ["ep_info_buffer", "policy_class", "observation_space"])
def test_a_zip_field_that_would_run_code_is_refused_naming_it_and_runs_only_when_trusted(model_zip, tmp_path, field):
    crafted, marker = tmp_path / "crafted.zip", tmp_path / "ran"
    _planted(model_zip, crafted, marker, field)
    message = _message(lambda: load_agent(crafted))
    assert f"its field {field!r} holds posix.mkdir" in message and "without trust" in message
    assert not marker.exists()
    with pytest.raises(AgentError) as info:
        load_agent(crafted)
    assert "trust=True" in info.value.hint and "--trust-agent" in info.value.hint
    # trusted, the file is unpickled as SB3's load does: its code runs (the marker proves the test can see it)
    with contextlib.suppress(AgentError):  # mkdir's None is no policy class or space: it fails after the code ran
        load_agent(crafted, trust=True)
    assert marker.is_dir()


def test_sb3_s_own_load_unpickles_nothing_when_specguard_decoded_the_fields(model_zip, tmp_path, monkeypatch):
    import cloudpickle

    def refuse(*args, **kwargs):
        raise AssertionError("cloudpickle.loads called")

    monkeypatch.setattr(cloudpickle, "loads", refuse)
    agent = load_agent(model_zip)
    assert agent.algorithm is sb3.PPO and agent(np.zeros(4, dtype=np.float32)) in (0, 1)


@pytest.mark.parametrize("layout", ["beside", "zoo"])
def test_statistics_that_would_run_code_are_refused_and_run_only_when_trusted(model_zip, tmp_path, layout):
    folder = tmp_path / "run"
    settings = folder / "CartPole-v1" if layout == "zoo" else folder
    settings.mkdir(parents=True)
    shutil.copy(model_zip, folder / "CartPole-v1.zip")
    if layout == "zoo":
        (settings / "config.yml").write_text("!!python/object/apply:collections.OrderedDict\n- [[n_envs, 1]]\n")
    marker = tmp_path / "ran"
    (settings / "vecnormalize.pkl").write_bytes(pickle.dumps(_Plant(str(marker))))
    message = _message(lambda: load_agent(folder))
    assert "the VecNormalize statistics file holds posix.mkdir" in message and not marker.exists()
    with pytest.raises(AgentError):
        load_agent(folder, trust=True)  # mkdir's None is no VecNormalize, after it ran
    assert marker.is_dir()


def test_real_statistics_and_every_algorithm_s_fields_decode_without_trust(tmp_path):
    norm = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")]))
    norm.obs_rms.mean = np.array([1.0, 2.0, 3.0])
    (tmp_path / "stats").mkdir()
    norm.save(tmp_path / "stats" / "vecnormalize.pkl")
    for cls in (sb3.SAC, sb3.DQN, sb3.A2C):
        env = "CartPole-v1" if cls in (sb3.DQN, sb3.A2C) else "Pendulum-v1"
        kwargs = {"buffer_size": 100} if cls is not sb3.A2C else {}
        cls("MlpPolicy", env, seed=0, device="cpu", **kwargs).save(tmp_path / "model.zip")
        stats = tmp_path / "stats" / "vecnormalize.pkl" if env == "Pendulum-v1" else None
        agent = load_agent(tmp_path / "model.zip", normalizer=stats)
        assert agent.algorithm is cls
        if stats is not None:
            assert agent.normalizer.obs_rms.mean.tolist() == [1.0, 2.0, 3.0]


def test_the_cli_refuses_a_crafted_agent_with_exit_2_and_trusts_it_with_trust_agent(model_zip, tmp_path, capsys):
    from specguard.cli.main import main

    spec_file = tmp_path / "specs.py"
    spec_file.write_text(
        "import specguard as sg\n"
        "cartpole = sg.InitialEnv('CartPole-v1', features=('x', 'v', 'theta', 'omega'))\n"
        "up = sg.Spec(cartpole, sg.Goal('upright', theta=(-0.2, 0.2)), expect={'upright': 0.5},\n"
        "    budget=sg.Budget(timesteps=1, eval_episodes=2, max_eval_episodes=2))\n"
    )
    crafted, marker = tmp_path / "crafted.zip", tmp_path / "ran"
    _planted(model_zip, crafted, marker)
    assert main(["check", str(spec_file), "--agent", str(crafted), "--no-cache"]) == 2
    err = capsys.readouterr().err
    assert "its field 'ep_info_buffer' holds posix.mkdir" in err and "--trust-agent" in err and not marker.exists()
    main(["check", str(spec_file), "--agent", str(crafted), "--no-cache", "--trust-agent"])
    assert marker.is_dir()


# -- damaged and crafted data, one line each -----------------------------------------------------------------


def _nested(depth: int) -> str:
    return "[" * depth + "]" * depth


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("[]", "its data is a list, not a mapping"),
        ("null", "its data is a null, not a mapping"),
        ("{not json", "JSONDecodeError"),
        (_nested(100_000), "nested too deeply"),
        ('{"policy_class": {":serialized:": "not base64!"}}', "its field 'policy_class' is not base64"),
        ('{"policy_class": {":serialized:": "bm90IGEgcGlja2xl"}}', "its field 'policy_class': cannot be decoded"),
    ],
)
def test_damaged_data_is_one_line(model_zip, tmp_path, text, says):
    crafted = tmp_path / "crafted.zip"
    _with_data(model_zip, crafted, lambda _: text)
    message = _message(lambda: load_agent(crafted))
    assert message.startswith(f"{str(crafted)!r}: ") and says in message


def test_a_pickle_that_raises_while_it_is_rebuilt_is_one_line(model_zip, tmp_path):
    blob = pickle.dumps(gym.spaces.Discrete(2))
    broken = blob.replace(b"Discrete", b"Discrett")  # a class the module lacks
    crafted = tmp_path / "crafted.zip"

    def change(text):
        data = json.loads(text)
        data["action_space"] = {":serialized:": base64.b64encode(broken).decode()}
        return json.dumps(data)

    _with_data(model_zip, crafted, change)
    message = _message(lambda: load_agent(crafted))
    assert "its field 'action_space' holds gymnasium.spaces.discrete.Discrett" in message


def test_data_that_inflates_past_the_limit_is_refused_before_it_is_read(model_zip, tmp_path):
    crafted = tmp_path / "bomb.zip"
    with zipfile.ZipFile(crafted, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("data", b" " * (MAX_DATA_BYTES + 1))
    assert crafted.stat().st_size < MAX_DATA_BYTES // 100
    message = _message(lambda: load_agent(crafted))
    assert f"its 'data' inflates to {MAX_DATA_BYTES + 1:,} bytes" in message


@pytest.mark.parametrize("damage", ["encrypted", "unknown compression"])
def test_an_entry_zipfile_cannot_read_is_one_line(model_zip, tmp_path, damage):
    crafted = tmp_path / "crafted.zip"
    shutil.copy(model_zip, crafted)
    raw = bytearray(crafted.read_bytes())
    # every header of 'data' (the local one and the central directory's): the encrypted flag, or method 99
    for signature, flags_at, method_at in ((b"PK\x03\x04", 6, 8), (b"PK\x01\x02", 8, 10)):
        at = raw.find(signature)
        while at >= 0:
            name_at = at + (30 if signature == b"PK\x03\x04" else 46)
            if raw[name_at : name_at + 4] == b"data":
                if damage == "encrypted":
                    raw[at + flags_at] |= 0x1
                else:
                    raw[at + method_at : at + method_at + 2] = (99).to_bytes(2, "little")
            at = raw.find(signature, at + 4)
    crafted.write_bytes(bytes(raw))
    message = _message(lambda: load_agent(crafted))
    assert message.startswith(f"{str(crafted)!r}: not a stable-baselines3 model (")


def test_read_data_with_trust_unpickles_as_sb3_does(model_zip):
    data, custom = read_data(model_zip, trust=True, replace={})
    assert custom == {} and isinstance(data["observation_space"], gym.spaces.Box)
    data, custom = read_data(model_zip, trust=False, replace={"lr_schedule": 0.0})
    assert custom["lr_schedule"] == 0.0 and custom["observation_space"] is data["observation_space"]


# -- a run's own files, never a sibling run's -------------------------------------------------------------------


def _saved_stats(path, shift: float) -> VecNormalize:
    norm = VecNormalize(DummyVecEnv([lambda: gym.make("CartPole-v1")]))
    norm.obs_rms.mean = np.full(4, shift)
    norm.obs_rms.var = np.full(4, 0.25)
    path.parent.mkdir(parents=True, exist_ok=True)
    norm.save(path)
    return norm


def test_a_zip_with_its_own_statistics_ignores_a_sibling_run_s_settings_and_statistics(model_zip, tmp_path):
    runs = tmp_path / "runs"
    runs.mkdir()
    shutil.copy(model_zip, runs / "model.zip")
    own = _saved_stats(runs / "vecnormalize.pkl", shift=0.5)
    _saved_stats(runs / "other" / "vecnormalize.pkl", shift=-3.0)
    (runs / "other" / "config.yml").write_text("!!python/object/apply:collections.OrderedDict\n- [[n_envs, 8]]\n")
    (runs / "other" / "env_kwargs.yml").write_text("sutton_barto_reward: true\n")
    agent = load_agent(runs / "model.zip")
    assert agent.normalizer.obs_rms.mean.tolist() == [0.5] * 4
    assert agent.config == {} and agent.env_kwargs == {}
    # a raw replay: the model's own predict on its own statistics' observations gives the agent's actions
    model = sb3.PPO.load(runs / "model.zip", device="cpu")
    rng = np.random.default_rng(0)
    observations = rng.normal(0.0, 1.0, (40, 4)).astype(np.float32)
    agent.start([None])
    acted = [int(agent(obs)) for obs in observations]
    raw = [int(model.predict(own.normalize_obs(obs), deterministic=True)[0]) for obs in observations]
    assert acted == raw


def test_an_rl_zoo_run_s_best_model_still_takes_its_run_s_settings(model_zip, tmp_path):
    run = tmp_path / "ppo" / "CartPole-v1_1"
    run.mkdir(parents=True)
    shutil.copy(model_zip, run / "CartPole-v1.zip")
    shutil.copy(model_zip, run / "best_model.zip")
    _saved_stats(run / "CartPole-v1" / "vecnormalize.pkl", shift=2.0)
    (run / "CartPole-v1" / "config.yml").write_text("!!python/object/apply:collections.OrderedDict\n- [[n_envs, 8]]\n")
    for path in (run, run / "best_model.zip"):
        agent = load_agent(path)
        assert agent.normalizer.obs_rms.mean.tolist() == [2.0] * 4 and agent.config == {"n_envs": 8}


def test_a_named_pipe_called_zip_is_refused_or_skipped_without_blocking(model_zip, tmp_path):
    pipe = tmp_path / "model.zip"
    os.mkfifo(pipe)
    assert _message(lambda: load_agent(pipe)) == f"{str(pipe)!r}: not a regular file or a folder"
    shutil.copy(model_zip, tmp_path / "real.zip")
    assert load_agent(tmp_path).path == tmp_path / "real.zip"  # the pipe beside it is no model
