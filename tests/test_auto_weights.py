"""Automatic weights: the rule, the adapter's window, and nodes that adapt."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

import specguard as sg
from specguard.extend import adapted_annotations
from specguard.training.auto_weights import (
    FLOOR,
    MIN_EPISODES,
    WeightAdapter,
    adapted_weights,
    adapting_nodes,
)

up = sg.Goal("up", x=(0.9, 1.0))
still = sg.Goal("still", v=(-0.1, 0.1))


def auto_tree(**kwargs):
    return sg.All(up, still, name="p", weights="auto", **kwargs)


@given(st.lists(st.integers(0, 100), min_size=1, max_size=6))
def test_adapted_weights_sum_to_one_and_favour_the_children_reached_less(successes):
    rates = [k / 100 for k in successes]  # shares of a window of 100 episodes
    weights = adapted_weights(rates)
    assert math.isclose(sum(weights), 1.0)
    assert all(w > 0 for w in weights)
    for i, j in zip(range(len(rates)), range(1, len(rates))):
        if rates[i] < rates[j]:
            assert weights[i] > weights[j]


def test_equal_success_gives_equal_weights_and_a_reached_child_keeps_the_floor():
    assert adapted_weights([0.3, 0.3, 0.3]) == pytest.approx((1 / 3,) * 3)
    assert adapted_weights([0.0, 1.0]) == pytest.approx(((1 + FLOOR) / (1 + 2 * FLOOR), FLOOR / (1 + 2 * FLOOR)))


def test_all_auto_starts_at_one_over_n_and_says_so():
    tree = auto_tree()
    assert tree.weights == "auto" and tree.adapts_weights
    assert tree.weights_in_force() == (0.5, 0.5)
    assert "weights=auto" in str(tree)
    assert not sg.All(up, still, name="p").adapts_weights


@pytest.mark.parametrize("weights", ["Auto", "uniform", b"auto"])
def test_all_rejects_other_words_for_weights(weights):
    with pytest.raises(sg.error.InvalidSpec, match=r"All 'p'.*None or 'auto'"):
        sg.All(up, still, name="p", weights=weights)


def test_adapting_nodes_finds_nested_auto_nodes_only():
    inner = sg.All(up, still, name="inner", weights="auto")
    tree = sg.All(inner, sg.Goal("far", x=(None, -0.5)), name="root", weights=(1, 2))
    assert adapting_nodes(tree) == {"root/inner": ("root/inner/up", "root/inner/still")}
    assert WeightAdapter.of(tree.children[1]) is None


def test_adapter_waits_for_enough_episodes_then_follows_the_window():
    adapter = WeightAdapter.of(auto_tree(), window=20)
    assert adapter is not None and adapter.in_force == {"p": (0.5, 0.5)}
    for _ in range(MIN_EPISODES - 1):
        adapter.observe({"p": False, "p/up": False, "p/still": True})
    assert adapter.update() is None and adapter.in_force == {"p": (0.5, 0.5)}
    adapter.observe({"p": False, "p/up": False, "p/still": True})
    assert adapter.update() == {"p": adapted_weights([0.0, 1.0])}
    for _ in range(20):  # the window forgets the hanging-still episodes
        adapter.observe({"p": True, "p/up": True, "p/still": True})
    assert adapter.rates() == {"p/up": 1.0, "p/still": 1.0}
    assert adapter.update() == {"p": (0.5, 0.5)}


def fast(s, a):
    return s.v > 1.0


def test_a_constraint_of_the_auto_node_left_at_its_default_weight_adapts_with_the_children():
    tree = auto_tree().annotate(sg.Constraint(fast, name="fast"), sg.Constraint(fast, name="kept", weight=2.0))
    inner = sg.All(up.annotate(sg.Constraint(fast, name="below")), still, name="p", weights="auto")
    assert adapted_annotations(tree) == (0,)  # "kept" has the weight its author set
    assert adapting_nodes(tree) == {"p": ("p/up", "p/still", "p:fast")}
    assert adapting_nodes(inner) == {"p": ("p/up", "p/still")}  # a child's constraint goes with the child
    adapter = WeightAdapter.of(tree)
    assert adapter is not None and adapter.in_force == {"p": (0.5, 0.5, 1.0)}  # 1/N per child, 1 per constraint
    for _ in range(MIN_EPISODES):  # it never speeds, and never holds still up there: the goals get the weight
        adapter.observe({"p": False, "p/up": False, "p/still": True}, {"p:fast": True, "p:kept": True})
    assert adapter.rates() == {"p/up": 0.0, "p/still": 1.0, "p:fast": 1.0}
    assert adapter.update() == {"p": adapted_weights([0.0, 1.0, 1.0])}
    assert adapter.in_force["p"][2] == pytest.approx(FLOOR / (1 + 3 * FLOOR))
