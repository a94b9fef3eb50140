"""The @goal_spec decorator."""

from __future__ import annotations

import re

import pytest

import specguard as sg
from specguard.tree.keys import ROOT


def test_marks_and_uses_the_goal_fixture():
    @sg.goal_spec(expect={"a": 0.5}, xfail=["a"])
    def test_x():
        pass

    marks = {m.name: m for m in test_x.pytestmark}
    assert marks["usefixtures"].args == ("specguard_goal",)
    assert marks["goal_spec"].kwargs == {"expect": {"a": 0.5}, "xfail": {"a": "expected to miss its threshold"}}


def test_falsify_puts_its_check_on_the_mark():
    @sg.goal_spec(expect={"a": 0.5}, falsify={"x": (-1.0, 1.0)})
    def test_x():
        pass

    (mark,) = [m for m in test_x.pytestmark if m.name == "goal_spec"]
    assert mark.kwargs["falsify"] == sg.Falsify({"x": (-1.0, 1.0)})


def test_a_number_means_the_root():
    @sg.goal_spec(0.7)
    def test_x():
        pass

    assert test_x.pytestmark[-1].kwargs["expect"] == {ROOT: 0.7}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"expect": {"a": 1.0}}, r"expect\['a'\]: a threshold of 1 can never be met"),
        ({"expect": {}}, r"expected at least one threshold, got \{\}: there is nothing to assert"),
        ({"expect": {"a": 0.5}, "xfail": {"b": "why"}}, r"expected xfail to name goals that expect gives a threshold"),
        ({"xfail": 3}, r"expected xfail to be \{goal: reason\} or a list of goals, got 3"),
    ],
)
def test_bad_declarations(kwargs, message):
    # Collection goes on: the test becomes one item that fails with the error.
    marked = sg.goal_spec(**kwargs)(_a_test)
    mark = marked.pytestmark[-1]
    assert mark.kwargs["expect"] is None
    assert re.search(message, mark.kwargs["error"])


def _a_test():
    """A function for @goal_spec to decorate (pytest marks only functions that look like tests)."""


# -- sg.goal_specs: specs declared once, gated by their own thresholds -------------------------------------------


def tiny_specs():
    from example_specs import pendulum

    budget = sg.Budget(timesteps=10)
    return {
        "w": sg.Spec(
            pendulum.initial_env, pendulum.trees["w"], budget=budget, expect={"pendulum": 0.8, "position": 0.9}
        ),
        "b": sg.Spec(
            pendulum.initial_env,
            pendulum.trees["b"],
            budget=budget,
            expect={"pendulum": 0.8},
            xfail={"pendulum": "the paper's local optimum"},
        ),
    }


def test_goal_specs_has_one_case_per_spec_and_goal_with_the_specs_xfail_and_marks():
    test_x = sg.goal_specs(tiny_specs(), marks={"b": pytest.mark.filterwarnings("ignore")})
    cases = test_x.pytestmark[-1].kwargs["cases"]
    assert [c.id for c in cases] == ["w-pendulum", "w-pendulum/position", "b-pendulum"]
    assert [c.values[0].xfail for c in cases] == [None, None, "the paper's local optimum"]
    assert [[m.name for m in c.marks] for c in cases] == [[], [], ["filterwarnings"]]


@pytest.mark.parametrize(
    ("specs", "marks", "message"),
    [
        ({"x": 3}, None, r"goal_specs\['x'\]: expected a specguard.Spec or a specguard.AgentCheck, got int"),
        ({}, {"y": pytest.mark.filterwarnings("ignore")}, r"names specs \['y'\] that are not among \[\]"),
    ],
)
def test_goal_specs_rejects_what_it_cannot_gate(specs, marks, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        sg.goal_specs(specs, marks=marks)


def test_goal_specs_needs_thresholds():
    from example_specs import pendulum

    spec = sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(timesteps=10))
    with pytest.raises(sg.error.InvalidSpec, match=r"goal_specs\['w'\]: expected at least one threshold, got \{\}"):
        sg.goal_specs({"w": spec})
