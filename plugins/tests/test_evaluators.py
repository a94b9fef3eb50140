"""The flat evaluator and the reference Algorithm 1 agree on random trees using the plugin's operators."""

from __future__ import annotations

from collections import namedtuple

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from specguard_plugins import AnyOf, Avoid, Sequence

import specguard as sg
from specguard import strategies as sgst
from specguard.construction.reference import ExtendedState, ReferenceEvaluator, process

FEATURES = ("a", "b", "c")
State = namedtuple("State", FEATURES)


def plugin_trees(**kwargs):
    return sgst.trees(
        FEATURES,
        operators=(sg.All, sg.Always, AnyOf, Sequence),
        annotations=(sg.Distance, sg.Constraint, Avoid),
        **kwargs,
    )


@given(plugin_trees(), sgst.trajectories(FEATURES, max_size=25), st.data())
def test_flat_and_reference_agree_step_by_step(tree, trajectory, data):
    actions = data.draw(st.lists(st.integers(0, 2), min_size=len(trajectory), max_size=len(trajectory)))
    flat = sg.compile_tree(tree, FEATURES).evaluator()
    ref = ReferenceEvaluator(tree, FEATURES)
    assert flat.paths == ref.paths
    assert flat.slots == ref.slots
    assert flat.safety_keys == ref.safety_keys
    assert flat.reset(trajectory[0]) == ref.reset(trajectory[0])
    assert flat.own_state == ref.own_state
    assert flat.safe == ref.safe
    for a, f in zip(actions, trajectory[1:]):
        r1, end1, goals1, terms1 = flat.step(a, f)
        r2, end2, goals2, terms2 = ref.step(a, f)
        assert type(r1) is float
        assert r1 == pytest.approx(r2, rel=1e-9, abs=1e-12)
        assert (end1, goals1) == (end2, goals2)
        assert list(terms1) == list(terms2)
        assert list(terms1.values()) == pytest.approx(list(terms2.values()), rel=1e-9, abs=1e-12)
        assert sum(terms1.values()) == pytest.approx(r1)
        assert flat.own_state == ref.own_state
        assert flat.safe == ref.safe
        if end1:
            break


@given(plugin_trees(), st.lists(sgst.states(FEATURES), min_size=1, max_size=20))
def test_batch_membership_agrees_with_reference(tree, batch):
    compiled = sg.compile_tree(tree, FEATURES)
    req = process(tree)
    members = compiled.members(np.asarray(batch))
    assert members.shape == (len(batch), len(compiled.paths))
    for row, f in zip(members, batch):
        s = State._make(f)
        x = ExtendedState(s, req.initial(s))
        assert row.tolist() == [req.goals[p](x) for p in compiled.paths]


@given(plugin_trees(), sgst.trajectories(FEATURES, max_size=12), st.data())
def test_step_batch_from_observations_agrees_with_the_episode(tree, trajectory, data):
    # What a Markov env must reproduce: each transition evaluated alone from its observation.
    actions = data.draw(st.lists(st.integers(0, 2), min_size=len(trajectory), max_size=len(trajectory)))
    compiled = sg.compile_tree(tree, FEATURES)
    ev = compiled.evaluator()
    ev.reset(trajectory[0])
    observations, episode = [], []
    for a, f in zip(actions, trajectory[1:]):
        observations.append(list(trajectory[len(observations)]) + list(ev.own_state))
        r, end, goals, _ = ev.step(a, f)
        episode.append((r, end, goals, list(ev.own_state)))
        if end:
            break
    n = len(episode)
    rewards, ended, goals, own = compiled.step_batch(
        np.asarray(observations), actions[:n], np.asarray(trajectory[1 : n + 1])
    )
    assert rewards.tolist() == pytest.approx([e[0] for e in episode], rel=1e-9, abs=1e-12)
    assert ended.tolist() == [e[1] for e in episode]
    assert [tuple(g) for g in goals.tolist()] == [e[2] for e in episode]
    assert own.tolist() == [e[3] for e in episode]


@given(
    sgst.trees(FEATURES, operators=(sg.All, AnyOf), annotations=(sg.Distance, sg.Constraint, Avoid)),
    st.data(),
)
def test_batch_rewards_of_stateless_trees_agree_with_reference(tree, data):
    # Without a Sequence the own state is only counters, which the batch path starts afresh from each state.
    n = data.draw(st.integers(1, 20))
    s = data.draw(st.lists(sgst.states(FEATURES), min_size=n, max_size=n))
    s2 = data.draw(st.lists(sgst.states(FEATURES), min_size=n, max_size=n))
    actions = data.draw(st.lists(st.integers(0, 2), min_size=n, max_size=n))
    compiled = sg.compile_tree(tree, FEATURES)
    req = process(tree)
    terms = compiled.reward_terms(np.asarray(s), np.asarray(actions), np.asarray(s2))
    for i in range(n):
        first, second = State._make(s[i]), State._make(s2[i])
        ext = ExtendedState(first, req.initial(first))
        ext2 = ExtendedState(second, req.transition(ext, actions[i], second, False))
        expected = req.reward(ext, actions[i], ext2)
        assert list(expected) == list(compiled.term_keys)
        assert terms[i].tolist() == pytest.approx(list(expected.values()), rel=1e-9, abs=1e-12)
