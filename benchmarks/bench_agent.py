"""Cost of judging an agent trained elsewhere (``sg.check_agent``) against a plain rollout of it on the raw env.

For each case, the same agent plays the same evaluation episodes (the same env seeds, hence the same
trajectories) twice, alternately over ``--rounds``: once in a plain loop over ``gymnasium.make(env_id)``
(``reset``, the agent's action, ``step``, until the episode ends), once through ``sg.check_agent`` (the baseline
env reading the goal tree beside it, the staged verdicts; no cache, the agent loaded beforehand). Prints the
medians and their ratio. The aim: at most 1.1x (issue "test the agent you already have"); an agent that costs
next to nothing per step (a hand-written rule) shows the goal tree's own cost per step, an agent with a network
shows what a user of a trained model pays.

Prints the figures; exits 0 whatever they are (machines are shared and noisy).

Usage:
    python benchmarks/bench_agent.py [--episodes 20] [--rounds 5] [--train-steps 4096]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import specguard as sg
from specguard.evaluation.episodes import EVAL_SEED_BASE

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
BALANCE = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")
PENDULUM = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
SWING_UP = sg.All(
    sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)), sg.Goal("slow", omega=(-0.25, 0.25)), name="up"
)


def _spec(initial: sg.InitialEnv, tree: Any) -> sg.Spec:
    return sg.Spec(initial, tree, budget=sg.Budget(timesteps=1), expect=0.5)


def _lean(obs: np.ndarray) -> int:
    """Push toward the lean."""
    return int(obs[2] > 0)


def _ppo_zip(env_id: str, steps: int, folder: Path) -> Path:
    """A PPO agent trained by plain stable-baselines3 for ``steps`` (one torch thread), saved as a zip."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    model = PPO("MlpPolicy", env_id, n_steps=512, batch_size=64, seed=0, device="cpu")
    model.learn(steps)
    path = folder / f"ppo-{env_id}.zip"
    model.save(path)
    return path


def _plain(env_id: str, act: Callable[[Any], Any], episodes: int) -> Callable[[], int]:
    """The user's own loop: the raw env, the agent's action, until each episode ends; returns the steps."""

    def rollout() -> int:
        env = gym.make(env_id)
        steps = 0
        for i in range(episodes):
            obs, _ = env.reset(seed=EVAL_SEED_BASE + i)
            done = False
            while not done:
                obs, _, terminated, truncated, _ = env.step(act(obs))
                done = terminated or truncated
                steps += 1
        env.close()
        return steps

    return rollout


def _judged(spec: sg.Spec, agent: Any, episodes: int) -> Callable[[], int]:
    def judge() -> int:
        result = sg.check_agent(spec, agent, episodes=episodes, max_episodes=episodes, cache_dir=None)
        return result.runs[0].episodes

    return judge


def _median_s(fn: Callable[[], Any], timings: list[float]) -> None:
    start = time.perf_counter()
    fn()
    timings.append(time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--train-steps", type=int, default=4096)
    args = parser.parse_args()
    warnings.simplefilter("ignore", sg.error.SpecWarning)
    with tempfile.TemporaryDirectory(prefix="bench-agent-") as tmp:
        cases: list[tuple[str, str, sg.Spec, Any, Callable[[Any], Any]]] = [
            ("CartPole, push toward the lean", "CartPole-v1", _spec(CARTPOLE, BALANCE), _lean, _lean)
        ]
        for env_id, initial, tree in (("CartPole-v1", CARTPOLE, BALANCE), ("Pendulum-v1", PENDULUM, SWING_UP)):
            agent = sg.load_agent(_ppo_zip(env_id, args.train_steps, Path(tmp)))
            model = agent.model

            def act(obs: Any, model: Any = model) -> Any:
                return model.predict(obs, deterministic=True)[0]

            cases.append((f"{env_id.split('-')[0]}, PPO zip", env_id, _spec(initial, tree), agent, act))
        print(f"{'case':<32} {'episodes':>8} {'plain s':>8} {'judged s':>9} {'ratio':>6}")
        import torch

        torch.set_num_threads(1)
        for label, env_id, spec, agent, act in cases:
            plain, judged = _plain(env_id, act, args.episodes), _judged(spec, agent, args.episodes)
            judged()  # the first call builds the spec's env factory; the figures are a user's next calls
            plain_s: list[float] = []
            judged_s: list[float] = []
            for _ in range(args.rounds):  # alternately, so that a busy machine weighs on both
                _median_s(plain, plain_s)
                _median_s(judged, judged_s)
            p, j = statistics.median(plain_s), statistics.median(judged_s)
            print(f"{label:<32} {args.episodes:>8} {p:8.3f} {j:9.3f} {j / p:5.2f}x")


if __name__ == "__main__":
    main()
