"""The one validator: uniform messages naming the place, what was expected and what was given."""

from __future__ import annotations

import ast
import math
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import specguard as sg
from specguard.validation import (
    check_budget,
    check_callable,
    check_count,
    check_name,
    check_positive,
    check_weight,
    child_path,
    function_text,
    number_text,
    parse_count,
    parse_positive,
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
        (
            lambda v: check_positive("D", "scale", v, "the largest distance"),
            0,
            r"D: expected scale to be a finite number > 0 \(the largest distance\), got 0",
        ),
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


# -- counts: integers >= 1, in specs (check_count) and in option text (parse_count) ------------------------------

COUNTS = [1, 3, np.int64(4), np.uint8(2)]  # numpy integers are integers
NOT_COUNTS = [0, -1, True, False, 1.0, 2.5, np.float64(2), Fraction(3), "3", None, np.bool_(True)]


@pytest.mark.parametrize("value", COUNTS)
def test_counts_are_integers_from_one(value):
    assert check_count("Here", "n", value) == value and type(check_count("Here", "n", value)) is int
    assert parse_count(value) == value and type(parse_count(value)) is int


@pytest.mark.parametrize("value", NOT_COUNTS)
def test_a_count_is_never_a_bool_a_float_or_text(value):
    # "3" is a count only as option text (parse_count), not as a spec's argument
    message = rf"Here: expected n to be an integer >= 1 \(runs\), got {re.escape(repr(value))}\n"
    with pytest.raises(sg.InvalidSpec, match=message):
        check_count("Here", "n", value, "runs")


@pytest.mark.parametrize(("text", "value"), [("1", 1), ("12", 12), (" 4 ", 4), ("4\n", 4)])
def test_counts_from_option_text(text, value):
    assert parse_count(text) == value


@pytest.mark.parametrize("text", ["0", "05", "007", "-1", "+3", "1_000", "2.5", "1e3", "\u0663", "", " ", "two"])
def test_count_text_is_plain_digits_without_a_leading_zero(text):
    # "05" was a worker count (str.isdigit) but not a checkpoint count; "\u0663" is an Arabic-Indic 3
    with pytest.raises(ValueError, match=rf"^expected an integer >= 1 \(runs\), got {re.escape(repr(text))}$"):
        parse_count(text, "runs")


@pytest.mark.parametrize("value", [True, 2.0, None, np.float64(2)])
def test_count_options_given_as_values_follow_the_same_rule(value):
    with pytest.raises(ValueError, match=r"expected an integer >= 1, got "):
        parse_count(value)


# -- positive numbers: finite reals > 0, in specs (check_positive) and in option text (parse_positive) ----------

POSITIVE = [1, 0.25, 1e-300, np.float64(0.5), np.int64(2), Fraction(1, 3)]
NOT_POSITIVE = [0, -1, -0.0, math.inf, -math.inf, math.nan, np.float64("inf"), True, None]


@pytest.mark.parametrize("value", POSITIVE)
def test_positive_numbers_are_finite_and_above_zero(value):
    assert check_positive("Here", "x", value) == float(value) and type(check_positive("Here", "x", value)) is float
    assert parse_positive(value) == float(value)


@pytest.mark.parametrize("value", NOT_POSITIVE)
def test_a_positive_number_is_never_infinite_nan_or_a_bool(value):
    with pytest.raises(sg.InvalidSpec, match=r"Here: expected x to be a finite number > 0 \(a scale\), got "):
        check_positive("Here", "x", value, "a scale")
    with pytest.raises(ValueError, match=r"^expected a finite number > 0, got "):
        parse_positive(value)


def test_text_is_a_positive_number_only_as_option_text():
    assert parse_positive("1") == 1.0
    with pytest.raises(sg.InvalidSpec, match=r"Here: expected x to be a finite number > 0, got '1'"):
        check_positive("Here", "x", "1")


@pytest.mark.parametrize(("text", "value"), [("1", 1.0), (" 0.25 ", 0.25), ("2e-3", 0.002)])
def test_positive_numbers_from_option_text(text, value):
    assert parse_positive(text) == value


@pytest.mark.parametrize("text", ["0", "-1", "inf", "Infinity", "nan", "1e999", "1e-999", "", "half"])
def test_positive_option_text_refuses_infinity_and_zero(text):
    # "1e999" reads as inf and "1e-999" as 0: neither is a usable scale
    with pytest.raises(ValueError, match=rf"^expected a finite number > 0 \(a scale\), got {re.escape(repr(text))}$"):
        parse_positive(text, "a scale")


# -- node paths: built in one place ------------------------------------------------------------------------------


def test_child_paths():
    assert child_path("pendulum", "position") == "pendulum/position"
    assert child_path("pendulum/position", "x") == "pendulum/position/x"
    assert child_path("", "pendulum") == "pendulum"  # a root has no parent: its path is its name


def test_tree_paths_are_child_paths():
    tree = sg.All(sg.All(sg.Goal("x", a=0), name="l"), sg.Goal("y", a=1), name="root")
    assert [p for p, _ in tree.walk()] == [
        "root",
        child_path("root", "l"),
        child_path(child_path("root", "l"), "x"),
        child_path("root", "y"),
    ]


ROOT_DIR = Path(__file__).resolve().parent.parent
SOURCES = sorted((ROOT_DIR / "specguard").rglob("*.py")) + sorted(
    (ROOT_DIR / "plugins/specguard_plugins").rglob("*.py")
)


def _is_separator(node: ast.AST) -> bool:
    if isinstance(node, ast.Constant):
        return node.value == "/"
    return (
        isinstance(node, ast.FormattedValue) and isinstance(node.value, ast.Name) and node.value.id == "PATH_SEPARATOR"
    )


def _is_name_of_a_node(node: ast.AST) -> bool:
    value = node.value if isinstance(node, ast.FormattedValue) else node
    return isinstance(value, ast.Attribute) and value.attr == "name"


def hand_built_paths(source: str) -> list[int]:
    """Lines that join a path variable, the separator and a node's name by hand: ``f"{path}/{c.name}"``,
    ``f"{path}{PATH_SEPARATOR}{c.name}"``, ``path + "/" + c.name``."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.JoinedStr):
            parts = node.values
            for first, sep, last in zip(parts, parts[1:], parts[2:]):
                if (
                    isinstance(first, ast.FormattedValue)
                    and isinstance(first.value, ast.Name)
                    and _is_separator(sep)
                    and _is_name_of_a_node(last)
                ):
                    lines.append(node.lineno)
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add) and _is_name_of_a_node(node.right):
            left = node.left
            if isinstance(left, ast.BinOp) and isinstance(left.left, ast.Name) and _is_separator(left.right):
                lines.append(node.lineno)
    return lines


def test_the_hand_built_path_finder_finds_them():
    assert hand_built_paths('f"{path}/{c.name}"\nf"{p}{PATH_SEPARATOR}{self.name}"\npath + "/" + c.name') == [1, 2, 3]
    assert hand_built_paths('child_path(path, c.name)\nf"{folder.name}/{png.name}"\nf"{k}/{n}"') == []


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT_DIR)))
def test_every_child_path_is_built_by_child_path(path):
    # tree walks, compiled envs, reference rewards, contract checks, auto weights, formulas and the gate's hints
    # each built parent/child themselves; validation.child_path is the one place now
    assert hand_built_paths(path.read_text()) == [], f"{path}: build node paths with validation.child_path"
