"""rl-zoo3's tuned settings as a spec's fields: the real files read, mapped, refused where unsafe, trained and cached.

rl_zoo3 itself is never imported here (its import patches Gymnasium's TimeLimit for the whole process): the tests
read its files as specguard does.
"""

from __future__ import annotations

import dataclasses
import pickle
import textwrap
import warnings

import pytest
import yaml
from stable_baselines3.common.callbacks import CheckpointCallback, ProgressBarCallback
from torch import nn

import specguard as sg
from specguard.cache.canonical import digest
from specguard.cache.fingerprint import fingerprint_spec
from specguard.spec.zoo import ZOO_FILES, LinearSchedule, ZooSettings, _zoo_file

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
UPRIGHT = sg.Goal("right", x=(0.3, None))  # starts lie near x = 0


def zoo(algorithm, env_id, **kwargs):
    """zoo_settings, with the warnings it gives (never left to escape into the session)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        settings = sg.zoo_settings(algorithm, env_id, **kwargs)
    return settings, [str(w.message) for w in caught if issubclass(w.category, sg.error.SpecWarning)]


def write(tmp_path, text):
    path = tmp_path / "mine.yml"
    path.write_text(textwrap.dedent(text))
    return path


# -- the real files -----------------------------------------------------------------------------------


def test_cartpole_ppo_is_the_zoos_entry_with_its_schedules():
    settings, warned = zoo("PPO", "CartPole-v1")
    assert warned == []
    assert dict(settings) == {
        "trainer": sg.SB3(
            algorithm="PPO",
            policy="MlpPolicy",
            hyperparameters={
                "n_steps": 32,
                "batch_size": 256,
                "gae_lambda": 0.8,
                "gamma": 0.98,
                "n_epochs": 20,
                "ent_coef": 0.0,
                "learning_rate": LinearSchedule(0.001),
                "clip_range": LinearSchedule(0.2),
            },
            n_envs=8,
            normalize=False,
            callbacks=(),
        ),
        "observation": "features",
    }
    assert settings.timesteps == 100_000 and type(settings.timesteps) is int
    assert settings.env_id == "CartPole-v1" and settings.not_taken == {}
    assert settings.source.startswith("rl-zoo3 ") and settings.source.endswith(", ppo.yml")


def test_policy_kwargs_are_evaluated_with_torch_nn_classes():
    settings, _ = zoo("RecurrentPPO", "CartPoleNoVel-v1")
    assert settings.trainer.policy == "MlpLstmPolicy"
    assert settings.trainer.hyperparameters["policy_kwargs"] == {
        "ortho_init": False,
        "activation_fn": nn.ReLU,
        "lstm_hidden_size": 64,
        "enable_critic_lstm": True,
        "net_arch": {"pi": [64], "vf": [64]},
    }


def test_what_a_spec_cannot_say_is_warned_and_kept():
    settings, warned = zoo("TD3", "Pendulum-v1")
    assert set(settings.not_taken) == {"noise_type", "noise_std"}
    assert "noise_type" not in settings.trainer.hyperparameters and settings.trainer.hyperparameters["gamma"] == 0.98
    [message] = warned
    assert "zoo_settings('TD3', 'Pendulum-v1')" in message and "not taken" in message
    assert "noise_type: 'normal'" in message and "noise_std: 0.1" in message

    settings, warned = zoo("PPO", "MountainCarContinuous-v0")  # normalize: true with gamma 0.9999
    assert settings.trainer.normalize is True
    assert settings.not_taken["normalize"].startswith("gamma=0.9999: a spec's normalize=True is VecNormalize")
    assert len(warned) == 1 and "normalize: gamma=0.9999" in warned[0]


def test_every_entry_of_the_zoos_files_maps_onto_a_spec():
    """Each entry of each file maps, and a spec takes its fields; the refusals are a policy the algorithm lacks, and
    an image policy (the zoo's Atari entries), which the features of CartPole are not."""
    mapped = refused = images = 0
    for algorithm, stem in ZOO_FILES.items():
        path, _ = _zoo_file("test", stem)
        for env_id in yaml.safe_load(path.read_text()):
            try:
                settings, _ = zoo(algorithm, env_id)
            except sg.error.InvalidSpec as e:
                assert ".policy: expected policy to be one of" in str(e), (algorithm, env_id, str(e))
                refused += 1
                continue
            try:
                sg.Spec(CARTPOLE, UPRIGHT, budget=sg.Budget(timesteps=settings.timesteps), **settings)
            except sg.error.InvalidSpec as e:
                assert str(settings.trainer.policy).startswith("Cnn") and "not an image" in str(e), (algorithm, env_id)
                images += 1
                continue
            mapped += 1
    assert mapped > 200 and refused <= 2 and images >= 1


def test_the_atari_entry_on_a_spec_of_numbers_is_refused_naming_the_policy():
    settings, _ = zoo("PPO", "atari")
    with pytest.raises(sg.error.InvalidSpec) as e:
        sg.Spec(CARTPOLE, UPRIGHT, budget=sg.Budget(timesteps=1000), **settings)
    assert e.value.where == "Spec 'right'.trainer.policy"
    assert "which 'CnnPolicy' does not take; one that does: MlpPolicy" in e.value.message


def test_an_entry_whose_policy_takes_a_dict_lets_the_agent_see_the_envs_own_observation():
    # The zoo trained FetchReach on a Dict observation (MultiInputPolicy): a spec gives its agent the env's own
    # observation beside the features (observation="features+env"), which that policy takes.
    settings, _ = zoo("SAC", "FetchReach-v1")
    assert settings.trainer.policy == "MultiInputPolicy" and settings["observation"] == "features+env"
    spec = sg.Spec(CARTPOLE, UPRIGHT, budget=sg.Budget(timesteps=1000), **settings)
    assert spec.observation == "features+env" and spec.trainer.policy == "MultiInputPolicy"


# -- refusals -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("algorithm", "env_id", "message"),
    [
        ("PPO", "CartPole-v0", r"ppo.yml has no entry for 'CartPole-v0'; did you mean 'CartPole-v1'\?.*'default'"),
        ("MaskablePPO", "CartPole-v1", r"rl-zoo3 has no settings for MaskablePPO; it has files for PPO, A2C, "),
        ("PPO2", "CartPole-v1", r"unknown algorithm 'PPO2'"),
        ("PPO", "", r"expected env_id to be a non-empty string, got ''"),
    ],
)
def test_a_name_the_zoo_lacks_is_one_line(algorithm, env_id, message):
    with pytest.raises(sg.error.InvalidSpec, match=message) as e:
        sg.zoo_settings(algorithm, env_id)
    assert "\n" not in e.value.message


def test_the_default_entry_is_asked_for_by_name():
    settings, _ = zoo("PPO", "default")
    assert settings.trainer.hyperparameters == {} and settings.timesteps == 1_000_000


@pytest.mark.parametrize(
    "text",
    [
        "__import__('os').system('true')",
        "dict(activation_fn=nn.functional.relu)",
        "dict(activation_fn=nn.init)",
        "dict(activation_fn=Tanh)",
        "exec",
        "dict(optimizer_class=th.optim.Adam)",
        "dict(**other)",
        "dict(f=lambda x: x)",
        "open('x')",
        "[x for x in ()]",
    ],
)
def test_policy_kwargs_outside_the_closed_scope_are_refused(tmp_path, text):
    path = write(tmp_path, f'CartPole-v1:\n  n_timesteps: 1000\n  policy_kwargs: "{text}"\n')
    with pytest.raises(sg.error.InvalidSpec, match=r"policy_kwargs.*(cannot evaluate|is not a torch.nn module class)"):
        sg.zoo_settings("PPO", "CartPole-v1", file=path)


def test_without_sb3_contrib_its_algorithms_say_what_to_install(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "sb3_contrib", None)  # import sb3_contrib raises ImportError
    with pytest.raises(
        sg.error.InvalidSpec, match=r"^zoo_settings\('TQC', 'Pendulum-v1'\): TQC is an sb3-contrib algorithm"
    ):
        sg.zoo_settings("TQC", "Pendulum-v1")


def test_without_rl_zoo3_it_says_what_to_install(monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "rl_zoo3" else real(name, *a))
    with pytest.raises(sg.error.InvalidSpec, match="rl-zoo3 is not installed") as e:
        sg.zoo_settings("PPO", "CartPole-v1")
    assert e.value.hint == "pip install 'specguard[zoo]'"


# -- a file of one's own, in the zoo's format ----------------------------------------------------------------


def test_a_file_of_ones_own_with_every_kind_of_key(tmp_path):
    path = write(
        tmp_path,
        """
        MyEnv-v0:
          n_timesteps: !!float 2e4
          n_envs: 2
          policy: MlpPolicy
          normalize: "dict(norm_obs=True, norm_reward=False, gamma=0.9)"
          env_wrapper: gymnasium.wrappers.TimeAwareObservation
          frame_stack: 4
          callback:
            - stable_baselines3.common.callbacks.ProgressBarCallback
            - stable_baselines3.common.callbacks.CheckpointCallback:
                save_freq: 100
                save_path: checkpoints
            - no_such_module.Callback
            - gymnasium.Env
          no_such_key: 1
          learning_rate: lin_7.3e-4
          clip_range_vf: -1
          policy_kwargs: "dict(net_arch=[8, 8], activation_fn=nn.Tanh, optimizer_class=RMSpropTFLike)"
        """,
    )
    settings, [message] = zoo("A2C", "MyEnv-v0", file=path)
    assert settings.timesteps == 20_000 and settings.trainer.n_envs == 2 and settings.trainer.normalize is True
    assert settings.trainer.hyperparameters["learning_rate"] == LinearSchedule(7.3e-4)
    assert settings.trainer.hyperparameters["policy_kwargs"]["activation_fn"] is nn.Tanh
    assert set(settings.not_taken) == {
        "normalize",
        "env_wrapper",
        "frame_stack",
        "callback[2]",
        "callback[3]",
        "no_such_key",
        "clip_range_vf",
    }
    assert settings.not_taken["normalize"].startswith("norm_reward=False: ")  # no gamma: rewards are not normalized
    assert "A2C's constructor takes no 'no_such_key'" in settings.not_taken["no_such_key"]
    assert "cannot import it (ModuleNotFoundError" in settings.not_taken["callback[2]"]
    assert "not a stable_baselines3 BaseCallback class" in settings.not_taken["callback[3]"]
    bar, checkpoint = settings.trainer.callbacks
    assert bar is ProgressBarCallback
    assert checkpoint.func is CheckpointCallback
    assert checkpoint.keywords == {"save_freq": 100, "save_path": "checkpoints"}
    assert settings.source == str(path) and str(path) in message


@pytest.mark.slow
def test_the_zoos_callbacks_run_in_the_spec_they_are_unpacked_into(tmp_path):
    path = write(
        tmp_path,
        f"""
        CartPole-v1:
          n_timesteps: 128
          n_steps: 64
          batch_size: 32
          callback:
            - stable_baselines3.common.callbacks.CheckpointCallback:
                save_freq: 64
                save_path: {tmp_path / "checkpoints"}
        """,
    )
    settings = sg.zoo_settings("PPO", "CartPole-v1", file=path)
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    budget = sg.Budget(timesteps=settings.timesteps, min_seeds=1, max_seeds=1, eval_episodes=2, checkpoints=1)
    spec = sg.Spec(cartpole, sg.Goal("right", x=(0.5, None)), budget=budget, **settings)
    result = sg.run_spec(spec, workers=1, cache_dir=None, progress=None)
    assert not result.errors
    saved = sorted(p.name for p in (tmp_path / "checkpoints").iterdir())
    assert saved == ["rl_model_128_steps.zip", "rl_model_64_steps.zip"]


def test_normalize_discounts_by_the_algorithms_gamma_as_rl_zoo3_does(tmp_path):
    # rl-zoo3 gives VecNormalize the algorithm's gamma over the one its options name: here 0.99, VecNormalize's own.
    path = write(tmp_path, 'E-v0:\n  n_timesteps: 100\n  gamma: 0.99\n  normalize: "dict(gamma=0.95)"\n')
    settings, warned = zoo("PPO", "E-v0", file=path)
    assert settings.trainer.normalize is True and settings.not_taken == {} and warned == []


def test_an_entry_without_a_policy_gets_the_algorithms_default(tmp_path):
    path = write(tmp_path, "E-v0:\n  n_timesteps: 100\n")
    assert zoo("RecurrentPPO", "E-v0", file=path)[0].trainer.policy == "MlpLstmPolicy"
    assert zoo("PPO", "E-v0", file=path)[0].trainer.policy == "MlpPolicy"


def test_train_freq_as_a_list_is_a_tuple_and_a_bad_schedule_is_refused(tmp_path):
    path = write(tmp_path, "E-v0:\n  n_timesteps: 100\n  train_freq: [1, episode]\n")
    settings, _ = zoo("SAC", "E-v0", file=path)
    assert settings.trainer.hyperparameters["train_freq"] == (1, "episode")
    path = write(tmp_path, "E-v0:\n  n_timesteps: 100\n  learning_rate: exp_0.1\n")
    with pytest.raises(
        sg.error.InvalidSpec, match=r"learning_rate: expected a number or a schedule 'lin_<initial value>'"
    ):
        sg.zoo_settings("SAC", "E-v0", file=path)


# -- bad input: one line, naming the file or key ------------------------------------------------------------


def refused(path, match):
    """The one InvalidSpec zoo_settings raises for ``path``'s entry E-v0, its message one line."""
    with pytest.raises(sg.error.InvalidSpec, match=match) as e:
        sg.zoo_settings("PPO", "E-v0", file=path)
    assert "\n" not in e.value.message and len(e.value.message) < 500
    return e.value


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("dict(net_arch={[1]: 2})", r"policy_kwargs: a dict key must be hashable .*, got \[1\]"),
        ("dict(net_arch={([1],): 2})", r"policy_kwargs: a dict key must be hashable .*, got \(\[1\],\)"),
        ("-" * 2000 + "1", r"policy_kwargs: cannot evaluate '-----.*1': it nests deeper than 64 levels"),
        ("not " * 5000 + "1", r"policy_kwargs: cannot evaluate 'not not .*1': it nests deeper than 64 levels"),
    ],
)
def test_policy_kwargs_python_cannot_evaluate_are_one_error(tmp_path, text, message):
    path = write(tmp_path, f'E-v0:\n  n_timesteps: 1000\n  policy_kwargs: "{text}"\n')
    refused(path, message)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"E-v0:\n  n_timesteps: 100\n  policy: Mlp\xe9Policy\n", r"not UTF-8 text \(byte 0xe9 at offset 38\)"),
        ("E-v0:\n  n_timesteps: 100\n  x: " + "[" * 100_000 + "]" * 100_000, "it nests deeper than 64 levels"),
        ("E-v0:\n  n_timesteps: " + "1" * 5000 + "\n", r"ValueError: Exceeds the limit \(4300 digits\)"),
        ("E-v0: [1, 2\n", r"expected ',' or ']', but got '<stream end>' \(line 2, column 1\)\n"),
    ],
    ids=["latin-1", "nested", "long-integer", "syntax"],
)
def test_a_file_yaml_cannot_read_is_one_error_naming_it(tmp_path, content, message):
    path = tmp_path / "mine.yml"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    refused(path, rf"^zoo_settings\('PPO', 'E-v0'\): cannot read '.*mine.yml': {message}")


@pytest.mark.parametrize("value", ["true", "false", "0", "-100", "1.5", ".inf", ".nan", "'1000'", "[1000]"])
def test_n_timesteps_must_be_a_whole_number_of_steps(tmp_path, value):
    path = write(tmp_path, f"E-v0:\n  n_timesteps: {value}\n")
    refused(path, r"expected n_timesteps to be a whole number of steps >= 1, got ")


def laughs(levels):
    """A YAML alias bomb under unknown keys: ``levels`` lists, each of 9 aliases of the one before (9**levels)."""
    lines = ["E-v0:", "  n_timesteps: 100", "  l0: &l0 [" + ",".join(["lol"] * 9) + "]"]
    lines += [f"  l{i}: &l{i} [" + ",".join([f"*l{i - 1}"] * 9) + "]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def test_an_alias_bomb_is_refused_and_what_is_not_taken_is_bounded(tmp_path):
    refused(write(tmp_path, laughs(6)), r"cannot read '.*mine.yml': with its aliases expanded it holds over 100,000")
    assert len(laughs(9)) < 500  # 9**9 (387 million) values once expanded: a repr of gigabytes
    refused(write(tmp_path, laughs(9)), "over 100,000 values")
    # Under the limit, a value's repr is still cut: 9**5 values under l4, a text of 100,000 characters.
    path = write(tmp_path, laughs(5) + f"  long: {'x' * 100_000}\n")
    settings, [message] = zoo("PPO", "E-v0", file=path)
    assert set(settings.not_taken) == {"l0", "l1", "l2", "l3", "l4", "long"}
    assert all(len(reason) < 300 for reason in settings.not_taken.values()) and len(message) < 2000
    assert settings.not_taken["long"].startswith("'xxxx") and "..." in settings.not_taken["long"]
    assert settings.not_taken["l4"].startswith("[[[[[...], [...],")
    refused(write(tmp_path, laughs(4) + "  policy: *l3\n"), r"expected policy to be one of .*, got \[\[\[\['lol', .*…")


@pytest.mark.parametrize("text", ["lin_inf", "lin_nan", "lin_1e999"])
def test_a_schedule_that_is_not_finite_is_refused_naming_the_hyperparameter(tmp_path, text):
    path = write(tmp_path, f"E-v0:\n  n_timesteps: 100\n  learning_rate: {text}\n")
    with pytest.raises(
        sg.error.InvalidSpec, match=rf"learning_rate: expected .*'lin_<initial value>', a finite one, got '{text}'"
    ):
        sg.zoo_settings("PPO", "E-v0", file=path)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("learning_rate", LinearSchedule(float("inf")), r"expected learning_rate to be a finite number, got Linear"),
        ("clip_range", float("nan"), r"expected clip_range to be a finite number, got nan"),
        ("learning_rate", "lin_inf", r"expected learning_rate to be a number or a schedule .*, got the text 'lin_inf'"),
    ],
)
def test_a_spec_refuses_a_schedule_that_is_not_finite_naming_the_hyperparameter(key, value, message):
    # It trained to NaN logits, which fail the agent at evaluation ("the agent raised ValueError"): refused first.
    with pytest.raises(sg.error.InvalidSpec, match=rf"^SB3.hyperparameters: {message}"):
        sg.Spec(CARTPOLE, UPRIGHT, budget=sg.Budget(timesteps=64), trainer=sg.SB3(hyperparameters={key: value}))


# -- schedules ------------------------------------------------------------------------------------------


def test_a_linear_schedule_is_rl_zoos_and_keys_by_its_value():
    schedule = LinearSchedule(0.2)
    assert [schedule(p) for p in (1.0, 0.5, 0.0)] == [0.2, 0.1, 0.0]
    assert pickle.loads(pickle.dumps(schedule)) == schedule
    assert digest(LinearSchedule(0.2)) == digest(schedule) != digest(LinearSchedule(0.3))


@pytest.mark.slow
def test_a_zoo_entry_trains_with_its_schedules_and_is_cached(tmp_path):
    """CartPole-v1's PPO entry end to end: two seeds in worker processes, the schedules in the model, then the cache."""
    settings, _ = zoo("PPO", "CartPole-v1")
    # 8 envs x 32 steps = 256 steps a rollout: two rollouts, so the schedules move.
    spec = sg.Spec(
        CARTPOLE,
        UPRIGHT,
        budget=sg.Budget(timesteps=512, min_seeds=2, eval_episodes=2, checkpoints=1),
        **settings,
    )
    first = sg.run_spec(spec, workers=2, cache_dir=tmp_path, progress=None)
    assert first.cached == {0: False, 1: False}
    model = sg.load_model(first, 0)
    assert model.n_envs == 8 and model.n_steps == 32 and model.gamma == 0.98
    assert model.learning_rate == LinearSchedule(0.001)
    assert model.clip_range(0.5) == pytest.approx(0.1) and model.lr_schedule(0.25) == pytest.approx(0.00025)
    again = sg.run_spec(spec, workers=1, cache_dir=tmp_path, progress=None)
    assert again.cached == {0: True, 1: True}
    hyperparameters = {**settings.trainer.hyperparameters, "learning_rate": 0.001}
    constant = dataclasses.replace(settings.trainer, hyperparameters=hyperparameters)
    other = sg.Spec(CARTPOLE, UPRIGHT, budget=spec.budget, observation=settings.observation, trainer=constant)
    assert fingerprint_spec(other).run_base != fingerprint_spec(spec).run_base


def test_settings_unpack_as_spec_fields_and_can_be_overridden():
    settings, _ = zoo("PPO", "CartPole-v1")
    assert isinstance(settings, ZooSettings) and list(settings) == ["trainer", "observation"]
    assert isinstance(settings.trainer, sg.SB3) and settings.trainer.n_envs == 8
    one_env = dataclasses.replace(settings.trainer, n_envs=1)
    spec = sg.Spec(CARTPOLE, UPRIGHT, budget=sg.Budget(timesteps=64), **{**settings, "trainer": one_env})
    assert spec.trainer.n_envs == 1 and spec.trainer.hyperparameters["n_steps"] == 32
    with pytest.raises(KeyError):
        settings["timesteps"]
