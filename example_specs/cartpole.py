"""CartPole-v1 beyond the paper: lean the pole out, then catch it (a Sequence, two Avoids, AnyOf regions).

The task cannot be stated with ``All`` alone: an intersection of goals holds
in one state, but "first lean the pole to at least 0.1 rad, *then* bring it
back upright and still" is about the order of states (its last state is an
upright pole, which ``All`` would accept without any lean). ``Sequence``
keeps the stage in the observation (Markov property) and pays each stage
once; each ``Avoid`` counts the steps that end in its region (an ``AnyOf`` of
two boxes: the track's edges, a pole past 0.2 rad) and ends the episode at
the first one, with a penalty: the env's own end at 0.21 rad pays nothing.

Needs the ``plugins/`` distribution (``pip install -e ./plugins``). Run
``python example_specs/cartpole.py`` to print the tree and its reward formula.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from specguard_plugins import AnyOf, Avoid, Sequence

import specguard as sg

initial_env = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))


def to_lean(s):  # type: ignore[no-untyped-def]
    """How far the pole is from leaning 0.1 rad to the right; at most 0.1 from upright."""
    return np.maximum(0.1 - s.theta, 0.0)


def to_upright(s):  # type: ignore[no-untyped-def]
    """How far the pole is from upright; at most 0.1 once leaned."""
    return np.abs(s.theta)


lean = sg.Goal("lean", theta=(0.1, None)).annotate(sg.Distance(to_lean, scale=0.1))
upright = sg.Goal("upright", theta=(-0.02, 0.02), omega=(-0.1, 0.1)).annotate(sg.Distance(to_upright, scale=0.1))
edges = AnyOf(sg.Goal("left_edge", x=(None, -2.0)), sg.Goal("right_edge", x=(2.0, None)), name="edges")
fallen = AnyOf(sg.Goal("back_down", theta=(None, -0.2)), sg.Goal("front_down", theta=(0.2, None)), name="fallen")

tree = Sequence(lean, upright, name="lean_and_catch").annotate(Avoid(edges, name="edges"), Avoid(fallen, name="fallen"))

# rl-zoo's tuned PPO for CartPole-v1.
ZOO_PPO: dict[str, Any] = {
    "n_steps": 32,
    "batch_size": 256,
    "gae_lambda": 0.8,
    "gamma": 0.98,
    "n_epochs": 20,
    "ent_coef": 0.0,
    "learning_rate": 1e-3,
    "clip_range": 0.2,
}
BUDGET = sg.Budget(timesteps=50_000, min_seeds=2, eval_episodes=30)
COMMON: dict[str, Any] = dict(budget=BUDGET, trainer=sg.SB3(hyperparameters=ZOO_PPO, n_envs=8))

specs: dict[str, sg.Spec] = {
    "lean_and_catch": sg.Spec(
        initial_env,
        tree,
        expect={"lean_and_catch": 0.8, "lean_and_catch:fallen": 0.8, "lean_and_catch:edges": 0.8},
        name="cartpole",
        **COMMON,
    )
}


if __name__ == "__main__":
    print(tree)
    print(sg.formula(tree))
