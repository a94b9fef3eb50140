"""Pendulum-v1, the paper's running example (docs/guide/case-studies.md, "Definitions"): swing up and hold it upright.

Run ``python example_specs/pendulum.py`` to print the trees, their reward
formulas and a short rollout of the constructed env.
"""

from __future__ import annotations

import dataclasses
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


# -- the specs, one refinement at a time (the paper's Figure 4 row; docs/guide/case-studies.md) -------------
#
# Budget: rl-zoo's tuned PPO for Pendulum (4 envs), at most 100k steps per run ((a): 200k, below). Under anytime
# verdicts (pytest --goal-specs) a run stops at the first tenth of its budget where every threshold is met.
# Measured figures are 2 seeds x 30 deterministic evaluation episodes on the 2-core development machine.
ZOO_PPO: dict[str, object] = {
    "n_steps": 1024,
    "gamma": 0.9,
    "learning_rate": 1e-3,
    "use_sde": True,
    "sde_sample_freq": 4,
    # Adam's fused CPU kernel (one call per update, not a loop over the tensors): 12k steps of (w) 9.1 s against
    # 11.0 s on the 2-core development machine.
    "policy_kwargs": {"optimizer_kwargs": {"fused": True}},
}
BUDGET = sg.Budget(timesteps=100_000, min_seeds=2, eval_episodes=30)
COMMON: dict[str, Any] = dict(budget=BUDGET, trainer=sg.SB3(hyperparameters=ZOO_PPO, n_envs=4))

trees: dict[str, sg.Node] = {}
specs: dict[str, sg.Spec] = {}

# (a) One leaf: the intersection of both goals, rewarded only when entered.
# Paper: 8 of 10 runs. Measured on the AMD EPYC development machine: 30/30 in both seeds, met at 90k and 40k.
# On an Intel Xeon 2-core machine (2026-11-28; torch's CPU kernels differ, so the same seeds train other agents),
# at a 100k ceiling seed 0 reached 2/30 and a third seed 88/120, so the main job failed there; with a 200k
# ceiling both seeds meet the threshold at a checkpoint (164 s of training for both). A ceiling, not a cost:
# anytime verdicts stop each run at its first checkpoint with every threshold met.
trees["a"] = sg.Goal("pendulum", x=(0.966, 1.0), y=(-0.259, 0.259), omega=(-0.25, 0.25))
specs["a"] = sg.Spec(
    initial_env,
    trees["a"],
    expect={"pendulum": 0.8},
    name="pendulum-a",
    **{**COMMON, "budget": dataclasses.replace(BUDGET, timesteps=200_000)},
)

# (b) (a) refined by All into its two goals, each rewarded on its own (weights 1/2).
# Paper: half the runs stabilise without reaching the position. Measured: 17% and 43% at 100k.
trees["b"] = sg.All(position, stabilization, name="pendulum")
specs["b"] = sg.Spec(
    initial_env,
    trees["b"],
    expect={"pendulum": 0.8, "stabilization": 0.8},
    xfail={"pendulum": "paper: half the runs stabilise without reaching the position"},
    name="pendulum-b",
    **COMMON,
)

# (c) (b) with a distance to the position: shaping towards the top.
# Paper: helps, but only the weights resolve the conflict. Measured: 83% and 87% at 100k.
trees["c"] = sg.All(near_position, stabilization, name="pendulum")
specs["c"] = sg.Spec(
    initial_env,
    trees["c"],
    expect={"pendulum": 0.6},
    xfail={"pendulum": "paper: the distance helps, only the weights resolve the conflict"},
    name="pendulum-c",
    **COMMON,
)

# (w) (c) with the paper's manual weights, position 0.8 and stabilization 0.2.
# Paper: more precise than the baseline. Measured: 100% in both seeds at 100k.
trees["w"] = sg.All(near_position, stabilization, name="pendulum", weights=(0.8, 0.2))
specs["w"] = sg.Spec(initial_env, trees["w"], expect={"pendulum": 0.8, "position": 0.8}, name="pendulum-w", **COMMON)

# (auto) (c) with weights="auto" (beyond the paper): no hand tuning, the weights adapt to the children's
# success during training (specguard.training.auto_weights).
# Measured at 100k, 5 seeds x 30-120 episodes: the adapted weights approach the manual ones, position 0.71 to
# 0.82 and stabilization 0.18 to 0.29 at the end, but only once the agent starts to hang still, after 40k-60k
# steps (until then both goals fail together and the weights stay near 1/2); root goal 99/120, 87/120, 17/30,
# 94/120, 95/120 (77% pooled; (w) 86%), so 1 of 5 seeds reaches 0.8. A window of 40 episodes instead of
# 100 reacts no sooner (92/120, 36/60, 17/30, 97/120), and a lower floor changes nothing: 0.05 gave 97, 92, 88,
# 95, 92 of 120 and 0.02 gave 99, 93, 86, 95, 93 of 120 (77% each, 1 of 5 seeds), with position 0.85-0.95 at
# the end. Both children are missed together for the first 30k-40k steps, so success cannot favour the
# position then, and the policy learned under equal weights plateaus.
trees["auto"] = sg.All(near_position, stabilization, name="pendulum", weights="auto")
specs["auto"] = sg.Spec(
    initial_env,
    trees["auto"],
    expect={"pendulum": 0.8, "position": 0.8},
    xfail={"pendulum": "measured: 1 of 5 seeds at 100k; the weights adapt only after 40k-60k steps"},
    name="pendulum-auto",
    **COMMON,
)

# The baseline: Pendulum-v1's own reward, judged by the same goals.
# Paper: consistent. Measured: 100% in both seeds at 100k.
specs["baseline"] = sg.Spec(
    initial_env, trees["w"], expect={"pendulum": 0.8}, baseline=True, name="pendulum-baseline", **COMMON
)

# The paper's reported results, beside ours in docs/reproduction.md.
PAPER = {
    "a": "8/10 runs",
    "b": "position in half the runs",
    "c": "distance helps; weights needed",
    "w": "more precise than baseline",
    "auto": "- (beyond the paper)",
    "baseline": "consistent",
}


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
