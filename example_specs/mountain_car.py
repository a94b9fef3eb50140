"""MountainCarContinuous-v0 (docs/guide/case-studies.md, "Definitions"): reach the flag, arriving slowly."""

from __future__ import annotations

from typing import Any

import specguard as sg

initial_env = sg.InitialEnv("MountainCarContinuous-v0", features=("x", "vel"))

position = sg.Goal("position", x=(0.45, 1.0))
velocity = sg.Goal("velocity", vel=(-0.03, 0.07))


def velocity_distance(s):  # type: ignore[no-untyped-def]
    """Distance to the top speed 0.07; at most 0.14 since |vel| <= 0.07."""
    return abs(s.vel - 0.07)


# -- the specs, one refinement at a time (the paper's Figure 4 row; docs/guide/case-studies.md) -------------
#
# Budget: PPO with use_sde (paper, Table 1), at most 50k steps per run; under anytime verdicts a run stops
# at the first tenth of its budget where every threshold is met. Measured figures are 2 seeds x 30
# deterministic evaluation episodes on the 2-core development machine.
ppo_kwargs: dict[str, object] = {"use_sde": True}
BUDGET = sg.Budget(timesteps=50_000, min_seeds=2, eval_episodes=30)
COMMON: dict[str, Any] = dict(budget=BUDGET, trainer=sg.SB3(hyperparameters=ppo_kwargs))

trees: dict[str, sg.Node] = {}
specs: dict[str, sg.Spec] = {}

# (a) One leaf: at the flag, slowly.
# Paper: exploration fails in most runs of every spec. Measured: 46% at 50k.
trees["a"] = sg.Goal("mountain_car", x=(0.45, 1.0), vel=(-0.03, 0.07))
specs["a"] = sg.Spec(
    initial_env,
    trees["a"],
    expect={"mountain_car": 0.8},
    xfail={"mountain_car": "paper: exploration fails in most runs of every spec"},
    name="mountain_car-a",
    **COMMON,
)

# (b) (a) refined by All into position and velocity.
# Measured: 0% in both seeds at 50k.
trees["b"] = sg.All(position, velocity, name="mountain_car")
specs["b"] = sg.Spec(
    initial_env,
    trees["b"],
    expect={"mountain_car": 0.8},
    xfail={"mountain_car": "measured 0% at 50k steps"},
    name="mountain_car-b",
    **COMMON,
)

# (c) (b) with a distance to the top speed: shaping towards building momentum.
# Paper: reached in about 6 of 10 runs. Measured: 2 of 10 seeds (0-9) at the end of 50k steps
# (docs/reproduction.md). Judged at checkpoints (anytime verdicts), whether both of 2 seeds meet it depends
# on the machine's floating-point kernels: on an AMD EPYC both did (30/30 at 30k and 5k steps), on an Intel
# Xeon seed 0 never did (0/30 at every checkpoint up to 51k) with the same code, seeds and packages. A
# goal that passes or fails by the CPU it trains on is the paper's negative result, not a test: xfail.
trees["c"] = sg.All(position, velocity.annotate(sg.Distance(velocity_distance, scale=0.14)), name="mountain_car")
specs["c"] = sg.Spec(
    initial_env,
    trees["c"],
    expect={"mountain_car": 0.8},
    xfail={"mountain_car": "paper: reached in about 6 of 10 runs; measured 2 of 10 at 50k steps"},
    name="mountain_car-c",
    **COMMON,
)

# (c+) (c) with exploration settings (beyond the paper): gSDE noise resampled every 64 steps instead of once
# per rollout, so one episode tries several pushing patterns; a discount close to 1, so reaching the flag
# late in a 999-step episode still counts; observations and rewards normalised (rl-zoo's MountainCar setting).
# Measured: 10 of 10 seeds (0-9) reach the flag in 30/30 evaluation episodes at the end of 50k steps, where
# (c) with the paper's settings reaches it in 1 of 5. Also tried on seeds 0-9 at 50k: 8 envs x 256 steps
# with gSDE once per rollout 9/10 (seed 1 0/30); earlier, gamma 0.9999 alone 2/5, with normalisation 6/10,
# with log_std_init 0.5 besides 5/10, no gSDE with ent_coef 0.01 0/10.
EXPLORE: dict[str, object] = {"use_sde": True, "sde_sample_freq": 64, "gamma": 0.9999}
specs["c+"] = sg.Spec(
    initial_env,
    trees["c"],
    expect={"mountain_car": 0.8},
    name="mountain_car-c+",
    budget=BUDGET,
    trainer=sg.SB3(hyperparameters=EXPLORE, normalize=True),
)

# The baseline: MountainCarContinuous-v0's own reward (+100 at the flag, minus the energy spent).
# Paper: 4 of 10 runs. Measured: 100% in both seeds at 50k.
specs["baseline"] = sg.Spec(
    initial_env, trees["c"], expect={"mountain_car": 0.8}, baseline=True, name="mountain_car-baseline", **COMMON
)

# The paper's reported results, beside ours in docs/reproduction.md.
PAPER = {
    "a": "fails in most runs",
    "b": "fails in most runs",
    "c": "6/10 runs",
    "c+": "- (beyond the paper)",
    "baseline": "4/10 runs",
}
