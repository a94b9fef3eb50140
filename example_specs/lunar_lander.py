"""LunarLander-v3 (docs/guide/case-studies.md, "Definitions"): land softly, upright, on both legs, on the pad.

Every tree carries the crash constraint on its root (budget 1), which stands
for the crash penalty of the original reward.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

import specguard as sg

initial_env = sg.InitialEnv("LunarLander-v3", features=("x", "y", "vx", "vy", "angle", "angular_vel", "leg1", "leg2"))

BOUNDS = {
    "position": {"x": (-0.2, 0.2), "y": (-0.05, 0.05)},
    "velocity": {"vx": (-0.1, 0.1), "vy": (-0.1, 0.1)},
    "stabilization": {"angle": (-0.1, 0.1), "angular_vel": (-0.1, 0.1)},
    "legs": {"leg1": 1.0, "leg2": 1.0},
}


def crash(s, a):  # type: ignore[no-untyped-def]
    """Low and off the pad: the paper's misprinted C_Crash, read as docs/guide/case-studies.md says."""
    return abs(s.x) >= 0.2 and s.y <= 0.2


def position_distance(s):  # type: ignore[no-untyped-def]
    return np.hypot(s.x, s.y)


def velocity_distance(s):  # type: ignore[no-untyped-def]
    return np.hypot(s.vx, s.vy)


def stabilization_distance(s):  # type: ignore[no-untyped-def]
    return abs(s.angle)


no_crash = sg.Constraint(crash, budget=1, name="crash")
goals = {name: sg.Goal(name, **bounds) for name, bounds in BOUNDS.items()}
# Scales: the lander leaves the screen at |x| >= 1 and starts near y = 1.4, so it
# stays within about 2 of the pad; speeds above 2 are rare; the angle is at most pi.
distances = {
    "position": sg.Distance(position_distance, scale=2.0),
    "velocity": sg.Distance(velocity_distance, scale=2.0),
    "stabilization": sg.Distance(stabilization_distance, scale=math.pi),
}
near = [g.annotate(distances[n]) if n in distances else g for n, g in goals.items()]


# -- the specs, one refinement at a time (the paper's Figure 4 row; docs/guide/case-studies.md) -------------
#
# Budget: rl-zoo's tuned PPO for LunarLander (16 envs), as the paper uses it (Table 1), at most 1M steps
# per run (the paper trained LunarLander for 1M steps and more). Under anytime verdicts (pytest
# --goal-specs) a run stops at the first tenth of its budget where every threshold is met. Thresholds are
# floors (docs/guide/case-studies.md, "Thresholds"). Measured figures are 2 seeds x 30 deterministic
# evaluation episodes on the 2-core development machine, about 3 000 steps/s per seed.
ppo_kwargs: dict[str, object] = {
    "n_steps": 1024,
    "batch_size": 64,
    "n_epochs": 4,
    "gae_lambda": 0.98,
    "gamma": 0.999,
    "ent_coef": 0.01,
    # Adam's fused CPU kernel: the same update in one call per step instead of a Python loop over the network's
    # tensors (32k steps: 15.6 s against 18.3 s on the 2-core development machine).
    "policy_kwargs": {"optimizer_kwargs": {"fused": True}},
}
BUDGET = sg.Budget(timesteps=1_000_000, min_seeds=2, eval_episodes=30)
COMMON: dict[str, Any] = dict(budget=BUDGET, trainer=sg.SB3(hyperparameters=ppo_kwargs, n_envs=16))

trees: dict[str, sg.Node] = {}
specs: dict[str, sg.Spec] = {}

# (a) One leaf: every goal at once, rewarded only when entered; the crash constraint on the root.
# Paper: the sparse single goal is not learned.
trees["a"] = sg.Goal("lander", **{f: b for bounds in BOUNDS.values() for f, b in bounds.items()}).annotate(no_crash)
specs["a"] = sg.Spec(
    initial_env,
    trees["a"],
    expect={"lander": 0.05},
    xfail={"lander": "paper: the sparse single goal is not learned"},
    name="lunar_lander-a",
    **COMMON,
)

# (b) (a) refined by All into position, velocity, stabilisation and legs (weights 1/4).
# Paper: converges to stabilising without landing. Measured: 0% in both seeds at 400k.
trees["b"] = sg.All(*goals.values(), name="lander").annotate(no_crash)
specs["b"] = sg.Spec(
    initial_env,
    trees["b"],
    expect={"lander": 0.05},
    xfail={"lander": "paper: stabilises without landing"},
    name="lunar_lander-b",
    **COMMON,
)

# (c) (b) with distances to the pad, to rest and to upright.
# Paper: most runs stabilise without reaching the position. Measured: 30% and 23% at 400k.
trees["c"] = sg.All(*near, name="lander").annotate(no_crash)
specs["c"] = sg.Spec(
    initial_env,
    trees["c"],
    expect={"lander": 0.05},
    xfail={"lander": "paper: stabilises without landing in most runs"},
    name="lunar_lander-c",
    **COMMON,
)

# (w) (c) with the paper's manual weights: position 200, velocity 100, stabilisation 50, legs 20.
# Paper: more precise than the baseline.
# Measured (why it missed at 400k, and what changed): at 400k both seeds reach the pad (position 15/30 and
# 30/30) but touch down too fast or tilted (velocity 14/30 and 7/30, stabilisation 8/30 and 9/30), so the
# root goal holds at the end of 0/30 and 5/30 episodes. The crash constraint (specguard's reading of the
# paper's, docs/guide/case-studies.md) punishes only low states off the pad, so a hard touchdown on the pad
# costs nothing but the velocity and stabilisation goals, and soft, level landings come late: between 500k
# and 700k steps.
# Root goal per 100k checkpoint, seeds 0 / 1: 400k 0 / 5, 500k 17 / 8, 600k 14 / 2, 700k 18 / 19,
# 800k 6 / 5, 900k 12 / 3, 1M 7 / 3 (of 30). Landing quality swings from checkpoint to checkpoint, so one
# judgment at a fixed budget is a coin toss; judged at checkpoints, both seeds meet the floor at 500k
# (17/30 and 8/30), where their training stops.
trees["w"] = sg.All(*near, name="lander", weights=(200, 100, 50, 20)).annotate(no_crash)
specs["w"] = sg.Spec(initial_env, trees["w"], expect={"lander": 0.05}, name="lunar_lander-w", **COMMON)

# (auto) (c) with weights="auto" (beyond the paper): the weights of the children and of the crash constraint
# adapt to their success during training (specguard.training.auto_weights) instead of the paper's hand-tuned
# 200/100/50/20. Measured at 1M steps, 5 seeds x 30 episodes (docs/reproduction.md, "weights"): root goal
# 20, 8, 14, 8, 17 of 30 (45%; (w) 37%, 5/5 each), crash-free 30, 15, 25, 20, 30 of 30 (80%; (w) 99%).
# Weights at the end: position 0.09-0.25, velocity 0.26-0.32, stabilisation 0.05-0.31, legs 0.15-0.26,
# crash 0.09-0.20. When only the children adapted (the crash penalty fixed at 1), the agent learnt
# first never to crash, hovering, and landed in 4% (1 of 5 seeds). In the main job (judged every 100k): met
# at 800k and 300k (13/30 and 7/30), 253 s of training for both seeds.
trees["auto"] = sg.All(*near, name="lander", weights="auto").annotate(no_crash)
specs["auto"] = sg.Spec(initial_env, trees["auto"], expect={"lander": 0.05}, name="lunar_lander-auto", **COMMON)

# The baseline: LunarLander-v3's own reward (shaping, leg contact, -100 for a crash, +100 at rest).
# Paper: about 80% on the root goal. Measured: 53% and 0% at 400k.
specs["baseline"] = sg.Spec(
    initial_env, trees["w"], expect={"lander": 0.05}, baseline=True, name="lunar_lander-baseline", **COMMON
)

# The paper's reported results, beside ours in docs/reproduction.md.
PAPER = {
    "a": "not learned",
    "b": "stabilises without landing",
    "c": "stabilises without landing (most runs)",
    "w": "more precise than baseline",
    "auto": "- (beyond the paper)",
    "baseline": "about 80%",
}
