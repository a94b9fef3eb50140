"""MountainCarContinuous-v0 (SPEC.md section 5): reach the flag, arriving slowly."""

from __future__ import annotations

import specguard as sg

initial_env = sg.InitialEnv("MountainCarContinuous-v0", features=("x", "vel"))

position = sg.Goal("position", x=(0.45, 1.0))
velocity = sg.Goal("velocity", vel=(-0.03, 0.07))


def velocity_distance(s):  # type: ignore[no-untyped-def]
    """Distance to the top speed 0.07; at most 0.14 since |vel| <= 0.07."""
    return abs(s.vel - 0.07)


trees: dict[str, sg.Node] = {
    "a": sg.Goal("mountain_car", x=(0.45, 1.0), vel=(-0.03, 0.07)),
    "b": sg.All(position, velocity, name="mountain_car"),
    "c": sg.All(position, velocity.annotate(sg.Distance(velocity_distance, scale=0.14)), name="mountain_car"),
}

ppo_kwargs: dict[str, object] = {"use_sde": True}  # paper, Table 1

# PPO with use_sde at 50k steps; a plain implementation reached (SPEC.md
# section 5): baseline 100%, (a) 100%, (b) 0%, (c) one seed 100% one 0%.
BUDGET = sg.Budget(timesteps=50_000, min_seeds=2, eval_episodes=30)

specs: dict[str, sg.Spec] = {
    key: sg.Spec(initial_env, tree, budget=BUDGET, expect=0.8, hyperparameters=ppo_kwargs, name=f"mountain_car-{key}")
    for key, tree in trees.items()
}
specs["baseline"] = sg.Spec(
    initial_env,
    trees["c"],
    budget=BUDGET,
    expect=0.8,
    hyperparameters=ppo_kwargs,
    baseline=True,
    name="mountain_car-baseline",
)
