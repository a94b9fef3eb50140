"""The one goal-name resolver and the one threshold rule, shared by Spec, @goal_spec and the plugin."""

from __future__ import annotations

import math
import re

import pytest

import specguard as sg
from example_specs import pendulum
from specguard.gate import with_thresholds
from specguard.goals import ROOT, check_threshold, resolve_goal

TREE = sg.All(
    sg.All(sg.Goal("x", a=(0, 1)), name="left"),
    sg.All(sg.Goal("x", a=(1, 2)), name="right"),
    sg.Goal("root", a=(None, 3)),  # a child named "root" is just a child
    sg.Goal("task", a=(None, 4)),  # a child named like the root
    name="task",
)


@pytest.mark.parametrize(
    ("key", "path"),
    [
        (ROOT, "task"),
        ("task", "task"),  # the root's path wins over the child's name
        ("task/task", "task/task"),
        ("root", "task/root"),
        ("left", "task/left"),
        ("task/left/x", "task/left/x"),
    ],
)
def test_resolve_goal(key, path):
    assert resolve_goal(TREE, key, "here") == path


def test_resolve_goal_errors_name_the_place_and_the_paths():
    with pytest.raises(sg.InvalidSpec, match=r"here: the name 'x' is ambiguous; use one of the paths task/left/x, "):
        resolve_goal(TREE, "x", "here")
    with pytest.raises(sg.InvalidSpec, match=r"here: no node is named 'y'; the tree's goals are task, task/left"):
        resolve_goal(TREE, "y", "here")


def spec(**kwargs):
    return sg.Spec(pendulum.initial_env, TREE_SPEC, budget=sg.Budget(timesteps=10), **kwargs)


TREE_SPEC = sg.All(sg.Goal("root", x=(0.9, 1)), sg.Goal("pendulum", omega=(-1, 1)), name="pendulum")


@pytest.mark.parametrize("key", ["root", "pendulum", "pendulum/pendulum", ROOT])
def test_spec_and_goal_spec_resolve_alike(key):
    # Before one resolver, "root" meant the root goal to @goal_spec and the child named "root" to Spec.
    from_spec = spec(expect={key: 0.5}).thresholds
    from_decorator = with_thresholds(spec(), {key: 0.5}, None)[0].thresholds
    assert from_spec == from_decorator
    assert spec(expect=0.5).thresholds == with_thresholds(spec(), {ROOT: 0.5}, None)[0].thresholds == {"pendulum": 0.5}


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (1.0, r"a threshold of 1 can never be met: a run meets a threshold when its whole confidence interval"),
        (1.5, r"expected a success rate in \[0, 1\), got 1.5"),
        (-0.1, r"expected a success rate in \[0, 1\), got -0.1"),
        (math.nan, r"expected a success rate in \[0, 1\), got nan"),
        (True, r"expected a success rate in \[0, 1\), got True"),
        ("0.5", r"expected a success rate in \[0, 1\), got '0.5'"),
    ],
)
def test_one_threshold_rule_everywhere(value, message):
    with pytest.raises(sg.InvalidSpec, match=message):
        check_threshold("here", value)
    with pytest.raises(sg.InvalidSpec, match=message):
        spec(expect={"root": value})
    declared = sg.goal_spec(expect={"root": value})(_a_test)
    assert re.search(message, declared.pytestmark[-1].kwargs["error"])


def test_thresholds_in_range_are_floats():
    assert check_threshold("here", 0) == 0.0 and isinstance(check_threshold("here", 0), float)
    assert check_threshold("here", 0.95) == 0.95


def test_root_key_survives_pickling():
    import pickle

    assert pickle.loads(pickle.dumps(ROOT)) is ROOT


def _a_test():
    """A function for @goal_spec to decorate (pytest marks only functions that look like tests)."""
