"""Sequence: stages in order, the stage in the observation, stage rewards and the active child's shaping."""

from __future__ import annotations

import math
from collections import namedtuple

import pytest
from hypothesis import given
from hypothesis import strategies as st
from specguard_plugins import AnyOf, Avoid, Sequence

import specguard as sg
from specguard import strategies as sgst
from specguard.construction.reference import ReferenceEvaluator
from specguard.error import InvalidSpec
from specguard.extend import SHAPING, Annotation, ChildWeights, Context, Slot, StagesForm
from specguard.testing import ReplayEnv

from .helpers import both_checkers, replay, rewards

FEATURES = ("a", "b", "c")
State = namedtuple("State", FEATURES)


def to_minus_1(s):
    return abs(s.x + 1.0)


def to_2(s):
    return abs(s.x - 2.0)


A = sg.Goal("a", x=(None, -1.0))
B = sg.Goal("b", x=(2.0, None))


def test_order_matters_reaching_the_second_child_first_pays_nothing():
    tree = Sequence(A, B, name="seq")
    info0, steps = replay(tree, [[0.0], [3.0], [-2.0], [0.0], [3.0], [0.0]])
    assert info0["goals"] == {"seq": False, "seq/a": False, "seq/b": False}
    assert rewards(steps) == [0.0, 0.5, 0.0, 0.5]
    assert [s[0] for s in steps] == [[3.0, 0.0], [-2.0, 1.0], [0.0, 1.0], [3.0, 2.0]]  # x, then the stage
    assert [s[2] for s in steps] == [False, False, False, True]  # q = N is the root goal
    assert [s[4]["goals"]["seq"] for s in steps] == [False, False, False, True]
    assert [s[4]["goals"]["seq/b"] for s in steps] == [True, False, False, True]  # in b, yet not counted at first
    assert steps[0][4]["reward_terms"] == {"seq/a": 0.0, "seq/b": 0.0, "seq": 0.0}
    assert steps[1][4]["reward_terms"] == {"seq/a": 0.0, "seq/b": 0.0, "seq": 0.5}


def test_initial_stage_counts_the_leading_children_satisfied_by_s0():
    a, b, c = sg.Goal("a", x=(None, 1.0)), sg.Goal("b", x=(0.0, None)), sg.Goal("c", x=(5.0, None))
    info0, steps = replay(Sequence(a, b, c, name="seq"), [[0.5], [6.0]])
    assert info0["goals"] == {"seq": False, "seq/a": True, "seq/b": True, "seq/c": False}
    assert steps[0][0] == [6.0, 3.0]
    assert steps[0][1] == pytest.approx(1 / 3)
    assert steps[0][2] is True


def test_initial_stage_stops_at_the_first_unsatisfied_child():
    later = sg.Goal("later", x=(None, 1.0))
    env_steps = replay(Sequence(sg.Goal("first", x=(5.0, None)), later, name="seq"), [[0.5], [0.5]])[1]
    assert env_steps[0][0] == [0.5, 0.0]  # `later` holds in s_0 but `first` does not: stage 0
    assert env_steps[0][1] == 0.0


def test_one_step_may_pass_several_stages():
    a, b, c = sg.Goal("a", x=(1.0, None)), sg.Goal("b", x=(2.0, None)), sg.Goal("c", x=(3.0, None))
    _, steps = replay(Sequence(a, b, c, name="seq"), [[0.0], [2.5], [3.5]])
    assert [s[0][1] for s in steps] == [2.0, 3.0]
    assert rewards(steps) == pytest.approx([2 / 3, 1 / 3])


def test_the_stage_never_goes_back_and_a_finished_sequence_stays_in_its_goal():
    never = sg.Goal("never", y=(100.0, None))
    tree = sg.All(Sequence(A, B, name="seq"), never, name="root")
    _, steps = replay(tree, [[-2.0, 0.0], [3.0, 0.0], [0.0, 0.0], [-2.0, 0.0]], features=("x", "y"))
    assert [s[0][2] for s in steps] == [2.0, 2.0, 2.0]
    assert [s[4]["goals"]["root/seq"] for s in steps] == [True, True, True]
    assert rewards(steps) == [0.25, 0.0, 0.0]  # the All passes 1/2 of the stage reward 1/2


def test_per_stage_weights_replace_one_over_n():
    tree = Sequence(A, B, name="seq", weights=(0.2, 0.8))
    _, steps = replay(tree, [[0.0], [-2.0], [3.0]])
    assert rewards(steps) == [0.2, 0.8]
    assert tree.stage_weights() == (0.2, 0.8)
    assert Sequence(A, B, name="seq").stage_weights() == (0.5, 0.5)


def test_only_the_active_childs_distance_shapes_and_the_potential_telescopes():
    a = A.annotate(sg.Distance(to_minus_1, scale=2.0))
    b = B.annotate(sg.Distance(to_2, scale=4.0))
    tree = Sequence(a, b, name="seq")
    _, steps = replay(tree, [[0.0], [-0.5], [-1.0], [1.0], [2.0]])
    # Phi(s, q) = q/2 + (1/2) * (-fn_{q+1}(s)/d_{q+1}) (the active stage's weight scales its shaping), Phi(s, 2) = 1:
    # Phi: -0.25 (x=0, q=0), -0.125 (x=-0.5), 0.5-0.375 (x=-1, q=1), 0.5-0.125 (x=1), 1 (x=2, q=2)
    assert rewards(steps) == [0.125, 0.25, 0.25, 0.625]
    assert sum(rewards(steps)) == 1.0 - (-0.25)
    assert steps[0][4]["reward_terms"] == {
        "seq/a": 0.0,
        "seq/a:distance": 0.0,  # taken over by the sequence: reported with weight 0
        "seq/b": 0.0,
        "seq/b:distance": 0.0,
        "seq": 0.125,
    }
    assert steps[-1][2] is True


def test_a_distance_weight_the_user_set_scales_its_shaping():
    b = B.annotate(sg.Distance(to_2, scale=4.0, weight=2.0))
    tree = Sequence(A, b, name="seq")
    _, steps = replay(tree, [[-2.0], [0.0], [1.0]])
    # q = 1 throughout; Phi = 0.5 - (1/2) * 2 * |x - 2| / 4 (the stage weight 1/2 times the user's weight 2)
    assert rewards(steps) == [0.5 * 2 * (4.0 - 2.0) / 4.0, 0.5 * 2 * (2.0 - 1.0) / 4.0]


def test_shaping_annotations_below_the_active_child_do_not_shape():
    inner = sg.All(sg.Goal("deep", x=(None, -1.0)).annotate(sg.Distance(to_minus_1, scale=1.0)), name="wrap")
    tree = Sequence(inner, B, name="seq")
    _, steps = replay(tree, [[0.0], [-0.5], [0.0]])
    assert rewards(steps) == [0.0, 0.0]
    assert steps[0][4]["reward_terms"]["seq/wrap/deep:distance"] == 0.0


def test_childrens_constraints_and_avoids_stay_in_force():
    a = A.annotate(sg.Constraint(lambda s, act: s.x > 5.0, budget=2), Avoid({"x": (5.0, None)}, budget=2))
    tree = Sequence(a, B, name="seq")
    info0, steps = replay(tree, [[0.0], [6.0], [0.0], [6.0]])
    assert info0["safe"] == {"seq/a:constraint": True, "seq/a:avoid": True}
    # step 1 enters the region (avoid: s'), step 2 leaves it from x=6 (constraint: s): one each,
    # step 3 enters again: the avoid counter reaches 0 and ends the episode, whose last state x=6 the
    # constraint judges too (with the action that led to it).
    assert [s[4]["reward_terms"]["seq/a:avoid"] for s in steps] == [-1.0, 0.0, -1.0]
    assert [s[4]["reward_terms"]["seq/a:constraint"] for s in steps] == [0.0, -1.0, -1.0]
    assert rewards(steps) == [-1.0, -1.0, -2.0]
    assert [s[0] for s in steps] == [[6.0, 2.0, 1.0, 0.0], [0.0, 1.0, 1.0, 0.0], [6.0, 0.0, 0.0, 0.0]]
    assert [s[2] for s in steps] == [False, False, True]
    assert steps[-1][4]["safe"] == {"seq/a:constraint": False, "seq/a:avoid": False}


def test_child_weights_pass_only_safety():
    tree = Sequence(A, B, sg.Goal("c", x=0), name="seq", weights=(1, 2, 3))
    assert tree.child_weights() == (ChildWeights(core=0.0, shaping=0.0, safety=1.0),) * 3


def test_protocol_values():
    tree = Sequence(A, B, name="seq")
    assert tree.state_slots() == (Slot("stage", 0.0, 2.0),)
    assert tree.box([A.box(()), B.box(())]) is None
    assert Sequence.refinements(A) is None
    assert tree.initial_state(Context(None, (), (True, False))) == (1.0,)
    assert tree.next_state(Context(None, (1.0,), (True, False)), 0, None, (False, True)) == (2.0,)
    assert tree.next_state(Context(None, (0.0,), (False, False)), 0, None, (False, True)) == (0.0,)
    assert [tree.contains(Context(None, (q,), (True, True))) for q in (0.0, 1.0, 2.0)] == [False, False, True]
    assert type(tree).terminates is sg.Node.terminates  # no termination of its own


def test_nested_sequence_under_an_all_is_weighted_by_its_parent():
    tree = sg.All(Sequence(A, B, name="seq"), sg.Goal("never", y=(100.0, None)), name="root", weights=(0.3, 0.7))
    _, steps = replay(tree, [[0.0, 0.0], [-2.0, 0.0], [3.0, 0.0]], features=("x", "y"))
    assert rewards(steps) == pytest.approx([0.15, 0.15])


def test_description_repr_and_formula_are_exact():
    tree = Sequence(A, B.annotate(sg.Distance(to_2, scale=4.0)), name="seq", weights=(0.1 + 0.2, 1))
    assert tree.describe() == "Sequence 'seq' weights=(0.30000000000000004, 1)"
    assert str(tree) == (
        "Sequence 'seq' weights=(0.30000000000000004, 1)\n"
        "├── Goal 'a': x <= -1\n"
        "└── Goal 'b': x >= 2\n"
        "        + Distance(to_2, scale=4)"
    )
    assert repr(tree) == (
        "Sequence(Goal('a', x=(None, -1)), Goal('b', x=(2, None)).annotate(Distance(to_2, scale=4)), "
        "name='seq', weights=(0.30000000000000004, 1.0))"
    )
    assert sg.formula(tree) == "R = Seq[seq]"
    wrapped = sg.All(tree, sg.Goal("c", x=0).annotate(sg.Distance(to_2, scale=1.0)), name="root")
    assert sg.formula(wrapped) == "R = 0.5*Seq[seq] + 0.5*(0.5*R[c] + 0.5*D[c])"
    annotated = tree.annotate(Avoid({"x": (9, None)}))
    assert repr(annotated).endswith(".annotate(Avoid(Goal 'avoid': x >= 9, budget=1))")
    assert sg.formula(annotated) == "R = Seq[seq] + P[seq:avoid]"


@pytest.mark.parametrize(
    ("kwargs", "children", "message"),
    [
        ({"name": "seq"}, (), "Sequence 'seq': expected at least one child node"),
        ({"name": "seq"}, (A, 3), "Sequence 'seq': expected children to be nodes"),
        ({"name": "seq"}, (A, A), "two children are named 'a'"),
        ({"name": 7}, (A,), "expected a non-empty string as name"),
        ({"name": "seq", "weights": (1, 2, 3)}, (A, B), "expected 2 weights (one per child), got 3"),
        ({"name": "seq", "weights": (0.0, 0.0)}, (A, B), "expected at least one weight > 0"),
        ({"name": "seq", "weights": (1, -0.5)}, (A, B), "Sequence 'seq', weight of 'b': expected a finite weight >= 0"),
        ({"name": "seq", "weights": 1.0}, (A, B), "expected weights to be a sequence"),
    ],
)
def test_invalid_arguments_are_refused_at_construction(kwargs, children, message):
    with pytest.raises(InvalidSpec) as e:
        Sequence(*children, **kwargs)
    assert message in str(e.value)


class Momentum(Annotation):
    """A shaping annotation with own state: a sequence cannot take over its potential."""

    role = SHAPING
    name = "momentum"
    weight = None

    def state_slots(self):
        return (Slot("m", 0.0, 1.0),)


def test_a_childs_stateful_shaping_annotation_is_refused():
    with pytest.raises(InvalidSpec, match="Sequence 'seq': child 'a' has the shaping annotation"):
        Sequence(A.annotate(Momentum()), B, name="seq")


def test_one_child_is_a_latch():
    tree = sg.All(Sequence(A, name="once"), sg.Goal("never", y=(100.0, None)), name="root")
    _, steps = replay(tree, [[0.0, 0.0], [-2.0, 0.0], [0.0, 0.0]], features=("x", "y"))
    assert [s[4]["goals"]["root/once"] for s in steps] == [True, True]
    assert [s[4]["goals"]["root/once/a"] for s in steps] == [True, False]
    assert rewards(steps) == [0.5, 0.0]


@given(
    st.lists(sgst.goals(FEATURES), min_size=1, max_size=3, unique_by=lambda g: g.name).flatmap(
        lambda goals: st.tuples(*(sgst.distances(FEATURES).map(g.annotate) | st.just(g) for g in goals))
    ),
    sgst.weights(3),
    sgst.trajectories(FEATURES, max_size=15),
)
def test_stage_reward_and_shaping_telescope(children, weights, trajectory):
    weights = None if weights is None else weights[: len(children)]
    if weights is not None and not any(weights):
        weights = None
    tree = sg.All(Sequence(*children, name="seq", weights=weights), sg.Goal("never", a=(100.0, None)), name="root")
    seq = tree.children[0]
    ev = ReferenceEvaluator(tree, FEATURES)
    ev.reset(trajectory[0])

    def phi(f):
        return seq.potential(Context(State._make(f), tuple(ev.own_state), ()))

    start, paid, stage = phi(trajectory[0]), 0.0, ev.own_state[0]
    for f in trajectory[1:]:
        paid += ev.step(0, f)[3]["root/seq"]
        assert stage <= ev.own_state[0] <= len(children)  # the stage never goes back
        stage = ev.own_state[0]
    assert paid == pytest.approx(0.5 * (phi(trajectory[-1]) - start), abs=1e-9)


# -- the constructed env ------------------------------------------------------


def test_constructed_envs_pass_both_checkers():
    tree = Sequence(
        sg.Goal("left", x=(None, -0.5)).annotate(sg.Distance(lambda s: abs(s.x + 0.5), scale=2.4)),
        AnyOf(sg.Goal("right", x=(0.5, None)), sg.Goal("upright", theta=(-0.01, 0.01)), name="then"),
        name="cartpole",
    )
    both_checkers(tree)


def _to_minus_1(s):
    return abs(s.a + 1.0)


def _flat_source(tree):
    return sg.compile_tree(tree, FEATURES).source


def test_a_sequence_compiles_to_its_stage_form_and_a_shaper_without_a_closed_form_to_its_methods():
    a, b = sg.Goal("a", a=(None, -1.0)), sg.Goal("b", a=(2.0, None))
    fast = Sequence(a.annotate(sg.Distance(_to_minus_1, scale=4.0)), b, name="seq")
    form = fast.fast_form()
    assert form is not None and form.stage == (0.0, 0.5, 1.0)
    assert form.shapers == (((_to_minus_1, 4.0, 0.5),), ())
    assert "_node0" not in _flat_source(fast) and "_sh0_0_0(s2)" in _flat_source(fast)

    class Opaque(sg.Distance):  # a shaping annotation that declares no closed form
        def fast_form(self):  # type: ignore[override]
            return None

    general = Sequence(a.annotate(Opaque(_to_minus_1, scale=4.0)), b, name="seq")
    assert general.fast_form() is None and "_node0" in _flat_source(general)
    trajectory = [[0.0, 0, 0], [-0.5, 0, 0], [-2.0, 0, 0], [1.0, 0, 0], [3.0, 0, 0]]
    fast_rewards = rewards(replay(fast, trajectory, FEATURES)[1])
    assert fast_rewards == rewards(replay(general, trajectory, FEATURES)[1])
    assert fast_rewards == [0.0625, 0.5 + 0.0625, 0.0, 0.5]  # the distance shaped stage 0 only, then the stages


@pytest.mark.parametrize("evaluator", ["flat", "reference"])
@pytest.mark.parametrize(
    "bad, message",
    [(-1.0, "expected a finite distance >= 0, got -1.0"), (None, "the distance function raised TypeError")],
    ids=["negative", "raises"],
)
def test_a_bad_distance_of_the_active_stage_is_one_error_naming_the_sequence(evaluator, bad, message):
    tree = Sequence(
        sg.Goal("a", a=(None, -1.0)).annotate(sg.Distance(lambda s: 1.0 if s.a < 0.55 else bad + 0.0, scale=4.0)),
        sg.Goal("b", a=(2.0, None)),
        name="seq",
    )
    initial = sg.InitialEnv(lambda: ReplayEnv([[0.0, 0, 0], [0.5, 0, 0], [0.6, 0, 0]]), features=FEATURES)
    env = sg.make_env(initial, tree, evaluator=evaluator)
    env.reset(seed=0)
    env.step(0)
    # The flat evaluator names the sequence (whose potential asked the distance), the reference its key.
    with pytest.raises(
        sg.error.EvaluationError, match=f"^seq{'' if evaluator == 'flat' else '/a:distance'}: {message}"
    ):
        env.step(0)


@pytest.mark.parametrize(
    "form, message",
    [
        ("stages", "fast_form\\(\\) must return a StagesForm or None, got 'stages'"),
        (StagesForm((0.0, 1.0), ((),)), "N \\+ 1 stage values and N shaper tuples for N = 2 children"),
        (StagesForm((0.0, 0.5, math.inf), ((), ())), "must be finite numbers"),
        (StagesForm((0.0, 0.5, 1.0), (((_to_minus_1, 0.0, 1.0),), ())), "scales must be > 0"),
    ],
    ids=["not a form", "sizes", "not finite", "scale"],
)
def test_a_malformed_stage_form_is_refused_naming_the_node(form, message):
    class Declares(Sequence):
        def fast_form(self):  # type: ignore[override]
            return form

    tree = Declares(sg.Goal("a", a=(None, -1.0)), sg.Goal("b", a=(2.0, None)), name="seq")
    with pytest.raises(InvalidSpec, match=f"seq.*{message}"):
        sg.compile_tree(tree, FEATURES)
