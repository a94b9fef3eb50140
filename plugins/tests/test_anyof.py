"""AnyOf: the union goal, its once-only core reward, what it passes on of its children."""

from __future__ import annotations

import math
from collections import namedtuple

import pytest
from hypothesis import given
from hypothesis import strategies as st
from specguard_plugins import AnyOf, Avoid, Sequence

import specguard as sg
from specguard import strategies as sgst
from specguard.construction.reference import ExtendedState, process
from specguard.error import InvalidSpec
from specguard.extend import ChildWeights, Context

from .helpers import both_checkers, replay, rewards

FEATURES = ("a", "b", "c")
State = namedtuple("State", FEATURES)


def dist_to_2(s):
    return abs(s.x - 2.0)


def test_two_overlapping_children_pay_the_union_once_and_reentry_is_paid_again_only_after_leaving():
    wide, narrow = sg.Goal("wide", x=(1.0, 3.0)), sg.Goal("narrow", x=(2.0, 4.0))
    never = sg.Goal("never", y=(10.0, None))  # keeps the root goal out of reach
    tree = sg.All(AnyOf(wide, narrow, name="any"), never, name="root")
    # x: 0 -> 2.5 (both) -> 3.5 (narrow only) -> 0 (none) -> 1.5 (wide only) -> 2.5 (both)
    trajectory = [[0.0, 0.0], [2.5, 0.0], [3.5, 0.0], [0.0, 0.0], [1.5, 0.0], [2.5, 0.0]]
    info0, steps = replay(tree, trajectory, features=("x", "y"))
    assert info0["goals"] == {
        "root": False,
        "root/any": False,
        "root/any/wide": False,
        "root/any/narrow": False,
        "root/never": False,
    }
    # All passes 1/2 of everything: the AnyOf's own term is 1/2 * (1[s' in G] - 1[s in G]).
    assert rewards(steps) == [0.5, 0.0, -0.5, 0.5, 0.0]
    assert steps[0][4]["reward_terms"] == {
        "root/any/wide": 0.0,
        "root/any/narrow": 0.0,
        "root/any": 0.5,
        "root/never": 0.0,
    }
    assert [s[4]["goals"]["root/any"] for s in steps] == [True, True, False, True, True]
    assert [s[4]["goals"]["root/any/narrow"] for s in steps] == [True, True, False, False, True]
    assert [s[2:4] for s in steps] == [(False, False)] * 4 + [(False, True)]  # truncated by the replay, never ended
    assert sum(rewards(steps)) == 0.5  # 1/2 * (1[s_T in G] - 1[s_0 in G])


def test_at_the_root_entering_the_union_pays_one_and_ends_the_episode():
    tree = AnyOf(sg.Goal("wide", x=(1.0, 3.0)), sg.Goal("narrow", x=(2.0, 3.0)), name="reach")
    _, steps = replay(tree, [[0.0], [2.5], [0.0]])
    assert len(steps) == 1
    obs, reward, terminated, truncated, info = steps[0]
    assert (reward, terminated, truncated) == (1.0, True, False)
    assert info["reward_terms"] == {"reach/wide": 0.0, "reach/narrow": 0.0, "reach": 1.0}
    assert info["goals"] == {"reach": True, "reach/wide": True, "reach/narrow": True}
    assert obs == [2.5]  # no own state


def test_starting_inside_pays_nothing_and_leaving_costs_one():
    edge = AnyOf(sg.Goal("l", x=(None, -1.0)), sg.Goal("r", x=(1.0, None)), name="edge")
    tree = sg.All(edge, sg.Goal("never", x=(100.0, None)), name="root")
    _, steps = replay(tree, [[2.0], [-2.0], [0.0]])
    # 2 -> -2 switches child without leaving the union: nothing; -2 -> 0 leaves it.
    assert rewards(steps) == [0.0, -0.5]


def test_children_keep_their_distances_and_penalties_but_not_their_goal_rewards():
    near = sg.Goal("near", x=(2.0, 2.0)).annotate(
        sg.Distance(dist_to_2, scale=4.0), sg.Constraint(lambda s, a: s.x < -1.0, budget=1)
    )
    tree = AnyOf(near, sg.Goal("far", x=(10.0, None)), name="any")
    info0, steps = replay(tree, [[0.0], [1.0], [-2.0], [0.0], [2.0]])
    assert info0["safe"] == {"any/near:constraint": True}
    # near's components: core 1/2 (not passed on: core weight 0), distance 1/2, constraint 1 (not normalised).
    assert steps[0][4]["reward_terms"] == {
        "any/near": 0.0,
        "any/near:distance": 0.5 * (2.0 - 1.0) / 4.0,
        "any/near:constraint": 0.0,
        "any/far": 0.0,
        "any": 0.0,
    }
    # The constraint judges (s, a): the step from x=-2 violates; the budget of 1 ends the episode there.
    assert rewards(steps) == [0.125, 0.5 * (1.0 - 4.0) / 4.0, 0.5 * (4.0 - 2.0) / 4.0 - 1.0]
    assert [s[0] for s in steps] == [[1.0, 1.0], [-2.0, 1.0], [0.0, 0.0]]  # x, then the counter
    assert [s[2] for s in steps] == [False, False, True]
    assert [s[4]["safe"]["any/near:constraint"] for s in steps] == [True, True, False]


def test_a_child_goal_reached_inside_the_union_pays_only_the_union():
    near = sg.Goal("near", x=(2.0, 2.0))
    tree = sg.All(
        AnyOf(near, sg.Goal("far", x=(10.0, None)), name="any"), sg.Goal("never", x=(None, -9.0)), name="root"
    )
    _, steps = replay(tree, [[0.0], [2.0], [10.0], [0.0]])
    assert [s[4]["reward_terms"]["root/any/near"] for s in steps] == [0.0, 0.0, 0.0]
    assert [s[4]["reward_terms"]["root/any/far"] for s in steps] == [0.0, 0.0, 0.0]
    assert rewards(steps) == [0.5, 0.0, -0.5]


def test_weights_scale_the_childrens_distances_and_penalties_never_their_goal_rewards():
    a = sg.Goal("a", x=(5.0, None)).annotate(sg.Distance(dist_to_2, scale=1.0, weight=1.0))
    b = sg.Goal("b", x=(None, -5.0)).annotate(Avoid({"x": (1.0, None)}, budget=3))
    tree = AnyOf(a, b, name="any", weights=(3.0, 0.5))
    assert tree.child_weights() == (ChildWeights(0.0, 3.0, 3.0), ChildWeights(0.0, 0.5, 0.5))
    _, steps = replay(tree, [[0.0], [1.0], [0.0]])
    assert steps[0][4]["reward_terms"] == {
        "any/a": 0.0,
        "any/a:distance": 3.0,
        "any/b": 0.0,
        "any/b:avoid": -0.5,
        "any": 0.0,
    }
    assert sg.formula(tree) == "R = Any[any] + 3*D[a] + 0.5*P[b:avoid]"


def test_default_child_weights_pass_shaping_and_safety_with_one_and_core_with_zero():
    tree = AnyOf(sg.Goal("a", x=(1, 2)), sg.Goal("b", x=(3, 4)), sg.Goal("c", x=(5, 6)), name="any")
    assert tree.child_weights() == (ChildWeights(core=0.0, shaping=1.0, safety=1.0),) * 3


def test_goal_is_the_union_and_box_only_with_one_child():
    a, b = sg.Goal("a", x=(1.0, 2.0)), sg.Goal("b", x=(3.0, 4.0))
    two, one = AnyOf(a, b, name="two"), AnyOf(a, name="one")
    assert two.box([a.box(()), b.box(())]) is None
    assert one.box([a.box(())]) == {"x": (1.0, 2.0)}
    assert [
        two.contains(Context(None, (), inside))
        for inside in ((False, False), (True, False), (False, True), (True, True))
    ] == [False, True, True, True]
    compiled = sg.compile_tree(sg.All(two, one, name="root"), ("x",))
    assert compiled.paths == ("root", "root/two", "root/two/a", "root/two/b", "root/one", "root/one/a")
    # The union has no box, so neither has the All above it; the one-child AnyOf is a box, tested as one.
    assert compiled.fast == (False, False, True, True, True, True)
    ev = compiled.evaluator()
    assert [ev.members([x])[1] for x in (0.0, 1.5, 2.5, 3.5)] == [False, True, False, True]


def test_own_reward_is_the_default_membership_difference():
    assert AnyOf.own_reward is True
    assert AnyOf.potential is sg.Node.potential and AnyOf.reward is sg.Node.reward
    assert AnyOf.terminates is sg.Node.terminates
    assert AnyOf(sg.Goal("a", x=(1, 2)), name="any").state_slots() == ()


def test_description_repr_and_formula_are_exact():
    tree = AnyOf(sg.Goal("a", x=(0.1 + 0.2, 1.0)), sg.Goal("b", x=(2, None)), name="reach", weights=(0.1 + 0.2, 1))
    assert tree.describe() == "AnyOf 'reach' weights=(0.30000000000000004, 1)"
    assert repr(tree) == (
        "AnyOf(Goal('a', x=(0.30000000000000004, 1)), Goal('b', x=(2, None)), name='reach', "
        "weights=(0.30000000000000004, 1.0))"
    )
    assert str(tree) == (
        "AnyOf 'reach' weights=(0.30000000000000004, 1)\n"
        "├── Goal 'a': 0.30000000000000004 <= x <= 1\n"
        "└── Goal 'b': x >= 2"
    )
    assert sg.formula(tree) == "R = Any[reach]"
    assert tree.formula_term("reach") == "Any[reach]"
    annotated = tree.annotate(sg.Distance(dist_to_2, scale=2.0))
    assert repr(annotated).endswith(".annotate(Distance(dist_to_2, scale=2))")
    assert sg.formula(annotated) == "R = 0.5*Any[reach] + 0.5*D[reach]"
    assert "0x" not in repr(annotated) + str(annotated)


def test_nested_formula_reads_naturally():
    tree = sg.All(
        AnyOf(
            sg.Goal("left", x=(None, -1)).annotate(sg.Distance(dist_to_2, scale=2.0)),
            sg.Goal("right", x=(1, None)),
            name="edge",
        ),
        sg.Goal("still", v=(-0.1, 0.1)),
        name="root",
    )
    assert sg.formula(tree) == "R = 0.5*(Any[edge] + 0.5*D[left]) + 0.5*R[still]"


def test_nodes_are_immutable_and_compare_by_value():
    a = AnyOf(sg.Goal("a", x=(1, 2)), name="any")
    assert a == AnyOf(sg.Goal("a", x=(1, 2)), name="any")
    assert hash(a) == hash(AnyOf(sg.Goal("a", x=(1, 2)), name="any"))
    with pytest.raises(AttributeError):
        a.name = "other"


@pytest.mark.parametrize(
    ("kwargs", "children", "message"),
    [
        ({"name": "any"}, (), "AnyOf 'any': expected at least one child node"),
        ({"name": "any"}, ("a",), "AnyOf 'any': expected children to be nodes"),
        ({"name": "any"}, (sg.Goal("a", x=1), sg.Goal("a", x=2)), "two children are named 'a'"),
        ({"name": ""}, (sg.Goal("a", x=1),), "expected a non-empty string as name"),
        ({"name": "a/b"}, (sg.Goal("a", x=1),), "may not contain '/'"),
        (
            {"name": "any", "weights": (1.0,)},
            (sg.Goal("a", x=1), sg.Goal("b", x=2)),
            "expected 2 weights (one per child), got 1",
        ),
        (
            {"name": "any", "weights": (0, 0)},
            (sg.Goal("a", x=1), sg.Goal("b", x=2)),
            "expected at least one weight > 0",
        ),
        (
            {"name": "any", "weights": (1, -1)},
            (sg.Goal("a", x=1), sg.Goal("b", x=2)),
            "AnyOf 'any', weight of 'b': expected a finite weight >= 0",
        ),
        (
            {"name": "any", "weights": (1, math.inf)},
            (sg.Goal("a", x=1), sg.Goal("b", x=2)),
            "expected a finite weight >= 0",
        ),
        (
            {"name": "any", "weights": (1, None)},
            (sg.Goal("a", x=1), sg.Goal("b", x=2)),
            "expected a number for every weight",
        ),
        ({"name": "any", "weights": "12"}, (sg.Goal("a", x=1), sg.Goal("b", x=2)), "expected weights to be a sequence"),
        (
            {"name": "any", "weights": (True, 1)},
            (sg.Goal("a", x=1), sg.Goal("b", x=2)),
            "expected weight to be a number",
        ),
    ],
)
def test_invalid_arguments_are_refused_at_construction(kwargs, children, message):
    with pytest.raises(InvalidSpec) as e:
        AnyOf(*children, **kwargs)
    assert message in str(e.value)


# -- refinements --------------------------------------------------------------


@given(st.data())
def test_refinement_preserves_the_root_goal(data):
    leaf = data.draw(sgst.goals(FEATURES, name="root"))
    refined = data.draw(AnyOf.refinements(leaf))
    assert isinstance(refined, AnyOf) and refined.name == "root"
    assert all(isinstance(c, sg.Goal) for c in refined.children)
    g_leaf, g_refined = process(leaf).goal, process(refined).goal
    flat_leaf = sg.compile_tree(leaf, FEATURES).evaluator()
    flat_refined = sg.compile_tree(refined, FEATURES).evaluator()
    leaf_box = leaf.box(())
    edges = sorted({v for lo, hi in leaf_box.values() for v in (lo, hi) if math.isfinite(v)})
    on_edges = (
        st.lists(st.sampled_from(edges) | sgst.states(FEATURES).map(lambda f: f[0]), min_size=3, max_size=3)
        if edges
        else sgst.states(FEATURES)
    )
    for f in data.draw(st.lists(on_edges | sgst.states(FEATURES), min_size=1, max_size=20)):
        x = ExtendedState(State._make(f), {})
        expected = all(
            lo <= v <= hi for v, (lo, hi) in zip(f, (leaf_box.get(n, (-math.inf, math.inf)) for n in FEATURES))
        )
        assert g_leaf(x) == g_refined(x) == expected
        assert flat_leaf.reset(f)[0] == flat_refined.reset(f)[0] == expected


@given(st.data())
def test_refinement_children_lie_inside_the_leaf(data):
    leaf = data.draw(sgst.goals(FEATURES, name="root"))
    refined = data.draw(AnyOf.refinements(leaf))
    assert 2 <= len(refined.children) <= 4
    leaf_box = leaf.box(())
    for child in refined.children:
        box = child.box(())
        assert set(box) == set(leaf_box)
        for f, (lo, hi) in box.items():
            assert leaf_box[f][0] <= lo <= hi <= leaf_box[f][1]


@given(st.data())
def test_refinement_of_a_box_of_exact_values_repeats_it(data):
    leaf = sg.Goal("legs", leg1=1, leg2=1)
    refined = data.draw(AnyOf.refinements(leaf))
    assert len(refined.children) >= 2
    assert all(c.box(()) == leaf.box(()) for c in refined.children)


def test_only_leaves_with_box_goals_refine():
    a, b = sg.Goal("a", x=(1, 2)), sg.Goal("b", x=(3, 4))
    assert AnyOf.refinements(AnyOf(a, b, name="any")) is None
    assert AnyOf.refinements(Sequence(a, b, name="seq")) is None
    assert AnyOf.refinements(a) is not None


# -- the constructed env ------------------------------------------------------


def test_constructed_envs_pass_both_checkers():
    tree = sg.All(
        AnyOf(sg.Goal("left", x=(None, -1.0)), sg.Goal("right", x=(1.0, None)), name="edge").annotate(
            sg.Distance(lambda s: abs(abs(s.x) - 1.0), scale=2.4)
        ),
        sg.Goal("upright", theta=(-0.05, 0.05)),
        name="cartpole",
    )
    both_checkers(tree)


def test_a_union_s_margin_is_its_best_child_s():
    from specguard.construction.initial_env import state_type
    from specguard.falsify.robustness import margins

    union = AnyOf(sg.Goal("left", x=(-1.0, 0.7)), sg.Goal("right", x=(0.5, 1.0)), name="sides")
    paths = ("sides", "sides/left", "sides/right")
    # 0.22 inside "right", 0.02 past "left": the union holds with 0.22 to spare (the smallest would say 0.02).
    got = margins(union, state_type(("x",))(0.72), {}, dict(zip(paths, (True, False, True))), {"x": 1.0})
    assert got["sides"] == pytest.approx(0.22) and got["sides/left"] == pytest.approx(-0.02)
    # Outside both: as far as the nearer child.
    union = AnyOf(sg.Goal("left", x=(-1.0, -0.5)), sg.Goal("right", x=(0.1, 1.0)), name="sides")
    got = margins(union, state_type(("x",))(0.0), {}, dict(zip(paths, (False, False, False))), {"x": 1.0})
    assert got["sides"] == pytest.approx(-0.1)
