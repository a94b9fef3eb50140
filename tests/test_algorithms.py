"""Algorithms a spec can name: SB3's and sb3-contrib's by name, any BaseAlgorithm subclass; policies; hyperparameters.

A TQC spec and a RecurrentPPO spec train, are judged and are served from the cache; MaskablePPO acts on the
env's masks (tests/test_policy.py has the policy's state per env).
"""

from __future__ import annotations

import textwrap

import gymnasium as gym
import numpy as np
import pytest
import sb3_contrib
import stable_baselines3
from bad_modules import CASES, write_bad_modules

import specguard as sg
from example_specs import pendulum
from specguard.cache.canonical import canonical
from specguard.cache.fingerprint import fingerprint_spec
from specguard.evaluation.rollout import rollout_model
from specguard.spec.algorithms import (
    ALGORITHMS,
    CONTRIB,
    SB3,
    algorithm_class,
    collect_steps,
    collection_unit,
    default_policy,
    hyperparameter_names,
    resolve_algorithm,
)
from specguard.training.train import train_run

TINY = {"n_steps": 32, "batch_size": 32, "n_epochs": 1}
BUDGET = sg.Budget(timesteps=64, min_seeds=1, eval_episodes=2, checkpoints=1)


def spec(**kwargs):
    kwargs.setdefault("budget", BUDGET)
    return sg.Spec(pendulum.initial_env, pendulum.trees["w"], **kwargs)


class ExtraPPO(stable_baselines3.PPO):
    """A user's algorithm: one keyword of its own, the rest passed on to PPO."""

    def __init__(self, *args, extra: int = 1, **kwargs):
        super().__init__(*args, **kwargs)
        self.extra = extra


# -- names and classes ---------------------------------------------------------------------


def test_every_named_algorithm_is_its_librarys_class():
    assert set(ALGORITHMS) == set(SB3) | set(CONTRIB)
    for name in SB3:
        assert algorithm_class(name) is getattr(stable_baselines3, name)
    for name in CONTRIB:
        assert algorithm_class(name) is getattr(sb3_contrib, name)


@pytest.mark.parametrize(
    ("given", "resolved"),
    [
        ("TQC", "TQC"),
        (sb3_contrib.TQC, "TQC"),
        ("sb3_contrib:TQC", "TQC"),
        ("sb3_contrib.tqc.tqc:TQC", "TQC"),
        ("QR-DQN", "QRDQN"),
        (stable_baselines3.PPO, "PPO"),
        (ExtraPPO, ExtraPPO),
    ],
)
def test_a_named_algorithm_is_its_name_whichever_way_it_is_given(given, resolved):
    assert resolve_algorithm("Spec 'x'.algorithm", given) == resolved


def test_an_algorithm_by_module_and_class(tmp_path, monkeypatch):
    (tmp_path / "my_algos.py").write_text(
        textwrap.dedent(
            """
            from stable_baselines3 import A2C

            class Mine(A2C):
                pass
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    import my_algos

    assert spec(trainer=sg.SB3(algorithm="my_algos:Mine")).trainer.algorithm is my_algos.Mine


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ("PPO2", r"unknown algorithm 'PPO2'; expected one of PPO, A2C, DQN, SAC, TD3, DDPG, ARS, CrossQ, "),
        ("qrdqn", r"unknown algorithm 'qrdqn'; expected one of .*QRDQN, RecurrentPPO, TQC, TRPO, "),
        ("no_such_module:X", r"cannot import algorithm 'no_such_module:X': ModuleNotFoundError"),
        ("sb3_contrib:Nope", r"cannot import algorithm 'sb3_contrib:Nope': AttributeError"),
        ("gymnasium:Env", r"expected algorithm to be one of .*a BaseAlgorithm subclass or 'module:Class', got"),
        (dict, r"expected algorithm to be one of .*, got <class 'dict'>"),
    ],
)
def test_an_unknown_algorithm_is_one_line_listing_what_is_accepted(given, message):
    with pytest.raises(sg.error.InvalidSpec, match=rf"^SB3.algorithm: {message}") as e:
        spec(trainer=sg.SB3(algorithm=given))
    assert "\n" not in e.value.message


@pytest.mark.parametrize(("module", "says"), CASES, ids=[m or "empty" for m, _ in CASES])
def test_a_module_that_cannot_be_imported_is_one_error_naming_the_string(module, says, tmp_path, monkeypatch):
    write_bad_modules(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    text = f"{module}:PPO"
    with pytest.raises(sg.error.InvalidSpec) as e:  # not the module's own error, nor its SystemExit
        spec(trainer=sg.SB3(algorithm=text))
    assert e.value.where == "SB3.algorithm"
    assert e.value.message.startswith(f"cannot import algorithm {text!r}: {says}")
    assert "\n" not in e.value.message


def test_without_sb3_contrib_its_names_say_what_to_install(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "sb3_contrib", None)  # import sb3_contrib raises ImportError
    with pytest.raises(
        sg.error.InvalidSpec, match=r"TQC is an sb3-contrib algorithm, and sb3-contrib is not installed"
    ):
        spec(trainer=sg.SB3(algorithm="TQC"))


# -- policies ----------------------------------------------------------------------------------


def test_the_default_policy_is_mlp_and_the_recurrent_algorithms_lstm():
    assert spec().trainer.policy == "MlpPolicy"
    assert spec(trainer=sg.SB3(algorithm="TQC")).trainer.policy == "MlpPolicy"
    assert spec(trainer=sg.SB3(algorithm="RecurrentPPO", hyperparameters=TINY)).trainer.policy == "MlpLstmPolicy"
    assert default_policy(ExtraPPO) == "MlpPolicy"


def test_a_policy_by_name_or_class():
    from stable_baselines3.common.policies import ActorCriticCnnPolicy, ActorCriticPolicy

    assert spec(trainer=sg.SB3(policy="MlpPolicy")).trainer.policy == "MlpPolicy"
    assert (
        spec(baseline=True, trainer=sg.SB3(policy="CnnPolicy")).trainer.policy == "CnnPolicy"
    )  # the env's own observation: SB3 checks it
    assert spec(trainer=sg.SB3(policy=ActorCriticPolicy)).trainer.policy is ActorCriticPolicy
    assert (
        spec(trainer=sg.SB3(policy=ActorCriticCnnPolicy)).trainer.policy is ActorCriticCnnPolicy
    )  # a class: SB3 checks the observation


@pytest.mark.parametrize(("algorithm", "policy"), [("PPO", "CnnPolicy"), ("RecurrentPPO", "CnnLstmPolicy")])
def test_an_image_policy_on_the_flat_features_is_refused_naming_the_policy_that_fits(algorithm, policy):
    with pytest.raises(sg.error.InvalidSpec) as e:
        spec(trainer=sg.SB3(algorithm=algorithm, policy=policy, hyperparameters=TINY))
    assert e.value.where == "Spec 'pendulum'.trainer.policy"
    fits = default_policy(algorithm)
    assert e.value.message == (
        f"the agent's observation is a flat Box of numbers, not an image (observation='features'), "
        f"which {policy!r} does not take; one that does: {fits}"
    )
    assert "observation='features+env'" in str(e.value.hint)


def test_a_policy_class_of_another_algorithm_is_refused_naming_the_policy():
    from stable_baselines3.dqn.policies import DQNPolicy

    with pytest.raises(sg.error.InvalidSpec) as e:
        sg.SB3(policy=DQNPolicy)
    assert e.value.where == "SB3.policy"
    assert e.value.message == (
        "DQNPolicy is no policy of PPO: expected a subclass of one of its policy classes "
        "(ActorCriticPolicy, ActorCriticCnnPolicy, MultiInputActorCriticPolicy)"
    )


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"policy": "MlpLstmPolicy"}, r"one of MlpPolicy, CnnPolicy, MultiInputPolicy \(PPO's policy names\) "),
        ({"policy": "MlpPolicy", "algorithm": "RecurrentPPO"}, r"one of MlpLstmPolicy, CnnLstmPolicy, Multi"),
        ({"policy": dict}, r"one of .* or a BasePolicy subclass, got <class 'dict'>"),
    ],
)
def test_a_policy_the_algorithm_cannot_take_is_refused(kwargs, message):
    with pytest.raises(sg.error.InvalidSpec, match=rf"^SB3.policy: expected policy to be {message}"):
        sg.SB3(**kwargs)


def test_a_policy_among_the_hyperparameters_is_refused_with_a_hint_to_the_field():
    with pytest.raises(sg.error.InvalidSpec, match=r"'policy' is not a hyperparameter here") as e:
        spec(trainer=sg.SB3(hyperparameters={"policy": "CnnPolicy"}))
    assert "\n" not in e.value.message
    assert e.value.hint == "use sg.SB3(..., policy=...)"


@pytest.mark.slow
def test_the_policy_trains():
    from stable_baselines3.common.policies import ActorCriticPolicy

    class Marked(ActorCriticPolicy):
        pass

    _, model = train_run(spec(trainer=sg.SB3(policy=Marked, hyperparameters=TINY)), seed=0)
    assert type(model.policy) is Marked


# -- hyperparameters ------------------------------------------------------------------------------


def test_an_unknown_hyperparameter_is_refused_at_construction_naming_it_the_algorithm_and_close_matches():
    with pytest.raises(sg.error.InvalidSpec) as e:
        spec(trainer=sg.SB3(hyperparameters={"bogus": 1, "n_stepz": 64, "gamma": 0.9}))
    assert e.value.where == "SB3.hyperparameters"
    assert e.value.message.splitlines() == [
        "PPO takes no hyperparameter 'bogus'",
        "PPO takes no hyperparameter 'n_stepz'; did you mean 'n_steps'?",
    ]
    assert e.value.hint.startswith("PPO takes learning_rate, n_steps, batch_size, n_epochs, gamma, ")


@pytest.mark.parametrize("key", ["seed", "env", "device", "verbose"])
def test_what_specguard_passes_itself_is_no_hyperparameter(key):
    with pytest.raises(sg.error.InvalidSpec, match=rf"'{key}' is not a hyperparameter here: "):
        spec(trainer=sg.SB3(hyperparameters={key: 0}))


def test_hyperparameter_names_follow_kwargs_to_the_base_class():
    names = hyperparameter_names(ExtraPPO)
    assert names[0] == "extra" and "n_steps" in names and "gae_lambda" in names
    assert "_init_setup_model" not in names and "policy" not in names
    spec(trainer=sg.SB3(algorithm=ExtraPPO, hyperparameters={"extra": 2, **TINY}))
    with pytest.raises(sg.error.InvalidSpec, match=r"test_algorithms:ExtraPPO takes no hyperparameter 'extr'; did you"):
        spec(trainer=sg.SB3(algorithm=ExtraPPO, hyperparameters={"extr": 2}))


def test_each_algorithm_checks_its_own_names():
    spec(trainer=sg.SB3(algorithm="TQC", hyperparameters={"top_quantiles_to_drop_per_net": 2}))
    with pytest.raises(sg.error.InvalidSpec, match=r"SAC takes no hyperparameter 'top_quantiles_to_drop_per_net'"):
        spec(trainer=sg.SB3(algorithm="SAC", hyperparameters={"top_quantiles_to_drop_per_net": 2}))


def test_values_are_sb3s_to_check():
    spec(trainer=sg.SB3(hyperparameters={"n_steps": "many"}))  # accepted here; SB3 rejects it when the run is built


# -- collections -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("algorithm", "steps", "unit"),
    [
        ("PPO", 2048, "rollouts"),
        ("A2C", 5, "rollouts"),
        ("DQN", 4, "collections"),
        ("SAC", 1, "collections"),
        ("RecurrentPPO", 128, "rollouts"),
        ("TRPO", 2048, "rollouts"),
        ("QRDQN", 4, "collections"),
        ("TQC", 1, "collections"),
        ("ARS", 1, "collections"),
        (ExtraPPO, 2048, "rollouts"),
    ],
)
def test_a_collection_is_read_from_the_algorithms_defaults(algorithm, steps, unit):
    assert (collect_steps(algorithm, {}), collection_unit(algorithm)) == (steps, unit)


# -- run keys ------------------------------------------------------------------------------------------


def test_a_contrib_algorithm_is_keyed_by_module_class_and_sb3_contribs_version():
    from importlib.metadata import version

    assert canonical(sb3_contrib.TQC) == [
        "class",
        "sb3_contrib.tqc.tqc",
        "TQC",
        f"sb3_contrib=={version('sb3_contrib')}",
    ]
    by_name, by_class = spec(trainer=sg.SB3(algorithm="TQC")), spec(trainer=sg.SB3(algorithm=sb3_contrib.TQC))
    assert fingerprint_spec(by_name).run_base == fingerprint_spec(by_class).run_base
    assert fingerprint_spec(by_name).run_base != fingerprint_spec(spec(trainer=sg.SB3(algorithm="SAC"))).run_base


def test_a_users_algorithm_is_keyed_by_its_code():
    assert fingerprint_spec(spec(trainer=sg.SB3(algorithm=ExtraPPO))).run_base != fingerprint_spec(spec()).run_base

    class Edited(ExtraPPO):
        def train(self):
            return super().train()

    class Again(ExtraPPO):
        def train(self):
            return None

    assert (
        fingerprint_spec(spec(trainer=sg.SB3(algorithm=Edited))).run_base
        != fingerprint_spec(spec(trainer=sg.SB3(algorithm=Again))).run_base
    )


def test_the_policy_is_in_the_key_only_when_it_is_not_the_default():
    default = fingerprint_spec(spec()).run_base
    assert fingerprint_spec(spec(trainer=sg.SB3(policy="MlpPolicy"))).run_base == default
    assert (
        fingerprint_spec(spec(trainer=sg.SB3(policy=stable_baselines3.common.policies.ActorCriticPolicy))).run_base
        != default
    )
    recurrent, named = (
        spec(trainer=sg.SB3(algorithm="RecurrentPPO")),
        spec(trainer=sg.SB3(algorithm="RecurrentPPO", policy="MlpLstmPolicy")),
    )
    assert fingerprint_spec(recurrent).run_base == fingerprint_spec(named).run_base


# -- training, judging, caching ---------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize(
    ("algorithm", "hyperparameters"),
    [("RecurrentPPO", TINY), ("TQC", {"learning_starts": 32, "batch_size": 32})],
)
def test_a_contrib_spec_trains_is_judged_and_is_served_from_the_cache(tmp_path, algorithm, hyperparameters):
    first = spec(expect={"pendulum": 0.5}, trainer=sg.SB3(algorithm=algorithm, hyperparameters=hyperparameters))
    result = sg.run_spec(first, workers=1, cache_dir=tmp_path, progress=None)
    assert [r.timesteps for r in result.runs] == [64] and result.cached == {0: False}
    assert not result.passed  # 64 steps hold no pendulum up: judged, missed
    assert type(sg.load_model(result, 0)) is getattr(sb3_contrib, algorithm)
    assert len(sg.rollout(result, 0)[0]) == 200  # the cached model acts (Pendulum's episodes are 200 steps)
    by_class = spec(
        expect=0.5, trainer=sg.SB3(algorithm=getattr(sb3_contrib, algorithm), hyperparameters=hyperparameters)
    )
    again = sg.run_spec(by_class, workers=1, cache_dir=tmp_path, progress=None)
    assert again.cached == {0: True} and again.runs[0].successes == result.runs[0].successes


# -- action masks --------------------------------------------------------------------------------------------


class Unmasked(gym.Env):
    """One action is valid per step (``t % 3``): ``bad`` counts the invalid ones taken, over 9 steps."""

    observation_space = gym.spaces.Box(np.zeros(3, np.float32), np.array([9, 9, 2], np.float32))
    action_space = gym.spaces.Discrete(3)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t, self.bad = 0, 0
        return self._obs(), {}

    def step(self, action):
        self.bad += int(action) != self.t % 3
        self.t += 1
        return self._obs(), 0.0, False, self.t >= 9, {}

    def _obs(self):
        return np.array([self.t, self.bad, self.t % 3], np.float32)


class Masked(Unmasked):
    """The same, saying which action is valid."""

    def action_masks(self):
        return np.arange(3) == self.t % 3


CLEAN = sg.Goal("clean", t=(8.5, 9), bad=(0, 0.5))


def masked_spec(initial=Masked, **kwargs):
    kwargs.setdefault("trainer", sg.SB3("MaskablePPO", hyperparameters=TINY))
    env = sg.InitialEnv(initial, features=("t", "bad", "valid"), **kwargs.pop("env_kwargs", {}))
    return sg.Spec(env, CLEAN, budget=sg.Budget(timesteps=64, min_seeds=1, eval_episodes=4, checkpoints=1), **kwargs)


@pytest.mark.slow
def test_maskable_ppo_acts_on_the_initial_envs_masks_in_training_and_evaluation():
    s = masked_spec(expect=0.5)
    result, model = train_run(s, seed=0)
    assert result.successes["clean"] == result.episodes  # every action valid: the masks reached predict
    steps = rollout_model(model, s, episodes=2)
    assert all(int(step["action"]) == int(step["obs"][2]) for episode in steps for step in episode)
    untrained_ppo, _ = train_run(masked_spec(trainer=sg.SB3("PPO", hyperparameters=TINY), expect=0.5), seed=0)
    assert untrained_ppo.successes["clean"] < untrained_ppo.episodes  # without masks, 64 steps do not learn them


@pytest.mark.slow
def test_maskable_ppo_without_masks_is_refused_before_training():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"MaskablePPO acts on action masks, and the initial env \(Unmasked\) "
    ):
        train_run(masked_spec(Unmasked, expect=0.5), seed=0)


@pytest.mark.slow
def test_maskable_ppo_refuses_masks_of_actions_execute_changes():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"acts on action masks, and the agent's actions go through execute\(\)"
    ):
        train_run(masked_spec(env_kwargs={"execute": lambda a: (a + 1) % 3}, expect=0.5), seed=0)
