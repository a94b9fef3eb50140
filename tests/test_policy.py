"""A model as a policy: a recurrent policy's state carried per env and cleared at episode starts, action masks read
per env, in evaluation, rollouts and the falsifier's lockstep batches."""

from __future__ import annotations

import numpy as np
import pytest
from sb3_contrib import MaskablePPO, RecurrentPPO

import specguard as sg
from specguard.construction.episode_policy import EpisodePolicy
from specguard.engine.falsify_run import batch_policy, property_keys
from specguard.evaluation.policy import Policy, policy
from specguard.evaluation.rollout import rollout_model
from specguard.falsify.search import EpisodeRunner

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
TREE = sg.All(sg.Goal("centre", x=(-0.5, 0.5)), sg.Goal("fast", v=(2.0, 100.0)), name="cartpole")
PENDULUM = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))


def cartpole_spec(**kwargs):
    return sg.Spec(CARTPOLE, TREE, budget=sg.Budget(timesteps=64, min_seeds=1), **kwargs)


def pendulum_spec(**kwargs):
    goal = sg.Goal("up", x=(0.99, 1.0), omega=(-0.1, 0.1))
    return sg.Spec(PENDULUM, goal, budget=sg.Budget(timesteps=64, min_seeds=1), **kwargs)


@pytest.fixture(scope="module")
def lstm():
    """An untrained recurrent policy on Pendulum: continuous actions, so every change of its state shows."""
    spec = pendulum_spec(trainer=sg.SB3(algorithm="RecurrentPPO"))
    return spec, RecurrentPPO("MlpLstmPolicy", spec.make_env(), seed=0, device="cpu")


def by_hand(model, observations, *, deterministic=True):
    """The actions SB3's own loop gives for one env's observations, from an episode start."""
    state, start, actions = None, np.ones(1, dtype=bool), []
    for obs in observations:
        action, state = model.predict(obs, state=state, episode_start=start, deterministic=deterministic)
        start = np.zeros(1, dtype=bool)
        actions.append(action.reshape(-1))
    return np.array(actions)


def same(a, b):
    """Equal up to float rounding (a batch and one row multiply in another order), relative to the actions' size."""
    return np.shape(a) == np.shape(b) and np.allclose(a, b, rtol=0, atol=1e-4 * np.abs(b).max())


OBS = np.random.default_rng(0).normal(size=(3, 40, 3)).astype(np.float32)  # env, step, observation
CART_OBS = np.random.default_rng(1).normal(size=(3, 2, 4)).astype(np.float32)


def test_a_model_policy_carries_state_and_tells_it_is_an_episode_policy(lstm):
    _, model = lstm
    act = policy(model)
    assert isinstance(act, EpisodePolicy) and isinstance(act, Policy)
    act.start([None])
    actions = np.array([act(obs) for obs in OBS[0]]).reshape(40, -1)
    assert same(actions, by_hand(model, OBS[0]))
    fresh = np.ones(1, dtype=bool)
    stateless = np.array([model.predict(o, episode_start=fresh, deterministic=True)[0] for o in OBS[0]])
    assert not same(actions[1:], stateless.reshape(40, -1)[1:])  # the state matters
    act.start([None])  # a new episode: the state starts afresh
    assert same(np.array([act(obs) for obs in OBS[0]]).reshape(40, -1), actions)


def test_a_batch_keeps_each_rows_state_as_rows_finish(lstm):
    _, model = lstm
    act = policy(model, batch=True)
    act.start([None, None, None])
    steps = {0: 25, 1: 10, 2: 40}  # rows finish at different steps
    got: dict[int, list[np.ndarray]] = {i: [] for i in steps}
    for t in range(40):
        rows = [i for i in steps if t < steps[i]]
        actions = act(OBS[rows, t], rows)
        for i, a in zip(rows, actions, strict=True):
            got[i].append(a)
    for i in steps:
        assert same(np.array(got[i]), by_hand(model, OBS[i, : steps[i]])), f"row {i}"


def test_a_models_actions_without_state_are_predicts_own(lstm):
    from stable_baselines3 import PPO

    spec, _ = lstm
    model = PPO("MlpPolicy", spec.make_env(), seed=0, device="cpu")
    act = policy(model, batch=True)
    act.start([None] * 3)
    assert np.array_equal(act(OBS[:, 0]), model.predict(OBS[:, 0], deterministic=True)[0])


def test_rollouts_carry_the_state_through_each_episode(lstm):
    spec, model = lstm
    episodes = rollout_model(model, spec, episodes=2, seed=5)
    for steps in episodes:
        assert same(np.array([s["action"] for s in steps]), by_hand(model, [s["obs"] for s in steps]))


def test_the_falsifiers_lockstep_batches_give_each_start_its_own_state():
    spec = cartpole_spec(trainer=sg.SB3(algorithm="RecurrentPPO"))
    model = RecurrentPPO("MlpLstmPolicy", spec.make_env(), seed=0, device="cpu")
    space = sg.StartSpace({"theta": (-0.2, 0.2), "omega": (-1.0, 1.0)})
    points = np.random.default_rng(1).uniform(-1, 1, size=(8, 4)) * [0, 0, 0.2, 1.0]

    def outcomes(batch):
        runner = EpisodeRunner(spec.make_env, batch_policy(model, None, True), space, property_keys(spec), batch=batch)
        return runner.run(points)

    together = outcomes(8)
    assert len({o.steps for o in together}) > 1  # rows finish at different steps
    assert together == outcomes(1)


def test_a_masked_model_reads_each_rows_masks_from_its_env():
    class Env:
        def __init__(self, valid):
            self.valid = valid

        def get_wrapper_attr(self, name):
            assert name == "action_masks"
            return lambda: np.arange(2) == self.valid

    spec = cartpole_spec(trainer=sg.SB3(algorithm="MaskablePPO"))
    model = MaskablePPO("MlpPolicy", spec.make_env(), seed=0, device="cpu")
    act = policy(model, batch=True)
    assert act.masked
    act.start([Env(0), Env(1), Env(0)])
    assert list(act(CART_OBS[:, 0])) == [0, 1, 0]
    assert list(act(CART_OBS[[1, 2], 1], [1, 2])) == [1, 0]
    single = policy(model)
    single.start([Env(1)])
    assert single(CART_OBS[0, 0]) == 1


def test_a_masked_model_not_told_its_envs_says_so():
    model = MaskablePPO(
        "MlpPolicy", cartpole_spec(trainer=sg.SB3(algorithm="MaskablePPO")).make_env(), seed=0, device="cpu"
    )
    with pytest.raises(sg.SpecError, match=r"MaskablePPO acts on action masks, and the policy was not told its envs"):
        policy(model)(CART_OBS[0, 0])


@pytest.mark.parametrize("deterministic", [True, False], ids=["deterministic", "sampled"])
@pytest.mark.parametrize("algorithm", ["PPO", "SAC", "RecurrentPPO"])
def test_a_policys_actions_are_predicts_own_to_the_bit_and_the_model_and_torch_are_restored(algorithm, deterministic):
    import torch
    from stable_baselines3 import PPO, SAC
    from torch.distributions import Distribution

    spec = pendulum_spec(trainer=sg.SB3(algorithm=algorithm))
    model = {"PPO": PPO, "SAC": SAC, "RecurrentPPO": RecurrentPPO}[algorithm](
        "MlpLstmPolicy" if algorithm == "RecurrentPPO" else "MlpPolicy", spec.make_env(), seed=0, device="cpu"
    )
    model.policy.set_training_mode(True)  # as SB3 leaves it after an update
    observations = OBS[0]
    torch.manual_seed(7)
    expected = by_hand(model, observations, deterministic=deterministic)

    model.policy.set_training_mode(True)
    calls = []
    original = type(model.policy).set_training_mode
    act = Policy(model, deterministic=deterministic)
    act.start([None])
    torch.manual_seed(7)
    try:
        type(model.policy).set_training_mode = lambda self, mode: (calls.append(mode), original(self, mode))[1]
        got = np.array([np.reshape(act(obs), -1) for obs in observations])
    finally:
        type(model.policy).set_training_mode = original
    assert got.tobytes() == expected.tobytes()
    assert calls == [False], "eval mode is set once, not at every step"
    assert not model.policy.training
    assert "set_training_mode" not in vars(model.policy) and Distribution._validate_args is True
