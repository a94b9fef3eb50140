"""Agents trained elsewhere, judged against specs: a goal spec returning ``sg.AgentCheck`` instead of a ``Spec``.

``pytest --goal-specs example_specs`` judges each agent on the spec's evaluation episodes and trains nothing
(docs/guide/agents.md): a CartPole policy written by hand, and a PPO agent trained by plain stable-baselines3 (not
by specguard) in a fixture, saved as a zip and loaded from it as any agent trained elsewhere would be.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

import specguard as sg

FEATURES = ("x", "v", "theta", "omega")
BALANCE = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")  # the pole up at every step
EPISODES = sg.Budget(timesteps=1, eval_episodes=30, max_eval_episodes=60)  # no training: only its evaluation counts


def keep_it_up(horizon: int | None = None, **expect: float) -> sg.Spec:
    """Keep the pole up until the end: CartPole's own 500 steps, or a shorter ``horizon``."""
    steps = {} if horizon is None else {"max_episode_steps": horizon}
    return sg.Spec(sg.InitialEnv("CartPole-v1", features=FEATURES, **steps), BALANCE, budget=EPISODES, expect=expect)


def push_toward_the_lean(obs: Any) -> int:
    """Push the cart toward the side the pole leans to: it catches the pole for a while, then overcorrects."""
    return int(obs[2] > 0)


@sg.goal_spec(
    expect={"balance": 0.8},
    xfail={"balance": "pushing toward the lean overcorrects: the pole falls within a few dozen steps"},
)
def test_push_toward_the_lean_until_the_end() -> sg.AgentCheck:
    return sg.AgentCheck(keep_it_up(), push_toward_the_lean)


@sg.goal_spec(expect={"balance": 0.8})
def test_push_toward_the_lean_for_20_steps() -> sg.AgentCheck:
    return sg.AgentCheck(keep_it_up(horizon=20), push_toward_the_lean)


PPO_STEPS = 8192  # seeds 0, 1 and 2 keep the pole up for 100 steps in 60/60, 60/60 and 56/60 episodes
PPO_SEED = 1


@pytest.fixture(scope="session")
def ppo_cartpole(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A PPO agent trained by plain stable-baselines3 on CartPole-v1, saved as a zip.

    Kept so that later sessions judge the same bytes without retraining: in pytest's cache where it is on, else
    beside specguard's run cache (``--goal-specs-cache-dir``, whose runs this project's ``-p no:cacheprovider``
    keeps); with ``--goal-specs-no-cache``, trained for this session only.
    """
    cache = getattr(request.config, "cache", None)  # None under -p no:cacheprovider
    runs = None if request.config.getoption("goal_specs_no_cache") else request.config.getoption("goal_specs_cache_dir")
    if cache is not None:
        folder = cache.mkdir("specguard-example-agents")
    elif runs:
        folder = Path(runs).parent / "example-agents"
        folder.mkdir(parents=True, exist_ok=True)
    else:
        folder = tmp_path_factory.mktemp("agents")
    path = folder / f"ppo-CartPole-v1-{PPO_STEPS}-seed{PPO_SEED}.zip"
    if not path.exists():
        import stable_baselines3 as sb3
        import torch

        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # a small network: more threads only wait for each other
        try:
            model = sb3.PPO(
                "MlpPolicy", "CartPole-v1", n_steps=256, batch_size=64, n_epochs=4, seed=PPO_SEED, device="cpu"
            )
            model.learn(PPO_STEPS)
        finally:
            torch.set_num_threads(threads)
        model.save(path.with_suffix(".tmp.zip"))
        path.with_suffix(".tmp.zip").replace(path)  # whole or not at all, should the session stop while saving
    return path


@sg.goal_spec(expect={"balance": 0.8})
def test_ppo_for_100_steps(ppo_cartpole: Path) -> sg.AgentCheck:
    return sg.AgentCheck(keep_it_up(horizon=100), ppo_cartpole)
