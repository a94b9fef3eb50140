"""The contract kit: built-ins pass every check; each broken operator is caught by the right one, readably."""

from __future__ import annotations

import re

import broken_operators as broken
import numpy as np
import pytest

import specguard as sg
from specguard.construction.env import SpecEnv
from specguard.contract import invariants as contract
from specguard.contract.invariants import FRESH_INTERPRETER
from specguard.testing import check_operator, parametrize_with_checks


@parametrize_with_checks([sg.All, sg.Always, sg.Goal, sg.Distance, sg.Constraint])
def test_builtins_keep_the_contract(operator, check):
    check(operator)


@pytest.mark.parametrize(
    "cls, check_name",
    [
        pytest.param(
            cls,
            name,
            id=cls.__name__,
            marks=[pytest.mark.slow] if getattr(contract, name) in FRESH_INTERPRETER else [],
        )
        for cls, name in broken.CAUGHT_BY.items()
    ],
)
def test_broken_operator_is_caught_by_the_right_check(cls, check_name):
    check = getattr(contract, check_name)
    # 150 examples: Hypothesis draws some values from the constants of the local modules loaded, so which examples a
    # derandomized run draws changes with the code and the tests run before. Hidden episode state
    # (ModuleStateSequence, ClassStateSequence) is missed by 1 in 6 runs of check_markov at 40 examples even with its
    # states moved into the goals (visiting_cases); each broken operator is caught long before 150.
    with pytest.raises(AssertionError) as caught:
        check(cls, max_examples=150)
    message = str(caught.value)
    invariant = check.__doc__.strip().splitlines()[0]
    assert message.startswith(f"{check_name} failed for {cls.__name__}.\nInvariant: {invariant}\n")
    # The shrunk tree, pretty-printed: the operator's own line, its children drawn below it.
    tree = message.split("\ntree:\n", 1)[1].split("\n\n", 1)[0]
    root = tree.splitlines()[1 if check_name == "check_refinement_preserves_root_goal" else 0].strip()
    assert root.startswith(cls.kind) or f"{cls.__name__} object at 0x" in root
    assert re.search(r"^    [└├]── \w+ '\w+'", tree, re.MULTILINE)
    if check_name not in ("check_description_is_exact", "check_state_methods_have_slots"):  # tree-only checks
        assert re.search(r"^    s0 = \(-?\d", message, re.MULTILINE)
    assert "\nWhat breaks it: " in message


def test_a_failure_reads_as_the_smallest_counterexample():
    with pytest.raises(AssertionError) as caught:
        contract.check_core_reward_telescopes(broken.PaysEveryStep)
    assert str(caught.value) == "\n".join(
        [
            "check_core_reward_telescopes failed for PaysEveryStep.",
            "Invariant: Over any trajectory, the rewards of every node/annotation of the class sum to "
            "potential(last) - potential(first).",
            "",
            "tree:",
            "    PaysEveryStep 'root'",
            "    └── Goal 'n0': a >= -2",
            "",
            "trajectory (state s_t, then the action a_t taken in it), features (a, b, c):",
            "    s0 = (-2.0, -2.0, -2.0)   a0 = 0",
            "    s1 = (-2.0, -2.0, -2.0)",
            "",
            "What breaks it: the rewards of node 'root' (PaysEveryStep) sum to 1.0, but potential(last) - "
            "potential(first) = 1.0 - 1.0 = 0.0; rewards per step [1.0], potentials [1.0, 1.0]",
        ]
    )


@pytest.mark.parametrize(
    "cls, check",
    [
        (broken.PaysEveryStep, contract.check_markov),  # wrong, but Markov and evaluated alike everywhere
        (broken.WrongBox, contract.check_markov),  # the env and step_batch both trust the wrong box
        (broken.OverfullLatch, contract.check_core_reward_telescopes),
    ],
    ids=lambda v: getattr(v, "__name__", None),
)
def test_checks_blame_only_what_is_broken(cls, check):
    check(cls, max_examples=20)


def test_a_slotless_operator_with_state_methods_is_caught_by_both_hidden_state_checks():
    # Its state methods run in no evaluator, so every env check passes; two named checks say why it is broken.
    with pytest.raises(AssertionError, match="declares no own-state slots") as caught:
        contract.check_state_methods_have_slots(broken.SlotlessSequence, max_examples=10)
    assert "overrides initial_state, next_state" in str(caught.value)
    with pytest.raises(AssertionError, match=r"contains\(ctx\) of node 'root' \(SlotlessSequence\) in s\d+ was"):
        contract.check_contains_depends_on_ctx_alone(broken.SlotlessSequence)
    for check in (contract.check_markov, contract.check_flat_matches_reference):  # blind to it, as the issue says
        check(broken.SlotlessSequence, max_examples=20)


def test_a_contains_that_reads_what_other_methods_left_is_caught():
    with pytest.raises(AssertionError, match="check_contains_depends_on_ctx_alone failed for HiddenSequence"):
        contract.check_contains_depends_on_ctx_alone(broken.HiddenSequence)


@pytest.mark.slow
def test_check_operator_runs_every_applicable_check_and_reports_each_failure():
    check_operator(sg.Distance, max_examples=5)
    with pytest.raises(AssertionError) as caught:
        check_operator(broken.AddressInDescribe, max_examples=10)
    message = str(caught.value)
    assert message.startswith("1 contract check(s) failed for AddressInDescribe:")
    assert "check_description_is_exact failed for AddressInDescribe." in message


@pytest.mark.slow
def test_operator_author_example_from_extend_passes():
    # The "at least k of the children" operator of specguard.extend's docstring keeps the contract.
    from specguard.extend import ChildWeights, Context, Node

    class AtLeast(Node):
        kind = "AtLeast"

        def __init__(self, *children, name, k=1):
            self.init_node(name, children)
            self.k = k

        def child_weights(self):
            return (ChildWeights(core=0.0, shaping=1.0, safety=1.0),) * len(self.nodes)

        def contains(self, ctx: Context) -> bool:
            return sum(ctx.inside) >= self.k

        def describe(self) -> str:
            return f"AtLeast {self.name!r} k={self.k}"

    for check in contract.checks_for(AtLeast):
        check(AtLeast, max_examples=15)


def test_parametrize_with_checks_makes_one_readable_item_per_check(pytester):
    pytester.makepyfile(
        """
        import specguard as sg
        from specguard.testing import parametrize_with_checks

        @parametrize_with_checks([sg.All, sg.Constraint])
        def test_contract(operator, check):
            check(operator, max_examples=5)
        """
    )
    collected = pytester.runpytest("--collect-only", "-q", "-p", "no:cacheprovider")
    ids = [line for line in collected.stdout.lines if "::test_contract[" in line]
    assert ids == [
        f"test_parametrize_with_checks_makes_one_readable_item_per_check.py::test_contract[{i}]"
        for i in [
            "All-check_observations_in_space",
            "All-check_rewards_are_finite_sums_of_terms",
            "All-check_core_reward_telescopes",
            "All-check_markov",
            "All-check_state_methods_have_slots",
            "All-check_contains_depends_on_ctx_alone",
            "All-check_reset_restores_own_state",
            "All-check_termination_includes_children",
            "All-check_flat_matches_reference",
            "All-check_description_is_exact",
            "All-check_refinement_preserves_root_goal",
            "Constraint-check_observations_in_space",
            "Constraint-check_rewards_are_finite_sums_of_terms",
            "Constraint-check_core_reward_telescopes",
            "Constraint-check_markov",
            "Constraint-check_state_methods_have_slots",
            "Constraint-check_reset_restores_own_state",
            "Constraint-check_flat_matches_reference",
            "Constraint-check_description_is_exact",
        ]
    ]
    result = pytester.runpytest("-q", "-p", "no:cacheprovider", "-k", "Constraint-check_markov")
    result.assert_outcomes(passed=1, deselected=18)


@pytest.mark.parametrize(
    "wrong, says",
    [
        (lambda reward: reward + 0.5, "!= the sum"),  # a reward that is not the sum of its reported terms
        (lambda reward: np.float64(reward), "not a Python float"),
    ],
    ids=["not-the-sum", "numpy-float"],
)
def test_rewards_check_catches_an_env_that_misreports(monkeypatch, wrong, says):
    step = SpecEnv.step

    def misreporting(self, action):
        obs, reward, terminated, truncated, info = step(self, action)
        return obs, wrong(reward), terminated, truncated, info

    monkeypatch.setattr(SpecEnv, "step", misreporting)
    with pytest.raises(AssertionError, match=says):
        contract.check_rewards_are_finite_sums_of_terms(sg.All, max_examples=10)


def test_a_state_moved_into_a_goal_box_lies_in_it():
    # check_markov's examples move states into the goals of the tree's nodes (contract.trees.visiting_cases).
    import math

    from specguard.contract.trees import _inside

    box = {"a": (0.1, 0.3), "b": (-math.inf, -2.0), "c": (5.0, math.inf)}
    moved = _inside(box, [9.0, 9.0, 9.0])
    assert all(lo <= v <= hi for v, (lo, hi) in zip(moved, box.values(), strict=True))
    assert moved[1:] == [-2.0, 5.0]  # a one-sided range: its bound
    assert _inside({"b": (1.0, 2.0)}, [7.0, 0.0, 8.0]) == [7.0, 1.5, 8.0]  # the other features are kept
