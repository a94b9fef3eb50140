"""REINFORCE in plain PyTorch, CleanRL's single-file style, trained through specguard's trainer protocol.

A trainer is a generator function ``trainer(make_env, timesteps, seed)`` that yields ``(steps, agent)`` checkpoints
as it trains (``Spec(trainer=...)``, docs/guide/training.md, "Your callbacks, logs and trainer"). specguard judges
the checkpoints with its anytime looks, closes the generator once every threshold is met, and caches the last agent.

This file is a spec file too: ``specguard run examples/trainers/reinforce.py`` trains and judges ``balance``.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

import specguard as sg

LEARNING_RATE = 1e-2
GAMMA = 0.99
EPISODES_PER_UPDATE = 8
HIDDEN = 32


class Actor(nn.Module):
    """A categorical policy over a Box observation: logits from a small MLP."""

    def __init__(self, observations: int, actions: int) -> None:
        super().__init__()
        self.net = nn.Sequential(nn.Linear(observations, HIDDEN), nn.Tanh(), nn.Linear(HIDDEN, actions))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs)


class Greedy:
    """The agent a checkpoint yields: the actor's most likely action for one observation (a snapshot of it)."""

    def __init__(self, actor: Actor) -> None:
        self.net = Actor(actor.net[0].in_features, actor.net[2].out_features)
        self.net.load_state_dict(actor.state_dict())

    def __call__(self, obs: np.ndarray) -> int:
        with torch.no_grad():
            return int(self.net(torch.as_tensor(obs, dtype=torch.float32)).argmax())


def reinforce(make_env, timesteps, seed):
    """Train a categorical policy by REINFORCE on ``make_env()``; yield ``(steps, agent)`` after every update."""
    torch.manual_seed(seed)
    torch.set_num_threads(1)
    env = make_env()
    actor = Actor(env.observation_space.shape[0], env.action_space.n)
    optimizer = torch.optim.Adam(actor.parameters(), lr=LEARNING_RATE)
    steps, episode = 0, 0
    try:
        while steps < timesteps:
            losses = []
            for _ in range(EPISODES_PER_UPDATE):
                obs, _ = env.reset(seed=seed + episode)
                episode += 1
                log_probs, rewards, done = [], [], False
                while not done:
                    logits = actor(torch.as_tensor(obs, dtype=torch.float32))
                    dist = torch.distributions.Categorical(logits=logits)
                    action = dist.sample()
                    obs, reward, terminated, truncated, _ = env.step(int(action))
                    log_probs.append(dist.log_prob(action))
                    rewards.append(float(reward))
                    done = terminated or truncated
                    steps += 1
                returns, g = [], 0.0
                for r in reversed(rewards):
                    g = r + GAMMA * g
                    returns.append(g)
                ret = torch.tensor(returns[::-1])
                ret = (ret - ret.mean()) / (ret.std() + 1e-8) if len(ret) > 1 else ret * 0
                losses.append(-(torch.stack(log_probs) * ret).sum())
            optimizer.zero_grad()
            torch.stack(losses).mean().backward()
            optimizer.step()
            yield steps, Greedy(actor)
    finally:
        env.close()


cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"), max_episode_steps=100)
balance = sg.Spec(
    cartpole,
    sg.Always(sg.Goal("upright", theta=(-0.2, 0.2), x=(-2.4, 2.4)), name="balance"),
    budget=sg.Budget(timesteps=40_000, eval_episodes=20, checkpoints=8),
    expect=0.5,
    trainer=reinforce,
    name="balance-reinforce",
)
