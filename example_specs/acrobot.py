"""Acrobot-v1 (docs/guide/case-studies.md, "Definitions"): swing the tip above the bar.

The height of the tip is not an observation, so ``state()`` appends it:
``height = -cos(t1) - cos(t1 + t2)``, from the observed cosines and sines.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

import specguard as sg

FEATURES = ("cos1", "sin1", "cos2", "sin2", "omega1", "omega2", "height")


def with_height(obs: np.ndarray) -> list[float]:
    """The six observations followed by the tip height (cos(t1+t2) = cos1 cos2 - sin1 sin2)."""
    cos1, sin1, cos2, sin2, omega1, omega2 = obs.tolist()
    return [cos1, sin1, cos2, sin2, omega1, omega2, -cos1 - (cos1 * cos2 - sin1 * sin2)]


initial_env = sg.InitialEnv(
    "Acrobot-v1",
    features=FEATURES,
    state=with_height,
    # Acrobot-v1's observation bounds, and the height's range [-2, 2].
    bounds={
        "cos1": (-1.0, 1.0),
        "sin1": (-1.0, 1.0),
        "cos2": (-1.0, 1.0),
        "sin2": (-1.0, 1.0),
        "omega1": (-4 * math.pi, 4 * math.pi),
        "omega2": (-9 * math.pi, 9 * math.pi),
        "height": (-2.0, 2.0),
    },
)


def height_distance(s):  # type: ignore[no-untyped-def]
    """Distance to the middle of the goal band; at most 3.5 since height >= -2."""
    return abs(s.height - 1.5)


# -- the specs, one refinement at a time (the paper's Figure 4 row; docs/guide/case-studies.md) -------------
#
# Budget: rl-zoo's PPO for Acrobot (16 envs, observations and rewards normalised by VecNormalize), at
# most 150k steps per run; under anytime verdicts a run stops at the first tenth of its budget where every
# threshold is met. Measured figures are 2 seeds x 30 deterministic evaluation episodes on the 2-core
# development machine. Without rl-zoo's normalisation, (c) reached only 105/120 (88%) in seed 0 at 150k:
# too close to its threshold of 0.8 to be judged met once every look is counted; with it both seeds
# reach the goal in 30/30 episodes at 15k and 30k steps.
ZOO_PPO: dict[str, object] = {"n_steps": 256, "gae_lambda": 0.94, "n_epochs": 4, "ent_coef": 0.0}
BUDGET = sg.Budget(timesteps=150_000, min_seeds=2, eval_episodes=30)
COMMON: dict[str, Any] = dict(budget=BUDGET, trainer=sg.SB3(hyperparameters=ZOO_PPO, n_envs=16, normalize=True))

height = sg.Goal("height", height=(1.0, 3.0))
trees: dict[str, sg.Node] = {}
specs: dict[str, sg.Spec] = {}

# (a) One leaf: the tip above the bar, rewarded only when entered (Acrobot has one goal: no (b)).
# Paper: found in about 6 of 10 runs. Measured: one seed 100%, one 0% at 150k.
trees["a"] = height
specs["a"] = sg.Spec(
    initial_env,
    trees["a"],
    expect={"height": 0.8},
    xfail={"height": "paper: the sparse goal is found in about 6 of 10 runs"},
    name="acrobot-a",
    **COMMON,
)

# (c) (a) with a distance to the middle of the goal band: shaping upwards.
# Paper: about the baseline. Measured: 100% in both seeds at 150k.
trees["c"] = height.annotate(sg.Distance(height_distance, scale=3.5))
specs["c"] = sg.Spec(initial_env, trees["c"], expect={"height": 0.8}, name="acrobot-c", **COMMON)

# The baseline: Acrobot-v1's own reward (-1 per step until the tip is up), judged by the same goal.
# Paper: about 100%. Measured: 100% in both seeds at 150k.
specs["baseline"] = sg.Spec(
    initial_env, trees["c"], expect={"height": 0.8}, baseline=True, name="acrobot-baseline", **COMMON
)

# The paper's reported results, beside ours in docs/reproduction.md.
PAPER = {"a": "about 6/10 runs", "c": "about the baseline", "baseline": "about 100%"}
