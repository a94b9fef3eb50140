"""The paper's four case studies, and a CartPole spec beyond them, as goal specs.

Run them with ``pytest --goal-specs example_specs``.

Thresholds follow what a plain implementation reached on a 2-core machine at
these budgets (SPEC.md section 5); goals the paper reports as not learned are
declared ``xfail``, so they report XFAIL, and XPASS once a change makes them pass.
Budgets are each module's ``BUDGET``; ``--goal-specs-budget-scale`` shrinks them.
"""

from __future__ import annotations

import specguard as sg
from example_specs import acrobot, cartpole, lunar_lander, mountain_car, pendulum

# -- Pendulum: rl-zoo PPO, 100k steps ------------------------------------------------


@sg.goal_spec(expect={"pendulum": 0.8})
def test_pendulum_baseline(pendulum_env, pendulum_trees):
    return sg.Spec(pendulum_env, pendulum_trees["w"], baseline=True, **pendulum.COMMON)


@sg.goal_spec(expect={"pendulum": 0.8})
def test_pendulum_single_goal(pendulum_env, pendulum_trees):
    return sg.Spec(pendulum_env, pendulum_trees["a"], **pendulum.COMMON)


@sg.goal_spec(
    expect={"pendulum": 0.8, "stabilization": 0.8},
    xfail={"pendulum": "paper: half the runs stabilise without reaching the position"},
)
def test_pendulum_refined(pendulum_env, pendulum_trees):
    return sg.Spec(pendulum_env, pendulum_trees["b"], **pendulum.COMMON)


@sg.goal_spec(
    expect={"pendulum": 0.6},
    xfail={"pendulum": "paper: the distance helps, only the weights resolve the conflict; measured 69% at 100k"},
)
def test_pendulum_distance(pendulum_env, pendulum_trees):
    return sg.Spec(pendulum_env, pendulum_trees["c"], **pendulum.COMMON)


@sg.goal_spec(expect={"pendulum": 0.8, "position": 0.8})
def test_pendulum_weighted(pendulum_env, pendulum_trees):
    return sg.Spec(pendulum_env, pendulum_trees["w"], **pendulum.COMMON)


# -- Acrobot: rl-zoo PPO, 16 envs, 150k steps ------------------------------------------


@sg.goal_spec(expect={"height": 0.8})
def test_acrobot_baseline(acrobot_env):
    return sg.Spec(acrobot_env, acrobot.trees["c"], baseline=True, **acrobot.COMMON)


@sg.goal_spec(expect={"height": 0.8}, xfail={"height": "paper: the sparse goal is found in about 6 of 10 runs"})
def test_acrobot_single_goal(acrobot_env):
    return sg.Spec(acrobot_env, acrobot.trees["a"], **acrobot.COMMON)


@sg.goal_spec(expect={"height": 0.8})
def test_acrobot_distance(acrobot_env):
    return sg.Spec(acrobot_env, acrobot.trees["c"], **acrobot.COMMON)


# -- MountainCarContinuous: PPO with use_sde, 50k steps --------------------------------


@sg.goal_spec(expect={"mountain_car": 0.8})
def test_mountain_car_baseline(mountain_car_env):
    return sg.Spec(mountain_car_env, mountain_car.trees["c"], baseline=True, **mountain_car.COMMON)


@sg.goal_spec(
    expect={"mountain_car": 0.8},
    xfail={"mountain_car": "paper: exploration fails in most runs of every spec; measured 46% at 50k"},
)
def test_mountain_car_single_goal(mountain_car_env):
    return sg.Spec(mountain_car_env, mountain_car.trees["a"], **mountain_car.COMMON)


@sg.goal_spec(expect={"mountain_car": 0.8}, xfail={"mountain_car": "measured 0% at 50k steps"})
def test_mountain_car_refined(mountain_car_env):
    return sg.Spec(mountain_car_env, mountain_car.trees["b"], **mountain_car.COMMON)


@sg.goal_spec(expect={"mountain_car": 0.8}, xfail={"mountain_car": "paper: reached in about 6 of 10 runs"})
def test_mountain_car_distance(mountain_car_env):
    return sg.Spec(mountain_car_env, mountain_car.trees["c"], **mountain_car.COMMON)


# -- LunarLander: rl-zoo PPO, 16 envs, 400k steps --------------------------------------


@sg.goal_spec(expect={"lander": 0.05})
def test_lunar_lander_baseline(lunar_lander_env):
    return sg.Spec(lunar_lander_env, lunar_lander.trees["w"], baseline=True, **lunar_lander.COMMON)


@sg.goal_spec(expect={"lander": 0.05}, xfail={"lander": "paper: the sparse single goal is not learned"})
def test_lunar_lander_single_goal(lunar_lander_env):
    return sg.Spec(lunar_lander_env, lunar_lander.trees["a"], **lunar_lander.COMMON)


@sg.goal_spec(expect={"lander": 0.05}, xfail={"lander": "paper: stabilises without landing"})
def test_lunar_lander_refined(lunar_lander_env):
    return sg.Spec(lunar_lander_env, lunar_lander.trees["b"], **lunar_lander.COMMON)


@sg.goal_spec(
    expect={"lander": 0.05},
    xfail={"lander": "paper: stabilises without landing; measured: stabilisation only, root 0% at 400k"},
)
def test_lunar_lander_distance(lunar_lander_env):
    return sg.Spec(lunar_lander_env, lunar_lander.trees["c"], **lunar_lander.COMMON)


@sg.goal_spec(expect={"lander": 0.05})
def test_lunar_lander_weighted(lunar_lander_env):
    return sg.Spec(lunar_lander_env, lunar_lander.trees["w"], **lunar_lander.COMMON)


# -- CartPole beyond the paper (plugins/: Sequence, Avoid, AnyOf): rl-zoo PPO, 8 envs, 50k steps ------------
# Measured on the 2-core development machine (2 seeds x 30 deterministic episodes): the root goal 30/30
# in both seeds, both safety rates (no edge, no fall) 30/30; about 35-40 s of training per seed.


@sg.goal_spec(expect={"lean_and_catch": 0.8, "lean_and_catch:fallen": 0.8, "lean_and_catch:edges": 0.8})
def test_cartpole_lean_and_catch():
    return sg.Spec(cartpole.initial_env, cartpole.tree, **cartpole.COMMON)
