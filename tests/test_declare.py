"""The @goal_spec decorator."""

from __future__ import annotations

import re

import pytest

import specguard as sg
from specguard.goals import ROOT


def test_marks_and_uses_the_goal_fixture():
    @sg.goal_spec(expect={"a": 0.5}, xfail=["a"])
    def test_x():
        pass

    marks = {m.name: m for m in test_x.pytestmark}
    assert marks["usefixtures"].args == ("specguard_goal",)
    assert marks["goal_spec"].kwargs == {"expect": {"a": 0.5}, "xfail": {"a": "expected to miss its threshold"}}


def test_a_number_means_the_root():
    @sg.goal_spec(0.7)
    def test_x():
        pass

    assert test_x.pytestmark[-1].kwargs["expect"] == {ROOT: 0.7}


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"expect": {"a": 1.0}}, r"expect\['a'\]: a threshold of 1 can never be met"),
        ({"expect": {}}, r"expected expect to be \{goal: min success\} or a number"),
        ({"expect": {"a": 0.5}, "xfail": {"b": "why"}}, r"xfail names goals \['b'\] that expect does not list"),
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
