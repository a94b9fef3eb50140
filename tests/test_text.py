"""The one table renderer."""

from __future__ import annotations

from specguard.utils.text import render_table


def test_columns_align_and_lines_have_no_trailing_spaces():
    lines = render_table(["a", "bb", "c"], [["xxx", "y", ""], ["z", "wwww", "v"]])
    assert lines == ["a    bb    c", "---  ----  -", "xxx  y", "z    wwww  v"]
    assert all(line == line.rstrip() for line in lines)
