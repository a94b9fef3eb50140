"""specguard.testing: ReplayEnv, the simulator-free test double, and the contract kit's pytest side."""

from __future__ import annotations

import inspect
import subprocess
import sys

import pytest
from gymnasium.utils.env_checker import check_env

import specguard as sg
from specguard import testing
from specguard.testing import ReplayEnv


def test_replays_the_trajectory_and_truncates_at_its_end():
    env = ReplayEnv([[0.0], [1.0], [2.0]])
    assert env.reset(seed=0)[0].tolist() == [0.0]
    assert env.step(0)[0].tolist() == [1.0]
    obs, reward, terminated, truncated, _ = env.step(1)
    assert (obs.tolist(), reward, terminated, truncated) == ([2.0], 0.0, False, True)


def test_passes_gymnasium_checker():
    check_env(ReplayEnv([[0.0, 1.0], [1.0, 2.0], [2.0, 3.0]]), skip_render_check=True)


def test_needs_two_observations():
    with pytest.raises(ValueError, match="at least two observations"):
        ReplayEnv([[0.0]])


# -- the contract kit's pytest side (tests/test_contract.py runs the checks) --


@pytest.mark.slow
def test_importing_the_kit_imports_neither_pytest_nor_hypothesis():
    code = "import sys, specguard.testing; print(sorted({'pytest', 'hypothesis'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_checks_lists_every_check_and_each_states_one_invariant():
    from specguard.contract import invariants as contract

    assert testing.CHECKS == contract.CHECKS
    assert [c.__name__ for c in testing.CHECKS] == [
        "check_observations_in_space",
        "check_rewards_are_finite_sums_of_terms",
        "check_core_reward_telescopes",
        "check_markov",
        "check_state_methods_have_slots",
        "check_contains_depends_on_ctx_alone",
        "check_reset_restores_own_state",
        "check_termination_includes_children",
        "check_flat_matches_reference",
        "check_description_is_exact",
        "check_refinement_preserves_root_goal",
    ]
    for check in testing.CHECKS:
        assert check.__doc__.strip().splitlines()[0].endswith("."), check.__name__
        assert set(inspect.signature(check).parameters) == {"cls", "max_examples"}


def test_checks_for_picks_what_applies():
    names = {cls: [c.__name__ for c in testing.checks_for(cls)] for cls in (sg.All, sg.Goal, sg.Distance)}
    assert "check_refinement_preserves_root_goal" in names[sg.All]
    assert "check_termination_includes_children" in names[sg.All]
    for cls in (sg.Goal, sg.Distance):  # a leaf and an annotation: no children to end, nothing to refine
        assert "check_termination_includes_children" not in names[cls]
        assert "check_refinement_preserves_root_goal" not in names[cls]
    assert "check_contains_depends_on_ctx_alone" in names[sg.Goal]  # a node's goal; an annotation has none
    assert "check_contains_depends_on_ctx_alone" not in names[sg.Distance]
    assert len(names[sg.Goal]) == 9
    assert len(names[sg.Distance]) == 8


@pytest.mark.parametrize("bad", [object, sg.Goal("g", x=(0, 1)), "All", int])
def test_kit_refuses_what_is_not_an_operator_or_annotation_class(bad):
    with pytest.raises(TypeError, match="expected a Node or Annotation subclass"):
        testing.parametrize_with_checks([bad])
    with pytest.raises(TypeError, match="expected a Node or Annotation subclass"):
        testing.check_operator(bad)


def test_parametrize_with_checks_ids_name_class_and_check():
    marker = testing.parametrize_with_checks([sg.Distance])
    argnames, params = marker.args
    assert argnames == "operator, check"
    assert [p.id for p in params] == [f"Distance-{c.__name__}" for c in testing.checks_for(sg.Distance)]
    assert all(p.values[0] is sg.Distance for p in params)


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'NOPE'"):
        _ = testing.NOPE
