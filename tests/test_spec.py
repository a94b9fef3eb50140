"""Spec: thresholds by path or name, and validation errors naming the spec and field."""

from __future__ import annotations

import numpy as np
import pytest

import specguard as sg
from example_specs import lunar_lander, pendulum

BUDGET = sg.Budget(timesteps=1000)


def spec(**kwargs):
    return sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=BUDGET, **kwargs)


def test_thresholds_resolve_names_to_paths():
    assert spec(expect={"position": 0.5, "pendulum": 0.8}).thresholds == {"pendulum/position": 0.5, "pendulum": 0.8}
    assert spec(expect=0.7).thresholds == {"pendulum": 0.7}
    assert spec().thresholds == {}


def test_quorum_defaults_to_every_run():
    assert spec().required_runs == 2
    assert sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(10, 2, 10), quorum=6).required_runs == 6


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"expect": {"pendulum": 1.5}}, r"Spec 'pendulum'.expect\['pendulum'\]: expected a success rate in \[0, 1\)"),
        ({"expect": {"pendulum": -0.1}}, r"expected a success rate in \[0, 1\), got -0.1"),
        ({"expect": {"pendulum": 1.0}}, r"a threshold of 1 can never be met: a run meets a threshold when"),
        (
            {"expect": {"height": 0.5}},
            r"expect\['height'\]: no node is named 'height'; the tree's goals are pendulum, pendulum/position",
        ),
        ({"expect": "high"}, r"Spec 'pendulum': expected expect to be \{goal: min success\} or a number, got 'high'"),
        ({"quorum": 3}, r"Spec 'pendulum': expected quorum <= budget.max_seeds=2 \(the runs trained\), got 3"),
        ({"quorum": 0}, r"Spec 'pendulum': expected quorum to be an integer >= 1 \(runs that must meet"),
        ({"confidence": 1.0}, r"Spec 'pendulum': expected confidence to be a number in \(0, 1\), got 1.0"),
        ({"undecided": "maybe"}, r"Spec 'pendulum': expected undecided to be one of fail, xfail, pass, got 'maybe'"),
    ],
)
def test_bad_specs(kwargs, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        spec(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"algorithm": "PPO2"}, r"^SB3.algorithm: unknown algorithm 'PPO2'; expected one of PPO, A2C"),
        ({"n_envs": 0}, r"^SB3: expected n_envs to be an integer >= 1 \(parallel environments"),
        ({"hyperparameters": [1]}, r"^SB3.hyperparameters: expected a mapping"),
        ({"normalize": "yes"}, r"^SB3.normalize: expected True or False, got 'yes'"),
        ({"tensorboard_log": 3}, r"^SB3: expected tensorboard_log to be a folder, got 3"),
    ],
)
def test_bad_sb3_settings_are_refused_where_the_trainer_is_made(kwargs, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        sg.SB3(**kwargs)


def test_counts_reach_the_shared_rule():
    # validation.check_count: numpy integers are integers, a bool is not a count
    s = spec(quorum=np.int64(2), trainer=sg.SB3(n_envs=np.int64(4)))
    assert (s.trainer.n_envs, s.quorum) == (4, 2) and type(s.trainer.n_envs) is int and type(s.quorum) is int
    with pytest.raises(sg.error.InvalidSpec, match=r"expected quorum to be an integer >= 1 .*got True"):
        spec(quorum=True)
    with pytest.raises(sg.error.InvalidSpec, match=r"expected n_envs to be an integer >= 1 .*got 2.0"):
        spec(trainer=sg.SB3(n_envs=2.0))


def test_ambiguous_names_ask_for_a_path():
    tree = sg.All(sg.All(sg.Goal("x", a=0), name="l"), sg.All(sg.Goal("x", a=1), name="r"), name="root")
    initial = sg.InitialEnv(lambda: None, features=("a",))
    with pytest.raises(
        sg.error.InvalidSpec, match=r"the name 'x' is ambiguous; use one of the paths root/l/x, root/r/x"
    ):
        sg.Spec(initial, tree, budget=BUDGET, expect={"x": 0.5})


def test_wrong_field_types():
    with pytest.raises(sg.error.InvalidSpec, match=r"\.budget: expected a Budget"):
        sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=1000)
    with pytest.raises(sg.error.InvalidSpec, match=r"\.initial_env: expected an InitialEnv"):
        sg.Spec("Pendulum-v1", pendulum.trees["w"], budget=BUDGET)
    with pytest.raises(sg.error.InvalidSpec, match=r"\.tree: expected a Goal or All node"):
        sg.Spec(lunar_lander.initial_env, "lander", budget=BUDGET)


def test_scaled_multiplies_the_training_budget_only():
    s = sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(timesteps=1000, min_seeds=3))
    assert s.scaled(1) is s
    half = s.scaled(0.5)
    assert half.budget.timesteps == 500 and half.budget.min_seeds == 3 and half.tree is s.tree


def test_xfail_names_thresholded_goals_and_resolves_them():
    spec = sg.Spec(
        pendulum.initial_env,
        pendulum.trees["b"],
        budget=sg.Budget(timesteps=10),
        expect={"pendulum": 0.8, "position": 0.5},
        xfail={"position": "the paper's local optimum"},
    )
    assert spec.xfail == {"pendulum/position": "the paper's local optimum"}
    with pytest.raises(
        sg.error.InvalidSpec,
        match=r"expected xfail to name goals that expect gives a threshold to \(\['pendulum'\]\), got",
    ):
        sg.Spec(
            pendulum.initial_env,
            pendulum.trees["b"],
            budget=sg.Budget(timesteps=10),
            expect=0.5,
            xfail={"stabilization": "x"},
        )
    with pytest.raises(
        sg.error.InvalidSpec, match=r"xfail\['pendulum'\]: expected the reason as non-empty text, got 3"
    ):
        sg.Spec(
            pendulum.initial_env, pendulum.trees["b"], budget=sg.Budget(timesteps=10), expect=0.5, xfail={"pendulum": 3}
        )
