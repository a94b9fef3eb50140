"""The one goal-name resolver and the one threshold rule, shared by Spec, @goal_spec and the plugin."""

from __future__ import annotations

import math
import re

import pytest

import specguard as sg
from example_specs import pendulum
from specguard.pytest_plugin.judge import with_thresholds
from specguard.tree.keys import (
    ROOT,
    XFAIL_REASON,
    check_expect,
    check_threshold,
    check_xfail,
    check_xfail_thresholded,
    require_thresholds,
    resolve_goal,
)

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
    with pytest.raises(
        sg.error.InvalidSpec, match=r"here: the name 'x' is ambiguous; use one of the paths task/left/x, "
    ):
        resolve_goal(TREE, "x", "here")
    with pytest.raises(sg.error.InvalidSpec, match=r"here: no node is named 'y'; the tree's goals are task, task/left"):
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
    with pytest.raises(sg.error.InvalidSpec, match=message):
        check_threshold("here", value)
    with pytest.raises(sg.error.InvalidSpec, match=message):
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


# -- expect and xfail: one reading for Spec and @goal_spec ------------------------------------------------------


def test_expect_is_a_mapping_or_one_number_for_the_root():
    assert check_expect("Here", 0.5) == {ROOT: 0.5}
    assert check_expect("Here", {"a": 0, "p/b": 0.25, ROOT: 0.5}) == {"a": 0.0, "p/b": 0.25, ROOT: 0.5}
    assert check_expect("Here", {}) == {}  # no thresholds: a Spec that only measures, or gets them from @goal_spec


@pytest.mark.parametrize(
    ("expect", "message"),
    [
        ("high", r"Here: expected expect to be \{goal: min success\} or a number, got 'high'"),
        (True, r"Here: expected expect to be \{goal: min success\} or a number, got True"),
        (None, r"Here: expected expect to be \{goal: min success\} or a number, got None"),
        ([0.5], r"Here: expected expect to be \{goal: min success\} or a number, got \[0.5\]"),
        ({3: 0.5}, r"Here: expected goal names or paths as keys of expect, got 3"),
        ({"a": 1.5}, r"Here.expect\['a'\]: expected a success rate in \[0, 1\), got 1.5"),
    ],
)
def test_bad_expect(expect, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        check_expect("Here", expect)


def test_xfail_is_a_mapping_of_reasons_or_a_list_of_goals():
    assert check_xfail("Here", None) == {}
    assert check_xfail("Here", ["a", ROOT]) == {"a": XFAIL_REASON, ROOT: XFAIL_REASON}
    assert check_xfail("Here", ("a",)) == {"a": XFAIL_REASON}
    assert check_xfail("Here", {"p/a": "the paper's local optimum"}) == {"p/a": "the paper's local optimum"}


@pytest.mark.parametrize(
    ("xfail", "message"),
    [
        (3, r"Here: expected xfail to be \{goal: reason\} or a list of goals, got 3"),
        ("a", r"Here: expected xfail to be \{goal: reason\} or a list of goals, got 'a'"),
        ([3], r"Here: expected goal names or paths as keys of xfail, got 3"),
        ([["a"]], r"Here: expected goal names or paths as keys of xfail, got \['a'\]"),  # not a TypeError
        ({3: "why"}, r"Here: expected goal names or paths as keys of xfail, got 3"),
        ({"a": 3}, r"Here.xfail\['a'\]: expected the reason as non-empty text, got 3"),
        ({"a": " "}, r"Here.xfail\['a'\]: expected the reason as non-empty text, got ' '"),
    ],
)
def test_bad_xfail(xfail, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        check_xfail("Here", xfail)


def test_xfail_names_only_thresholded_goals():
    check_xfail_thresholded("Here", {"a": "why"}, {"a": 0.5, "b": 0.5})
    check_xfail_thresholded("Here", {}, {})
    message = r"Here: expected xfail to name goals that expect gives a threshold to \(\['a'\]\), got \['b'\]"
    with pytest.raises(sg.error.InvalidSpec, match=message):
        check_xfail_thresholded("Here", {"a": "why", "b": "why"}, {"a": 0.5})


def test_what_is_asserted_has_thresholds():
    require_thresholds("Here", {"a": 0.5})
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Here: expected at least one threshold, got \{\}: there is nothing to"
    ):
        require_thresholds("Here", {})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"expect": "high"}, r"expected expect to be \{goal: min success\} or a number, got 'high'"),
        ({"expect": {3: 0.5}}, r"expected goal names or paths as keys of expect, got 3"),
        ({"expect": 0.5, "xfail": 3}, r"expected xfail to be \{goal: reason\} or a list of goals, got 3"),
        # @goal_spec took any reason and any key, as str(...): an empty reason, 3 as a reason, the goal 3
        ({"expect": {"pendulum": 0.5}, "xfail": {"pendulum": ""}}, r"expected the reason as non-empty text, got ''"),
        ({"expect": {"pendulum": 0.5}, "xfail": {"pendulum": 3}}, r"expected the reason as non-empty text, got 3"),
        ({"expect": {"pendulum": 0.5}, "xfail": [3]}, r"expected goal names or paths as keys of xfail, got 3"),
        ({"expect": {"pendulum": 0.5}, "xfail": ["root"]}, r"expected xfail to name goals that expect gives a"),
    ],
)
def test_spec_and_goal_spec_read_expect_and_xfail_alike(kwargs, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        spec(**kwargs)
    declared = sg.goal_spec(**kwargs)(_a_test)
    assert re.search(message, declared.pytestmark[-1].kwargs["error"])


def test_an_empty_expect_measures_in_a_spec_and_is_refused_by_goal_spec():
    # A Spec may take its thresholds from @goal_spec, or only measure (specguard run);
    # @goal_spec(expect=None) already means "the Spec's own", so an empty expect there asserts nothing.
    assert spec(expect={}).thresholds == {}
    declared = sg.goal_spec(expect={})(_a_test)
    assert "expected at least one threshold, got {}" in declared.pytestmark[-1].kwargs["error"]


def test_a_spec_takes_xfail_as_a_list_of_goals_too():
    assert spec(expect={"pendulum": 0.5}, xfail=["pendulum"]).xfail == {"pendulum": XFAIL_REASON}
    assert sg.goal_spec(expect={"pendulum": 0.5}, xfail=["pendulum"])(_a_test).pytestmark[-1].kwargs["xfail"] == {
        "pendulum": XFAIL_REASON
    }


# -- safety rates: keys path:name of safety annotations, resolved by the same function --------------------------

CRASH = sg.Constraint(lambda s, a: s.a > 5, name="crash")
SAFE_TREE = sg.All(
    sg.Goal("up", a=(0, 1)).annotate(sg.Constraint(lambda s, a: False, name="spin")),
    sg.Goal("spin", a=(1, 2)),  # a node named like the constraint on "up"
    sg.Goal("near", a=(0, 2)).annotate(sg.Distance(abs, scale=1.0)),
    name="lunar",
).annotate(CRASH)


def test_safety_keys_are_path_colon_name_of_safety_annotations_only():
    from specguard.tree.keys import is_safety_key, kind, label, result_keys, safety_keys

    assert safety_keys(SAFE_TREE) == ["lunar:crash", "lunar/up:spin"]  # tree order; Distance has no rate
    assert result_keys(SAFE_TREE) == ["lunar", "lunar/up", "lunar/spin", "lunar/near", "lunar:crash", "lunar/up:spin"]
    assert safety_keys(TREE) == []
    assert is_safety_key("lunar:crash") and not is_safety_key("lunar/up")
    assert (kind("lunar:crash"), kind("lunar")) == ("safety", "goal")
    assert (label("lunar:crash"), label("lunar/up")) == ("lunar:crash (safe)", "lunar/up")


def test_every_annotation_whose_role_is_safety_gets_a_key():
    from specguard.extend import Annotation
    from specguard.tree.keys import resolve_goal, safety_keys

    class Guard(Annotation):  # a third party's constraint-like annotation: only its role matters, not its class
        role = "safety"

        def __init__(self, name):
            self.name, self.weight = name, None

    tree = sg.Goal("g", a=(0, 1)).annotate(Guard("guard"))
    assert safety_keys(tree) == ["g:guard"]
    assert resolve_goal(tree, "guard", "here") == "g:guard"


@pytest.mark.parametrize(
    ("key", "resolved"),
    [
        ("lunar:crash", "lunar:crash"),  # the full key
        ("crash", "lunar:crash"),  # a unique annotation name
        ("lunar/up:spin", "lunar/up:spin"),  # a full key wins over the ambiguous name "spin"
        ("lunar/spin", "lunar/spin"),
        (ROOT, "lunar"),
    ],
)
def test_resolve_safety_keys(key, resolved):
    assert resolve_goal(SAFE_TREE, key, "here") == resolved


def test_safety_key_errors_list_the_goals_and_the_safety_rates():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"here: the name 'spin' is ambiguous; use one of the keys lunar/spin, lunar/up:spin"
    ):
        resolve_goal(SAFE_TREE, "spin", "here")
    with pytest.raises(
        sg.error.InvalidSpec,
        match=r"here: no node or safety annotation is named 'lunar:crsh'; the tree's goals are lunar, lunar/up, "
        r"lunar/spin, lunar/near; its safety rates are lunar:crash, lunar/up:spin",
    ):
        resolve_goal(SAFE_TREE, "lunar:crsh", "here")
    with pytest.raises(
        sg.error.InvalidSpec, match=r"'lunar/near:distance' names an annotation that is not a safety"
    ) as e:
        resolve_goal(SAFE_TREE, "lunar/near:distance", "here")
    assert "not to shaping annotations such as Distance" in str(e.value)
    with pytest.raises(sg.error.InvalidSpec, match=r"'distance' names an annotation that is not a safety annotation"):
        resolve_goal(SAFE_TREE, "distance", "here")


def test_safety_thresholds_in_spec_and_goal_spec():
    cartpole = sg.InitialEnv("CartPole-v1", features=("a", "v", "theta", "omega"))
    tree = sg.All(sg.Goal("up", a=(0, 1)), name="lunar").annotate(CRASH)
    s = sg.Spec(cartpole, tree, budget=sg.Budget(timesteps=10), expect={"crash": 0.9, "lunar:crash": 0.8})
    assert s.thresholds == {"lunar:crash": 0.8}  # both name the same rate; the later one wins, as for goals
    spec_, paths = with_thresholds(sg.Spec(cartpole, tree, budget=sg.Budget(timesteps=10)), {"crash": 0.9}, "crash")
    assert spec_.thresholds == {"lunar:crash": 0.9} and paths == ["lunar:crash"]
    with pytest.raises(sg.error.InvalidSpec, match=r"expect\['lunar:crsh'\]: no node or safety annotation is named"):
        sg.Spec(cartpole, tree, budget=sg.Budget(timesteps=10), expect={"lunar:crsh": 0.9})
