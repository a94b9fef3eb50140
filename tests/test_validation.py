"""The one validator: uniform messages naming the place, what was expected and what was given."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

import specguard as sg
from specguard.validation import (
    check_budget,
    check_callable,
    check_name,
    check_positive,
    check_weight,
    function_text,
    number_text,
)


@given(st.floats(allow_nan=False))
def test_numbers_are_written_exactly(x):
    assert float(number_text(x)) == x


def test_whole_numbers_drop_their_point():
    assert (number_text(1.0), number_text(-0.0), number_text(2.5), number_text(math.inf)) == ("1", "-0", "2.5", "inf")


def test_names():
    assert type(check_name("Goal", type("S", (str,), {})("up"))) is str  # a str subclass becomes a plain str
    with pytest.raises(sg.InvalidSpec, match=r"Goal 'a/b': a name may not contain '/'"):
        check_name("Goal", "a/b")
    with pytest.raises(sg.InvalidSpec, match=r"Goal ' ': expected a non-empty string as name, got ' '"):
        check_name("Goal", " ")


@pytest.mark.parametrize(
    ("check", "value", "message"),
    [
        (lambda v: check_weight("All 'r'", v), -1, r"All 'r': expected a finite weight >= 0, got -1"),
        (lambda v: check_weight("All 'r'", v), True, r"All 'r': expected weight to be a number, got True"),
        (lambda v: check_positive("D", "scale", v, "the largest distance"), 0, r"D: expected scale > 0 \(the largest"),
        (lambda v: check_budget("C", v), 0, r"C: expected budget to be an integer >= 1 .*got 0"),
        (lambda v: check_callable("C", v, "fn(s, a)"), 3, r"C: expected fn to be callable as fn\(s, a\), got 3"),
    ],
)
def test_bad_arguments_are_named(check, value, message):
    with pytest.raises(sg.InvalidSpec, match=message):
        check(value)


def test_function_text_never_holds_an_address():
    def inner(s):  # type: ignore[no-untyped-def]
        return s

    class Callable_:
        def __call__(self, s):  # type: ignore[no-untyped-def]
            return s

    assert function_text(inner) == "inner"
    assert function_text(abs) == "abs"
    assert function_text(Callable_()) == "Callable_"
