"""Text every door writes the same way: tables, numbers written exactly, user functions by name."""

from __future__ import annotations

import math

from hypothesis import given
from hypothesis import strategies as st

from specguard.utils.text import MAX_CELL, elide, function_text, number_text, render_table


def test_columns_align_and_lines_have_no_trailing_spaces():
    lines = render_table(["a", "bb", "c"], [["xxx", "y", ""], ["z", "wwww", "v"]])
    assert lines == ["a    bb    c", "---  ----  -", "xxx  y", "z    wwww  v"]
    assert all(line == line.rstrip() for line in lines)


def test_a_long_cell_is_elided_in_the_middle_and_the_columns_stay_narrow():
    key = "specs.py::test_" + "x" * 300 + "_end"
    lines = render_table(["spec", "goal", "note"], [[key, "up", "a long last cell " * 20], ["s", "down", "ok"]])
    width = MAX_CELL + 2 + 4 + 2
    assert all(len(line) <= width + len("a long last cell " * 20) for line in lines)
    first = lines[2].split("  ")[0]
    assert len(first) == MAX_CELL and first.startswith("specs.py::test_xxx") and first.endswith("xxx_end")
    assert "…" in first
    assert lines[2].endswith("a long last cell " * 19 + "a long last cell")  # the last column is never cut
    assert lines[3].startswith("s" + " " * (MAX_CELL + 1) + "down")


def test_elide_keeps_short_text_and_both_ends_of_long_text():
    assert elide("abc", 5) == "abc"
    assert elide("abcdefghij", 5) == "ab…ij" and len(elide("abcdefghij", 6)) == 6


@given(st.floats(allow_nan=False))
def test_numbers_are_written_exactly(x):
    assert float(number_text(x)) == x


def test_whole_numbers_drop_their_point():
    assert (number_text(1.0), number_text(-0.0), number_text(2.5), number_text(math.inf)) == ("1", "-0", "2.5", "inf")


def test_function_text_never_holds_an_address():
    def inner(s):  # type: ignore[no-untyped-def]
        return s

    class Callable_:
        def __call__(self, s):  # type: ignore[no-untyped-def]
            return s

    assert function_text(inner) == "inner"
    assert function_text(abs) == "abs"
    assert function_text(Callable_()) == "Callable_"
