"""CartPole-v1 beyond the paper: out and back, without leaving the track (a Sequence, an Avoid, an AnyOf).

The task cannot be stated with ``All`` alone: an intersection of goals holds
in one state, but "first reach ``x >= 1``, *then* return to the centre
upright" is about the order of states. ``Sequence`` keeps the stage in the
observation (Markov property) and pays each stage once; ``Avoid`` counts the
steps that end near a track edge (a region that is itself an ``AnyOf`` of two
boxes) and ends the episode at the first one.

Needs the ``plugins/`` distribution (``pip install -e ./plugins``). Run
``python example_specs/cartpole.py`` to print the tree and its reward formula.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from specguard_plugins import AnyOf, Avoid, Sequence

import specguard as sg

initial_env = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))


def to_the_right(s):  # type: ignore[no-untyped-def]
    """How far the cart is from x = 0.25 (about 0.25 from the start)."""
    return np.maximum(0.25 - s.x, 0.0)


def to_the_centre(s):  # type: ignore[no-untyped-def]
    """How far the cart is from the centre (about 0.25 once out)."""
    return np.abs(s.x)


out = sg.Goal("out", x=(0.25, None)).annotate(sg.Distance(to_the_right, scale=0.25, weight=4.0))
back = sg.Goal("back", x=(-0.1, 0.1), theta=(-0.05, 0.05)).annotate(sg.Distance(to_the_centre, scale=0.25))
edges = AnyOf(sg.Goal("left", x=(None, -2.0)), sg.Goal("right", x=(2.0, None)), name="edges")
# The env ends an episode once |theta| > 0.2095 without a penalty: as a region to avoid, falling costs -1.
fallen = AnyOf(sg.Goal("back_down", theta=(None, -0.2)), sg.Goal("front_down", theta=(0.2, None)), name="fallen")

tree = Sequence(out, back, name="out_and_back").annotate(Avoid(edges, name="edges"), Avoid(fallen, weight=4.0, name="fallen"))

# rl-zoo's tuned PPO for CartPole-v1.
ZOO_PPO: dict[str, Any] = {
    "n_steps": 64,
    "batch_size": 256,
    "gae_lambda": 0.8,
    "gamma": 0.99,
    "n_epochs": 10,
    "ent_coef": 0.01,
    "learning_rate": 1e-3,
    "clip_range": 0.2,
}
BUDGET = sg.Budget(timesteps=100_000, min_seeds=2, eval_episodes=30)
COMMON: dict[str, Any] = dict(budget=BUDGET, hyperparameters=ZOO_PPO, n_envs=8)

spec = sg.Spec(initial_env, tree, expect={"out_and_back": 0.8}, name="cartpole", **COMMON)


if __name__ == "__main__":
    print(tree)
    print(sg.formula(tree))
