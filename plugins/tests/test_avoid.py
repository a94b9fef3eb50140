"""Avoid: a counter of the steps whose next state lies in a region, ending the episode at 0."""

from __future__ import annotations

import math
import pickle

import cloudpickle
import numpy as np
import pytest
from hypothesis import given
from specguard_plugins import AnyOf, Avoid, Sequence

import specguard as sg
from specguard.error import EvaluationError, InvalidSpec
from specguard.extend import SAFETY, CounterForm, Slot

from .helpers import both_checkers, replay, replay_env, rewards

FEATURES = ("a", "b", "c")


def test_counter_drops_on_every_next_state_in_the_region_and_ends_the_episode_at_zero():
    tree = sg.Goal("far", x=(10.0, None)).annotate(Avoid({"x": (2.0, None)}, budget=2, name="edges"))
    info0, steps = replay(tree, [[3.0], [3.0], [0.0], [2.0], [0.0]])
    assert info0["safe"] == {"far:edges": True}  # s_0 in the region is no violation
    assert [s[0] for s in steps] == [[3.0, 1.0], [0.0, 1.0], [2.0, 0.0]]  # x, then the counter
    assert rewards(steps) == [-1.0, 0.0, -1.0]
    assert [s[4]["reward_terms"] for s in steps] == [
        {"far": 0.0, "far:edges": -1.0},
        {"far": 0.0, "far:edges": 0.0},
        {"far": 0.0, "far:edges": -1.0},
    ]
    assert [s[4]["safe"] for s in steps] == [{"far:edges": False}] * 3
    assert [s[2:4] for s in steps] == [(False, False), (False, False), (True, False)]
    assert [s[4]["goals"] for s in steps] == [{"far": False}] * 3


def test_staying_in_the_region_is_a_violation_every_step():
    tree = sg.Goal("far", x=(10.0, None)).annotate(Avoid({"x": (2.0, None)}, budget=3))
    _, steps = replay(tree, [[0.0], [2.5], [2.5], [2.5], [2.5]])
    assert rewards(steps) == [-1.0, -1.0, -1.0]
    assert [s[0][1] for s in steps] == [2.0, 1.0, 0.0]
    assert steps[-1][2] is True


def test_weight_scales_the_penalty_and_is_outside_the_normalisation():
    avoid = Avoid({"x": (2.0, None)}, budget=2, weight=0.5)
    tree = sg.Goal("far", x=(10.0, None)).annotate(sg.Distance(lambda s: abs(s.x), scale=8.0), avoid)
    _, steps = replay(tree, [[0.0], [3.0], [0.0]])
    # core and distance share 1/2 each; the penalty keeps its own weight
    assert steps[0][4]["reward_terms"] == {"far": 0.0, "far:distance": 0.5 * (0.0 - 3.0) / 8.0, "far:avoid": -0.5}
    assert sg.formula(tree) == "R = 0.5*R[far] + 0.5*D[far] + 0.5*P[far:avoid]"


def test_an_avoid_judges_the_next_state_where_a_constraint_judges_the_state():
    tree = sg.Goal("far", x=(10.0, None)).annotate(
        Avoid({"x": (2.0, None)}, budget=5), sg.Constraint(lambda s, a: s.x >= 2.0, budget=5)
    )
    _, steps = replay(tree, [[0.0], [3.0], [0.0]])
    assert [s[4]["reward_terms"]["far:avoid"] for s in steps] == [-1.0, 0.0]
    assert [s[4]["reward_terms"]["far:constraint"] for s in steps] == [0.0, -1.0]


def test_a_node_region_uses_the_nodes_goal():
    edges = AnyOf(sg.Goal("l", x=(None, -2.0)), sg.Goal("r", x=(2.0, None)), name="edges")
    tree = sg.Goal("far", x=(10.0, None)).annotate(Avoid(edges, budget=3))
    _, steps = replay(tree, [[0.0], [-3.0], [0.0], [3.0], [1.0]])
    assert rewards(steps) == [-1.0, 0.0, -1.0, 0.0]
    band = sg.All(sg.Goal("above", x=(1.0, None)), sg.Goal("below", x=(None, 2.0)), name="band")
    avoid = Avoid(band)
    assert [avoid.in_region(type("S", (), {"x": x})) for x in (0.5, 1.0, 1.5, 2.0, 2.5)] == [
        False,
        True,
        True,
        True,
        False,
    ]


def test_a_region_with_own_state_is_refused():
    seq = Sequence(sg.Goal("a", x=1), sg.Goal("b", x=2), name="seq")
    with pytest.raises(InvalidSpec, match="Avoid 'avoid': the region 'seq' is not a set of states"):
        Avoid(seq)
    with pytest.raises(InvalidSpec, match="Avoid 'zone': the region 'any/seq' is not a set of states"):
        Avoid(AnyOf(sg.Goal("c", x=3), seq, name="any"), name="zone")


def test_protocol_values():
    avoid = Avoid({"x": (2.0, None)}, budget=3)
    assert (Avoid.role, Avoid.normalised, Avoid.symbol) == (SAFETY, False, "P")
    assert avoid.state_slots() == (Slot("counter", 0.0, 3.0),)
    assert avoid.initial_state(None) == (3.0,)
    assert avoid.potential(None, (2.0,)) == 2.0
    assert [avoid.terminates((q,)) for q in (2.0, 1.0, 0.0)] == [False, False, True]
    assert [avoid.violations((q,)) for q in (3.0, 2.0, 0.0)] == [0, 1, 3]


def test_fast_form_is_a_counter_on_the_next_state_compiled_to_straight_line_code():
    avoid = Avoid({"x": (2.0, None)}, budget=3)
    form = avoid.fast_form()
    assert isinstance(form, CounterForm)
    assert (form.budget, form.on_next_state) == (3, True)
    state = sg.compile_tree(sg.Goal("far", x=(10.0, None)).annotate(avoid), ("x",))
    assert state.all_fast
    assert [t.kind for t in state.terms] == ["member", "counter"]
    assert "_ann" not in state.source  # no call into the protocol methods per step
    s = type("S", (), {})
    for x in (1.0, 2.0, 3.0):
        s.x = x
        assert form.fn(s) == avoid.in_region(s) == (x >= 2.0)
        assert avoid.next_state(None, (3.0,), 0, s) == ((2.0,) if x >= 2.0 else (3.0,))


def test_batch_rewards_agree_with_the_episode():
    tree = sg.Goal("far", x=(10.0, None)).annotate(Avoid({"x": (2.0, None)}, budget=3))
    compiled = sg.compile_tree(tree, ("x",))
    s, s2 = np.array([[0.0], [0.0], [3.0]]), np.array([[3.0], [1.0], [2.0]])
    assert compiled.reward_terms(s, [0, 0, 0], s2).tolist() == [[0.0, -1.0], [0.0, 0.0], [0.0, -1.0]]


def test_description_and_repr_are_exact():
    assert repr(Avoid(sg.Goal("edges", x=(2.4, None)))) == "Avoid(Goal 'edges': x >= 2.4, budget=1)"
    assert Avoid({"x": (2.4, None)}, name="edges").describe() == (
        "Avoid(Goal 'edges': x >= 2.4, budget=1, name='edges')"
    )
    assert repr(Avoid({"x": (None, 0.1 + 0.2)}, budget=2, weight=0.1 + 0.2)) == (
        "Avoid(Goal 'avoid': x <= 0.30000000000000004, budget=2, weight=0.30000000000000004)"
    )
    edges = AnyOf(sg.Goal("l", x=(None, -2.0)), sg.Goal("r", x=(2.0, None)), name="edges")
    assert repr(Avoid(edges)) == "Avoid(AnyOf 'edges' [Goal 'l': x <= -2; Goal 'r': x >= 2], budget=1)"
    tree = sg.Goal("far", x=(10.0, None)).annotate(Avoid(edges, budget=2))
    assert str(tree) == (
        "Goal 'far': x >= 10\n    + Avoid(AnyOf 'edges' [Goal 'l': x <= -2; Goal 'r': x >= 2], budget=2)"
    )
    assert "0x" not in repr(tree)


def test_equal_by_value_and_picklable():
    avoid = Avoid({"x": (2.0, None)}, budget=2, weight=3.0, name="edges")
    assert avoid == Avoid(sg.Goal("edges", x=(2.0, None)), budget=2, weight=3.0, name="edges")
    assert avoid != Avoid({"x": (2.0, None)}, budget=1, weight=3.0, name="edges")
    assert hash(avoid) == hash(Avoid({"x": (2.0, None)}, budget=2, weight=3.0, name="edges"))
    for dumps, loads in ((pickle.dumps, pickle.loads), (cloudpickle.dumps, cloudpickle.loads)):
        back = loads(dumps(avoid))
        assert back == avoid and repr(back) == repr(avoid)
        assert back.in_region(type("S", (), {"x": 2.0})) is True
    with pytest.raises(AttributeError):
        avoid.budget = 5


@pytest.mark.parametrize(
    ("args", "kwargs", "message"),
    [
        ((3,), {}, "Avoid 'avoid': expected region to be a node (Goal, All, AnyOf, ...) or a box"),
        (("x",), {}, "expected region to be a node"),
        (({},), {}, "Avoid 'avoid': expected a region box {feature: (lo, hi)} with at least one feature"),
        (({1: (0, 1)},), {}, "expected feature names (str) as the region's keys, got 1"),
        (
            ({"x": (2, 1)},),
            {},
            "Avoid 'avoid': the region box is malformed: Goal 'avoid', feature 'x': expected lo <= hi",
        ),
        (({"x": (None, None)},), {}, "the region box is malformed"),
        (({"x": (2, None)},), {"budget": 0}, "Avoid 'avoid': expected budget to be an integer >= 1"),
        (({"x": (2, None)},), {"budget": 1.5}, "expected budget to be an integer >= 1"),
        (({"x": (2, None)},), {"budget": True}, "expected budget to be an integer >= 1"),
        (({"x": (2, None)},), {"weight": -1}, "Avoid 'avoid': expected a finite weight >= 0"),
        (({"x": (2, None)},), {"weight": math.nan}, "expected a finite weight >= 0"),
        (({"x": (2, None)},), {"weight": "1"}, "expected weight to be a number"),
        (({"x": (2, None)},), {"name": ""}, "expected a non-empty string as name"),
        (({"x": (2, None)},), {"name": "a:b"}, "may not contain ':'"),
    ],
)
def test_invalid_arguments_are_refused_at_construction(args, kwargs, message):
    with pytest.raises(InvalidSpec) as e:
        Avoid(*args, **kwargs)
    assert message in str(e.value)


def test_two_avoids_on_a_node_need_distinct_names():
    with pytest.raises(InvalidSpec, match="two annotations are named 'avoid'"):
        sg.Goal("g", x=1).annotate(Avoid({"x": (2, None)}), Avoid({"x": (None, -2)}))


def test_a_region_on_an_unknown_feature_fails_at_the_first_step_naming_the_annotation():
    env = replay_env(sg.Goal("far", x=(10.0, None)).annotate(Avoid({"zz": (2.0, None)})), [[0.0], [1.0]])
    env.reset(seed=0)
    with pytest.raises(EvaluationError, match=r"far:avoid: .*'zz'"):
        env.step(0)


@given(Avoid.strategy(FEATURES, "avoid0"))
def test_strategy_draws_valid_avoids(avoid):
    assert isinstance(avoid, Avoid) and avoid.name == "avoid0"
    assert 1 <= avoid.budget <= 4
    assert isinstance(avoid.region, sg.Goal) and set(avoid.region.box(())) <= set(FEATURES)
    assert avoid.weight is None or 0.0 <= avoid.weight <= 10.0


def test_constructed_envs_pass_both_checkers():
    tree = sg.Goal("right", x=(0.5, 1.5)).annotate(  # a root goal no CartPole start is in (GoalMetAtStart)
        Avoid({"x": (2.0, None)}, budget=3, name="far_right"),
        Avoid(AnyOf(sg.Goal("spin_l", omega=(None, -1.0)), sg.Goal("spin_r", omega=(1.0, None)), name="spin")),
    )
    both_checkers(tree)
