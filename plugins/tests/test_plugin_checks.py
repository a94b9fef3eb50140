"""The shared weight check: one finite number >= 0 per child, one of them > 0, errors naming the node."""

from __future__ import annotations

import pytest
from specguard_plugins._checks import check_weights, weights_text

import specguard as sg
from specguard.error import InvalidSpec

KIDS = (sg.Goal("a", x=1), sg.Goal("b", x=2))


def test_none_is_the_default_and_numbers_become_floats():
    assert check_weights("Op 'o'", KIDS, None, "it") is None
    assert check_weights("Op 'o'", KIDS, [1, 0], "it") == (1.0, 0.0)
    assert all(type(w) is float for w in check_weights("Op 'o'", KIDS, (2, 3), "it"))


@pytest.mark.parametrize(
    ("weights", "message"),
    [
        ((1,), "Op 'o': expected 2 weights (one per child), got 1: (1,)"),
        ((0, 0.0), "Op 'o': expected at least one weight > 0, got weights=(0, 0); a weight scales it"),
        ((1, -2), "Op 'o', weight of 'b': expected a finite weight >= 0, got -2"),
        ((1, None), "Op 'o': expected a number for every weight, got (1, None)"),
        ("ab", "Op 'o': expected weights to be a sequence of numbers (one per child), got 'ab'"),
        (3, "expected weights to be a sequence of numbers"),
    ],
)
def test_bad_weights_name_the_node_and_what_was_given(weights, message):
    with pytest.raises(InvalidSpec) as e:
        check_weights("Op 'o'", KIDS, weights, "it")
    assert message in str(e.value)


def test_weights_text_is_exact():
    assert weights_text(None) == ""
    assert weights_text((0.1 + 0.2, 1.0, 2.5)) == " weights=(0.30000000000000004, 1, 2.5)"
