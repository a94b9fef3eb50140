"""The falsifier's ``value`` arm: the agent's own critic (``Policy.values``) steers it to the starts the agent expects
the least return from (planted policies on ``test_falsify``'s plane; SB3 models' critics read as they act)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from sb3_contrib import RecurrentPPO
from stable_baselines3 import DQN, PPO, SAC
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import VecNormalize
from test_falsify import runner
from test_falsify_learned import corner

import specguard as sg
from specguard.construction.episode_policy import ValuedPolicy
from specguard.evaluation.policy import Policy
from specguard.falsify.portfolio import VALUE_SHARE, Portfolio
from specguard.falsify.search import falsify


class Critic:
    """The corner's policy (it fails from 1 start in 400), with a critic that expects the least from the square
    x > 0.5, y > 0.5 around the corner (a sixteenth of the plane), and the same from everywhere else."""

    def __call__(self, observations):
        return corner(observations)

    def values(self, observations):
        return -((observations[:, 0] > 0.5) & (observations[:, 1] > 0.5)).astype(float)


def test_the_value_arm_picks_the_least_or_the_most_valued_of_its_candidates_as_often():
    # Mutation: argmin alone (or argmax alone) leaves one end without picks.
    portfolio = Portfolio(2, np.random.default_rng(0), value=lambda points: points.sum(axis=1))
    picked = np.stack(list(portfolio._valued(400))).sum(axis=1)
    assert np.abs(picked).mean() > 1.2  # uniform draws: 2/3 on average
    assert 0.4 < np.mean(picked < 0) < 0.6
    assert "value" not in Portfolio(2, np.random.default_rng(0)).shares()


def test_the_value_arms_share_is_fixed_whatever_the_other_arms_earn():
    portfolio = Portfolio(2, np.random.default_rng(0), value=lambda points: points[:, 0])
    portfolio.observe(np.zeros((40, 2)), np.linspace(1.0, 0.0, 40), ["trend"] * 40)  # each lower: each pays
    shares = portfolio.shares()
    assert shares["value"] == VALUE_SHARE and shares["uniform"] == 0.5
    assert shares["trend"] > shares["local"] and sum(shares.values()) == pytest.approx(1.0)
    # Before any score: the value arm's share, and uniform draws for the arms that follow scores.
    _, arms = Portfolio(2, np.random.default_rng(1), value=lambda points: points[:, 0]).propose(400)
    assert set(arms) == {"uniform", "value"} and 0.15 < arms.count("value") / 400 < 0.35


def test_the_critic_steers_the_search_to_a_rare_failure():
    # The corner fails from 1 start in 400, a 25th of the square the critic expects least from. Half the value arm's
    # starts are the least valued of 16 draws (64% of them in the square): its starts fail about 5 times as often as
    # uniform ones, the search's, a quarter of them the arm's, about twice. Capped at 1,000 episodes, 20 searches
    # spend about half as many (measured: 0.58). Mutation: not giving the portfolio the critic (the same searches).
    def episodes(critic):
        spent = 0
        for seed in range(20):
            found = falsify(runner(Critic()), examples=1000, uniform=0, seed=seed, shrink=False, critic=critic)
            spent += found.episodes_to_first if found.found else 1000
        return spent

    valued, plain = episodes(True), episodes(False)
    assert valued < 0.8 * plain, (valued, plain)


def test_the_report_says_whether_the_critic_steered_the_search():
    found = falsify(runner(Critic()), examples=40, uniform=0, seed=0, shrink=False)
    assert found.critic_text.startswith("the value arm took 25% of every round, the least or most valued of 16")
    assert f"it drew {found.drawn_by.get('value', 0)} of the guided starts" in found.critic_text
    assert "the agent's critic: the value arm" in found.report() and found.to_dict()["critic"] == found.critic_text
    off = falsify(runner(Critic()), examples=40, uniform=0, seed=0, shrink=False, critic=False)
    assert off.critic_text == "not used (critic=False)" and "value" not in off.drawn_by
    plain = falsify(runner(corner), examples=40, uniform=0, seed=0, shrink=False)  # a callable: no critic
    assert plain.critic_text.startswith("none to ask") and "value" not in plain.drawn_by
    with pytest.raises(sg.error.InvalidSpec, match="critic"):
        falsify(runner(corner), examples=4, critic="yes")


def test_a_models_values_are_its_critics_on_the_observations_it_reads():
    obs = np.random.default_rng(0).normal(size=(5, 4)).astype(np.float32)
    ppo = PPO("MlpPolicy", "CartPole-v1", seed=0, device="cpu")
    with torch.no_grad():
        expected = ppo.policy.predict_values(torch.as_tensor(obs)).numpy().ravel()
    assert isinstance(Policy(ppo, batch=True), ValuedPolicy)
    np.testing.assert_allclose(Policy(ppo, batch=True).values(obs), expected, rtol=1e-6)
    # Its VecNormalize statistics applied, as when it acts. Mutation: the raw observations give other values.
    stats = VecNormalize(make_vec_env("CartPole-v1", n_envs=1), norm_reward=False)
    stats.obs_rms.mean, stats.obs_rms.var = np.full(4, 3.0), np.full(4, 4.0)
    with torch.no_grad():
        normalised = ppo.policy.predict_values(torch.as_tensor(stats.normalize_obs(obs))).numpy().ravel()
    np.testing.assert_allclose(Policy(ppo, stats, batch=True).values(obs), normalised, rtol=1e-6)
    assert not np.allclose(normalised, expected)
    dqn = DQN("MlpPolicy", "CartPole-v1", seed=0, device="cpu", learning_starts=0)
    with torch.no_grad():
        best = dqn.policy.q_net(torch.as_tensor(obs)).max(dim=1).values.numpy()
    np.testing.assert_allclose(Policy(dqn, batch=True).values(obs), best, rtol=1e-6)
    sac = SAC("MlpPolicy", "Pendulum-v1", seed=0, device="cpu")
    o = obs[:, :3]
    with torch.no_grad():
        q1, q2 = sac.policy.critic(torch.as_tensor(o), sac.policy._predict(torch.as_tensor(o), deterministic=True))
    np.testing.assert_allclose(Policy(sac, batch=True).values(o), torch.min(q1, q2).numpy().ravel(), rtol=1e-6)
    # A recurrent policy's critic needs its hidden state: no estimate from the observation alone.
    assert Policy(RecurrentPPO("MlpLstmPolicy", "CartPole-v1", seed=0, device="cpu"), batch=True).values(obs) is None


def test_an_agent_trained_elsewhere_steers_the_search_by_its_own_critic():
    # An SB3 model handed to falsify_agent: its critic is asked through the Agent. Mutation: Agent.values returning
    # None leaves the search without its value arm.
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    spec = sg.Spec(cartpole, sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance"), budget=sg.Budget(1))
    model = PPO("MlpPolicy", "CartPole-v1", seed=0, device="cpu")
    found = sg.falsify_agent(spec, model, sg.StartSpace({"theta": (-0.1, 0.1)}), examples=40, uniform=0)
    assert found.critic_text.startswith("the value arm took 25% of every round"), found.critic_text
    off = sg.falsify_agent(spec, model, sg.StartSpace({"theta": (-0.1, 0.1)}), examples=40, uniform=0, critic=False)
    assert off.critic_text == "not used (critic=False)"
