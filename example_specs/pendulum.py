"""Pendulum-v1 (SPEC.md sections 4 and 5): swing up and hold the pendulum upright.

Run ``python example_specs/pendulum.py`` to print the trees, their reward
formulas and a short rollout of the constructed env.
"""

from __future__ import annotations

from typing import Any

import numpy as np

import specguard as sg

initial_env = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))

# Upright within 15 degrees (cos 15 = 0.966, sin 15 = 0.259), slow.
position = sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259))
stabilization = sg.Goal("stabilization", omega=(-0.25, 0.25))


def position_distance(s):  # type: ignore[no-untyped-def]
    """Distance to the top centre (1, 0); at most 2 on the unit circle."""
    return np.hypot(s.x - 1.0, s.y)


near_position = position.annotate(sg.Distance(position_distance, scale=2.0))

trees: dict[str, sg.Node] = {
    "a": sg.Goal("pendulum", x=(0.966, 1.0), y=(-0.259, 0.259), omega=(-0.25, 0.25)),
    "b": sg.All(position, stabilization, name="pendulum"),
    "c": sg.All(near_position, stabilization, name="pendulum"),
    "w": sg.All(near_position, stabilization, name="pendulum", weights=(0.8, 0.2)),
}

ppo_kwargs: dict[str, object] = {}  # SB3 defaults (paper, Table 1)

# Budgets and thresholds: rl-zoo's tuned PPO at 100k steps, where a plain
# implementation reached (SPEC.md section 5, 2 seeds x 30 episodes): baseline
# 100%, (a) 100%, (b) 17% and 43%, (c) 83% and 87%, (w) 100%. (b) is expected to
# miss: its agents stabilise without reaching the position (the paper's finding).
ZOO_PPO: dict[str, object] = {
    "n_steps": 1024,
    "gamma": 0.9,
    "learning_rate": 1e-3,
    "use_sde": True,
    "sde_sample_freq": 4,
}
BUDGET = sg.Budget(timesteps=100_000, min_seeds=2, eval_episodes=30)

EXPECT = {"a": 0.8, "b": 0.8, "c": 0.6, "w": 0.8, "baseline": 0.8}
COMMON: dict[str, Any] = dict(budget=BUDGET, hyperparameters=ZOO_PPO, n_envs=4)

specs: dict[str, sg.Spec] = {
    key: sg.Spec(initial_env, tree, expect=EXPECT[key], name=f"pendulum-{key}", **COMMON) for key, tree in trees.items()
}
specs["baseline"] = sg.Spec(
    initial_env, trees["w"], expect=EXPECT["baseline"], baseline=True, name="pendulum-baseline", **COMMON
)


def main(steps: int = 10, seed: int = 0) -> None:
    """Print the specification (w), its reward formula and a short random rollout."""
    tree = trees["w"]
    print(tree)
    print()
    print(sg.formula(tree))
    print()
    env = sg.make_env(initial_env, tree)
    obs, info = env.reset(seed=seed)
    env.action_space.seed(seed)
    print(f"reset  obs={np.round(obs, 3)}")
    for t in range(steps):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        reached = [p for p, inside in info["goals"].items() if inside]
        print(f"step {t + 1:2d} obs={np.round(obs, 3)} reward={reward:+.4f} goals reached={reached}")
        if terminated or truncated:
            break
    env.close()


if __name__ == "__main__":
    main()
