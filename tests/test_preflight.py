"""Static checks before training: goals no state can reach are refused, edge goals warn."""

from __future__ import annotations

import warnings

import pytest

import specguard as sg
from specguard.construction.compiled import compile_tree
from specguard.construction.env import make_baseline_env
from specguard.construction.preflight import check_goals_off_the_edge, check_goals_reachable, unreachable_reason
from specguard.engine.run_spec import run_spec
from specguard.error import InvalidSpec, UnreachableGoal

FEATURES = ("x", "v", "theta", "omega")


@pytest.fixture
def cartpole():
    return sg.InitialEnv("CartPole-v1", features=FEATURES)


def test_a_goal_outside_the_bounds_is_refused_naming_feature_box_and_bounds(cartpole):
    tree = sg.All(sg.Goal("far", x=(10, None)), sg.Goal("upright", theta=(-0.1, 0.1)), name="cartpole")
    with pytest.raises(UnreachableGoal) as e:
        sg.make_env(cartpole, tree)
    assert isinstance(e.value, InvalidSpec)
    assert e.value.where == "cartpole/far"  # the innermost node, not its parent
    assert "goal box x in [10, inf] lies outside the bounds of x, [-4.8, 4.8]" in str(e.value)
    assert "Hint: move the box of 'x' inside [-4.8, 4.8]" in str(e.value)
    with pytest.raises(UnreachableGoal, match="cartpole/far"):
        make_baseline_env(cartpole, tree)


def test_run_spec_refuses_before_training(cartpole, tmp_path):
    spec = sg.Spec(cartpole, sg.Goal("far", x=(10, None)), budget=sg.Budget(timesteps=64, min_seeds=1))
    cache = tmp_path / "cache"
    with pytest.raises(UnreachableGoal, match="far: goal box x in"):
        run_spec(spec, workers=1, cache_dir=cache, progress=None)
    assert not [p for p in cache.rglob("*") if p.is_file() and p.suffix != ".lock"]  # no run was stored


def test_a_goal_at_the_edge_of_the_bounds_warns_once_naming_it(cartpole):
    tree = sg.All(sg.Goal("edge", x=(4.8, None)), sg.Goal("slow", v=(-1, 1)), name="cartpole")
    with pytest.warns(UserWarning, match=r"edge of the feature bounds: cartpole/edge \(x in \[4.8, inf\]") as seen:
        sg.make_env(cartpole, tree).close()
    edge = [w for w in seen if "edge of the feature bounds" in str(w.message)]
    assert len(edge) == 1
    assert edge[0].filename == __file__  # the line that built the env, not one inside specguard


def test_a_goal_inside_the_bounds_passes_silently(cartpole):
    tree = sg.All(sg.Goal("centre", x=(-0.5, 0.5)), sg.Goal("exact", v=0.0), name="cartpole")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sg.make_env(cartpole, tree).close()
        sg.make_env(cartpole, sg.Goal("near_edge", x=(4.7, None))).close()
    assert unreachable_reason(cartpole, tree, "cartpole/centre") is None


def test_an_all_of_reachable_children_with_an_empty_intersection_is_refused(cartpole):
    tree = sg.All(sg.Goal("left", x=(-1.0, -0.5)), sg.Goal("right", x=(0.5, 1.0)), name="both")
    compiled = compile_tree(tree, FEATURES)
    low, high = (-4.8, -float("inf"), -0.42, -float("inf")), (4.8, float("inf"), 0.42, float("inf"))
    with pytest.raises(UnreachableGoal) as e:
        check_goals_reachable(compiled, low, high)
    assert e.value.where == "both"
    assert "children's boxes do not overlap on x: their intersection [0.5, -0.5] is empty" in str(e.value)
    with pytest.raises(UnreachableGoal, match="both"):
        sg.make_env(cartpole, tree)


def test_bounds_given_by_the_initial_env_are_checked():
    env = sg.InitialEnv("CartPole-v1", features=FEATURES, bounds={"v": (-3.0, 3.0)})
    with pytest.raises(UnreachableGoal, match=r"v in \[-inf, -5\] lies outside the bounds of v, \[-3, 3\]"):
        sg.make_env(env, sg.Goal("fast_back", v=(None, -5.0)))
    compiled = compile_tree(sg.Goal("fast", v=(3.0, None)), FEATURES)
    with pytest.warns(UserWarning, match="fast"):
        check_goals_off_the_edge(compiled, (-4.8, -3.0, -0.42, -1.0), (4.8, 3.0, 0.42, 1.0))


def test_an_exact_value_at_a_bound_is_deliberate_and_does_not_warn():
    compiled = compile_tree(sg.Goal("legs", leg=1.0), ("leg",))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_goals_off_the_edge(compiled, (0.0,), (1.0,))
        check_goals_reachable(compiled, (0.0,), (1.0,))


def test_an_unreachable_alternative_of_an_or_warns_instead_of_refusing_the_spec():
    from example_specs.at_least import AtLeast

    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    tree = AtLeast(1, sg.Goal("far", x=(10, None)), sg.Goal("left", x=(None, -1)), name="any")
    with pytest.warns(UserWarning, match=r"any/far: goal box x in \[10, inf\] lies outside .*; any is not a box"):
        env = sg.make_env(cartpole, tree)
    env.close()
    with pytest.raises(
        sg.error.UnreachableGoal, match=r"any/far"
    ):  # the same alternative under an All: the root never holds
        sg.make_env(cartpole, sg.All(sg.Goal("far", x=(10, None)), sg.Goal("left", x=(None, -1)), name="any"))
