"""Properties of the definitions (docs/semantics.md, "Reward"), checked on the reference Algorithm 1."""

from __future__ import annotations

import math
from itertools import pairwise

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import specguard as sg
from specguard import strategies as sgst
from specguard.construction.initial_env import state_type
from specguard.construction.reference import ExtendedState, ReferenceEvaluator, process
from specguard.extend import component_weights

FEATURES = ("a", "b", "c")
State = state_type(FEATURES)


def inside(goal: sg.Goal, f: list[float]) -> bool:
    s = dict(zip(FEATURES, f))
    return all(lo <= s[name] <= hi for name, lo, hi in goal.bounds)


def chain(req, trajectory, actions=None):
    """The extended states of a trajectory, own states following the transitions."""
    s = State._make(trajectory[0])
    out = [ExtendedState(s, req.initial(s))]
    for t, f in enumerate(trajectory[1:]):
        s2 = State._make(f)
        out.append(ExtendedState(s2, req.transition(out[-1], actions[t] if actions else 0, s2, False)))
    return out


def run(tree: sg.Node, trajectory: list[list[float]], actions: list[int] | None = None):
    """Rewards, terms and flags of the reference evaluator along a trajectory (stops when it ends)."""
    ev = ReferenceEvaluator(tree, FEATURES)
    first = ev.reset(trajectory[0])
    steps = []
    for t, f in enumerate(trajectory[1:]):
        a = actions[t] if actions else 0
        reward, ended, goals, terms = ev.step(a, f)
        steps.append((reward, ended, goals, terms, ev.own_state))
        if ended:
            break
    return first, steps


@given(sgst.goals(FEATURES), sgst.trajectories(FEATURES))
def test_leaf_rewards_telescope_to_final_minus_initial_membership(goal, trajectory):
    _, steps = run(goal, trajectory)
    # The root leaf ends the episode when reached: s_T is the last state visited.
    last = trajectory[len(steps)]
    total = sum(r for r, *_ in steps)
    assert total == pytest.approx(int(inside(goal, last)) - int(inside(goal, trajectory[0])))


@given(sgst.goals(FEATURES), sgst.trajectories(FEATURES))
def test_reentering_a_leaf_is_never_paid_twice(goal, trajectory):
    req = process(sg.All(goal, name="root"), root=False)  # no root termination: the whole trajectory runs
    ext = chain(req, trajectory)
    rewards = [sum(req.reward(s, 0, s2).values()) for s, s2 in pairwise(ext)]
    running = 0.0
    for r in rewards:
        running += r
        assert running in (pytest.approx(-1.0), pytest.approx(0.0), pytest.approx(1.0))
    assert sum(rewards) == pytest.approx(int(inside(goal, trajectory[-1])) - int(inside(goal, trajectory[0])))


@given(sgst.goals(FEATURES), sgst.distances(FEATURES), sgst.trajectories(FEATURES))
def test_distance_shaping_telescopes(goal, distance, trajectory):
    tree = sg.All(goal.annotate(distance), name="root")
    req = process(tree, root=False)
    ext = chain(req, trajectory)
    key = f"root/{goal.name}:{distance.name}"
    _, weights = component_weights(goal.annotate(distance))
    shaped = sum(req.reward(s, 0, s2)[key] for s, s2 in pairwise(ext))
    expected = weights[0] * (distance.fn(ext[0].s) - distance.fn(ext[-1].s)) / distance.scale
    assert shaped == pytest.approx(expected, abs=1e-9)


@given(st.data())
def test_refinement_preserves_the_root_goal(data):
    leaf = data.draw(sgst.goals(FEATURES, name="root"))
    refined = data.draw(sgst.refinements(leaf))
    g_leaf, g_refined = process(leaf).goal, process(refined).goal
    for f in data.draw(st.lists(sgst.states(FEATURES), min_size=1, max_size=20)):
        s = State._make(f)
        x = ExtendedState(s, {})
        assert g_leaf(x) == g_refined(x) == inside(leaf, f)


@given(st.data())
def test_refinement_changes_the_root_reward(data):
    # A leaf bounding >= 2 features, split by feature into children: a state that
    # enters one child's box but not the leaf's is rewarded only after refinement.
    leaf = data.draw(sgst.goals(FEATURES, name="root"))
    finite = [(f, lo, hi) for f, lo, hi in leaf.bounds if math.isfinite(lo) or math.isfinite(hi)]
    assume(len(finite) >= 2)
    weights = data.draw(st.lists(st.floats(0.01, 10.0), min_size=2, max_size=2))
    half = [finite[:1], finite[1:]]
    children = [
        sg.Goal(f"part{i}", **{f: (None if math.isinf(lo) else lo, None if math.isinf(hi) else hi) for f, lo, hi in p})
        for i, p in enumerate(half)
    ]
    refined = sg.All(*children, name="root", weights=weights)

    def outside(lo: float, hi: float) -> float:
        return lo - 1.0 if math.isfinite(lo) else hi + 1.0

    def inner(lo: float, hi: float) -> float:
        return lo if math.isfinite(lo) else hi

    values = {f: 0.0 for f in FEATURES}  # inside any feature the leaf leaves open
    s = dict(values, **{f: outside(lo, hi) for f, lo, hi in finite})
    s2 = dict(s, **{f: inner(lo, hi) for f, lo, hi in half[0]})
    ext, ext2 = (ExtendedState(State(**v), {}) for v in (s, s2))
    r_leaf = sum(process(leaf).reward(ext, 0, ext2).values())
    r_refined = sum(process(refined).reward(ext, 0, ext2).values())
    assert r_leaf == 0.0
    assert r_refined == pytest.approx(weights[0])


@given(st.data())
def test_and_reward_is_the_weighted_sum_of_the_childrens(data):
    kids = data.draw(st.lists(sgst.trees(FEATURES, max_depth=2), min_size=1, max_size=3, unique_by=lambda n: n.name))
    some_weights = st.lists(st.floats(0.0, 10.0), min_size=len(kids), max_size=len(kids))
    weights = data.draw(st.none() | some_weights.filter(lambda w: any(x > 0 for x in w)))
    node = sg.All(*kids, name="root", weights=weights)
    f, f2 = data.draw(sgst.states(FEATURES)), data.draw(sgst.states(FEATURES))
    a = data.draw(st.integers(0, 2))
    reqs = [process(k, f"root/{k.name}", root=False) for k in kids]
    own = [
        {key: (float(data.draw(st.integers(0, int(slot.high)))),) for r in reqs for key, slot in r.slots} for _ in "12"
    ]
    ext, ext2 = ExtendedState(State._make(f), own[0]), ExtendedState(State._make(f2), own[1])
    total = sum(process(node, root=False).reward(ext, a, ext2).values())
    expected = sum(w * sum(r.reward(ext, a, ext2).values()) for w, r in zip(node.weights_in_force(), reqs))
    assert total == pytest.approx(expected, abs=1e-9)


@given(st.data())
def test_parent_termination_includes_every_childs(data):
    tree = data.draw(sgst.trees(FEATURES))
    f = data.draw(sgst.states(FEATURES))
    for path, node in tree.walk():
        req = process(node, path, root=False)
        own = {key: (float(data.draw(st.integers(0, int(slot.high)))),) for key, slot in req.slots}
        ext = ExtendedState(State._make(f), own)
        for child in node.children:
            if process(child, f"{path}/{child.name}", root=False).terminal(ext):
                assert req.terminal(ext)


@given(sgst.trees(FEATURES), sgst.trajectories(FEATURES, max_size=20), st.data())
def test_constraint_counters_never_increase_and_end_the_episode_at_zero(tree, trajectory, data):
    actions = data.draw(st.lists(st.integers(0, 2), min_size=len(trajectory), max_size=len(trajectory)))
    ev = ReferenceEvaluator(tree, FEATURES)
    ev.reset(trajectory[0])
    previous = ev.own_state
    assert previous == [slot.high for _, slot in ev.slots]
    for t, f in enumerate(trajectory[1:]):
        _, ended, goals, _ = ev.step(actions[t], f)
        counters = ev.own_state
        assert all(0 <= c <= p for c, p in zip(counters, previous))
        assert ended == (goals[0] or 0 in counters)
        previous = counters
        if ended:
            break


@given(sgst.trees(FEATURES), sgst.trajectories(FEATURES))
def test_root_goal_ends_the_episode(tree, trajectory):
    ev = ReferenceEvaluator(tree, FEATURES)
    ev.reset(trajectory[0])
    for f in trajectory[1:]:
        _, ended, goals, _ = ev.step(0, f)
        if goals[0]:
            assert ended
        if ended:
            break


def test_pendulum_refinements_share_the_root_goal_but_not_the_reward():
    from example_specs import pendulum

    up_fast, up_slow = (0.99, 0.0, 1.0), (0.99, 0.0, 0.1)
    for tree_key in "abcw":
        ev = ReferenceEvaluator(pendulum.trees[tree_key], ("x", "y", "omega"))
        ev.reset(up_fast)
        assert ev.step(0, up_slow)[1] is True  # every variant ends in the same goal
    rewards = {}
    for tree_key in "ab":
        ev = ReferenceEvaluator(pendulum.trees[tree_key], ("x", "y", "omega"))
        ev.reset((-1.0, 0.0, 1.0))
        rewards[tree_key] = ev.step(0, up_fast)[0]
    assert rewards == {"a": 0.0, "b": 0.5}  # (b) pays for reaching the position alone


@pytest.mark.parametrize("bad", [math.inf, math.nan, -1.0])
def test_distances_must_be_finite_and_non_negative(bad):
    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Distance(lambda s: s.b, scale=1.0))
    ev = ReferenceEvaluator(tree, FEATURES)
    ev.reset([5.0, 1.0, 0.0])
    message = rf"g:distance: expected a finite distance >= 0, got {bad!r} \(state State\(a=5.0, b={bad!r}, c=0.0\)\)"
    with pytest.raises(sg.error.EvaluationError, match=message):
        ev.step(0, [5.0, bad, 0.0])


def test_a_raising_distance_is_named():
    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Distance(lambda s: s.zz, scale=1.0))
    ev = ReferenceEvaluator(tree, FEATURES)
    ev.reset([5.0, 1.0, 0.0])
    with pytest.raises(sg.error.EvaluationError, match=r"g:distance: the distance function raised AttributeError"):
        ev.step(0, [5.0, 1.0, 0.0])
