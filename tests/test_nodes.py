"""Goal-tree nodes: construction, immutability, printing and validation errors."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import specguard as sg
from specguard.tree.nodes import component_weights


def dist(s):
    return abs(s.x)


def test_goal_records_inclusive_bounds_with_open_sides():
    g = sg.Goal("g", x=(0, 1), y=(None, 2), z=(-1, None), leg=1)
    assert g.bounds == (("x", 0.0, 1.0), ("y", -math.inf, 2.0), ("z", -1.0, math.inf), ("leg", 1.0, 1.0))
    assert repr(g) == "Goal('g', x=(0, 1), y=(None, 2), z=(-1, None), leg=(1, 1))"
    assert g.describe() == "Goal 'g': 0 <= x <= 1, y <= 2, z >= -1, leg == 1"


def test_numpy_numbers_are_numbers():
    g = sg.Goal("g", x=(np.float32(0.5), np.int64(2)))
    assert g.bounds == (("x", 0.5, 2.0),)
    assert sg.Constraint(lambda s, a: False, budget=np.int64(2)).budget == 2
    assert sg.Distance(abs, scale=np.float32(2.0)).scale == 2.0


def test_a_feature_may_be_called_name():
    assert sg.Goal("g", name=(0, 1)).bounds == (("name", 0.0, 1.0),)


def test_nodes_are_immutable_and_annotate_returns_a_new_node():
    g = sg.Goal("g", x=(0, 1))
    with pytest.raises(dataclasses.FrozenInstanceError):
        g.name = "h"  # type: ignore[misc]
    d = sg.Distance(dist, scale=2.0)
    annotated = g.annotate(d)
    assert g.annotations == ()
    assert annotated.annotations == (d,)
    assert annotated.bounds == g.bounds
    assert annotated != g
    assert g.annotate(d) == annotated  # equal values, equal nodes
    assert hash(g.annotate(d)) == hash(annotated)


def test_pretty_prints_the_tree():
    tree = sg.All(
        sg.Goal("position", x=(0.966, 1.0)).annotate(sg.Distance(dist, scale=2.0)),
        sg.All(sg.Goal("slow", omega=(-0.25, 0.25)), name="inner"),
        name="root",
        weights=(0.8, 0.2),
    ).annotate(sg.Constraint(lambda s, a: False, budget=3, name="crash"))
    assert str(tree) == "\n".join(
        [
            "All 'root' weights=(0.8, 0.2)",
            "│   + Constraint(<lambda>, budget=3, name='crash')",
            "├── Goal 'position': 0.966 <= x <= 1",
            "│       + Distance(dist, scale=2)",
            "└── All 'inner'",
            "    └── Goal 'slow': -0.25 <= omega <= 0.25",
        ]
    )
    assert repr(tree).startswith("All(Goal('position', x=(0.966, 1)).annotate(Distance(dist, scale=2)), All(")


def test_walk_yields_paths_parents_first():
    tree = sg.All(sg.Goal("a", x=0), sg.All(sg.Goal("b", x=0), name="c"), name="r")
    assert [p for p, _ in tree.walk()] == ["r", "r/a", "r/c", "r/c/b"]


def test_component_weights_follow_spec():
    g = sg.Goal("g", x=(0, 1))
    assert component_weights(g) == (1.0, ())
    c = sg.Constraint(lambda s, a: False)
    d = sg.Distance(dist, scale=1.0)
    assert component_weights(g.annotate(d, c)) == (0.5, (0.5, 1.0))
    assert component_weights(g.annotate(sg.Distance(dist, scale=1.0, weight=3.0), c)) == (0.5, (3.0, 1.0))


# -- validation: one test per error -------------------------------------------------


def test_lo_greater_than_hi():
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal 'g', feature 'x': expected lo <= hi, got lo=2 > hi=1"):
        sg.Goal("g", x=(2, 1))


@pytest.mark.parametrize("bound", [(math.nan, 1), (0, math.nan)])
def test_nan_bounds(bound):
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal 'g', feature 'x': (lo|hi) is NaN"):
        sg.Goal("g", x=bound)


@pytest.mark.parametrize("bound", ["0..1", (0, 1, 2), ("a", 1)])
def test_malformed_bounds(bound):
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal 'g', feature 'x': expected"):
        sg.Goal("g", x=bound)


def test_goal_without_features():
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal 'g': expected at least one feature"):
        sg.Goal("g")


def test_empty_all():
    with pytest.raises(sg.error.InvalidSpec, match=r"All 'r': expected at least one child node, got none"):
        sg.All(name="r")


def test_wrong_number_of_weights():
    with pytest.raises(sg.error.InvalidSpec, match=r"All 'r': expected 2 weights \(one per child\), got 3"):
        sg.All(sg.Goal("a", x=0), sg.Goal("b", x=0), name="r", weights=(1, 2, 3))


def test_negative_weights():
    with pytest.raises(sg.error.InvalidSpec, match=r"All 'r', weight of 'b': expected a finite weight >= 0, got -1"):
        sg.All(sg.Goal("a", x=0), sg.Goal("b", x=0), name="r", weights=(1, -1))


def test_negative_annotation_weight():
    with pytest.raises(sg.error.InvalidSpec, match=r"Distance 'distance': expected a finite weight >= 0, got -0.5"):
        sg.Distance(dist, scale=1.0, weight=-0.5)


def test_duplicate_sibling_names():
    with pytest.raises(sg.error.InvalidSpec, match=r"All 'r': two children are named 'a'"):
        sg.All(sg.Goal("a", x=0), sg.Goal("a", y=0), name="r")


def test_duplicate_annotation_names():
    g = sg.Goal("g", x=0)
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal 'g': two annotations are named 'distance'"):
        g.annotate(sg.Distance(dist, scale=1.0), sg.Distance(dist, scale=2.0))


def test_non_node_child():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"All 'r': expected children to be nodes \(Goal, All, ...\), got 'a'"
    ):
        sg.All("a", name="r")  # type: ignore[arg-type]


def test_annotate_with_a_non_annotation():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Goal 'g': annotate\(\) expects annotations \(Distance, Constraint, ...\)"
    ):
        sg.Goal("g", x=0).annotate(dist)  # type: ignore[arg-type]


@pytest.mark.parametrize("scale", [0, -1.0, math.inf, math.nan])
def test_scale_must_be_positive(scale):
    with pytest.raises(sg.error.InvalidSpec, match=r"Distance 'distance': expected scale to be a finite number > 0"):
        sg.Distance(dist, scale=scale)


@pytest.mark.parametrize("budget", [0, -2, 1.5, True])
def test_budget_must_be_an_integer_at_least_one(budget):
    with pytest.raises(sg.error.InvalidSpec, match=r"Constraint 'crash': expected budget to be an integer >= 1"):
        sg.Constraint(lambda s, a: False, budget=budget, name="crash")


def test_functions_must_be_callable():
    with pytest.raises(sg.error.InvalidSpec, match=r"Distance 'distance': expected fn to be callable as fn\(s\)"):
        sg.Distance(1.0, scale=1.0)  # type: ignore[arg-type]
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Constraint 'constraint': expected fn to be callable as fn\(s, a\)"
    ):
        sg.Constraint("x > 1")  # type: ignore[arg-type]


@pytest.mark.parametrize("name", ["", "a/b", "a:b", 3])
def test_node_names_are_checked(name):
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal"):
        sg.Goal(name, x=0)


def test_errors_are_spec_errors_and_value_errors():
    with pytest.raises(sg.SpecError):
        sg.Goal("g", x=(2, 1))
    with pytest.raises(ValueError):
        sg.Goal("g", x=(2, 1))


@pytest.mark.parametrize(
    ("bound", "expected"),
    [((0, math.inf), (0.0, math.inf)), ((-math.inf, 1), (-math.inf, 1.0)), ((-math.inf, None), (-math.inf, math.inf))],
)
def test_infinite_bounds_are_open_sides(bound, expected):
    g = sg.Goal("g", x=bound, y=(0, 1))
    assert g.bounds[0] == ("x", *expected)
    assert repr(sg.Goal("g", x=(0, math.inf))) == "Goal('g', x=(0, None))"


@pytest.mark.parametrize(
    ("bound", "message"),
    [
        (math.inf, r"expected a finite exact value, got inf"),
        (-math.inf, r"expected a finite exact value, got -inf"),
        ((math.inf, None), r"expected lo to be finite \(or -inf or None for an open side\), got lo=inf"),
        ((None, -math.inf), r"expected hi to be finite \(or inf or None for an open side\), got hi=-inf"),
        ((math.inf, math.inf), r"expected lo to be finite .*, got lo=inf"),
    ],
)
def test_impossible_infinite_bounds(bound, message):
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal 'g', feature 'x': " + message) as info:
        sg.Goal("g", x=bound)
    assert "could never hold" in str(info.value)


@pytest.mark.parametrize("bound", [(None, None), (-math.inf, math.inf), (None, math.inf)])
def test_goal_must_bound_at_least_one_side(bound):
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Goal 'g': a goal must bound at least one side of one feature"
    ) as info:
        sg.Goal("g", x=bound, y=(None, None))
    assert "every state would satisfy it" in str(info.value)
    assert "x=(None, None), y=(None, None)" in str(info.value)


def test_goal_may_leave_some_features_open():
    g = sg.Goal("g", x=(0, None), y=(None, None))
    assert g.describe() == "Goal 'g': x >= 0, y unconstrained"


@pytest.mark.parametrize("weights", [(0, 0), (0.0, np.float64(0.0))])
def test_all_zero_weights(weights):
    with pytest.raises(sg.error.InvalidSpec, match=r"All 'r': expected at least one weight > 0, got weights=\(0, 0\)"):
        sg.All(sg.Goal("a", x=0), sg.Goal("b", x=0), name="r", weights=weights)


def test_some_zero_weights_and_zero_annotation_weights_are_allowed():
    assert sg.All(sg.Goal("a", x=0), sg.Goal("b", x=0), name="r", weights=(0, 1)).weights == (0.0, 1.0)
    assert sg.Distance(dist, scale=1.0, weight=0).weight == 0.0
    assert sg.Constraint(lambda s, a: False, weight=0).weight == 0.0


class _SneakyName(str):
    def __repr__(self):
        return "__import__('os')"

    def __format__(self, spec):
        return "sneaky"


def test_str_subclass_names_are_stored_as_plain_str():
    g = sg.Goal(_SneakyName("g"), x=0).annotate(sg.Distance(dist, scale=1.0, name=_SneakyName("d")))
    assert type(g.name) is str and type(g.annotations[0].name) is str
    assert type(sg.All(g, name=_SneakyName("r")).name) is str
    assert [p for p, _ in sg.All(g, name="r").walk()] == ["r", "r/g"]
