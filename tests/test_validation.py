"""The one validator: uniform messages naming the place, what was expected and what was given."""

from __future__ import annotations

import ast
import math
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import specguard as sg
from specguard.utils.node_paths import child_path
from specguard.utils.parsing import parse_choice, parse_count, parse_natural, parse_positive
from specguard.validation import (
    check_budget,
    check_callable,
    check_choice,
    check_count,
    check_finite,
    check_flag,
    check_name,
    check_natural,
    check_open_fraction,
    check_positive,
    check_text,
    check_unique,
    check_weight,
)


def test_names():
    assert type(check_name("Goal", type("S", (str,), {})("up"))) is str  # a str subclass becomes a plain str
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal 'a/b': a name may not contain '/'"):
        check_name("Goal", "a/b")
    with pytest.raises(sg.error.InvalidSpec, match=r"Goal ' ': expected a non-empty string as name, got ' '"):
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
    with pytest.raises(sg.error.InvalidSpec, match=message):
        check(value)


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
    with pytest.raises(sg.error.InvalidSpec, match=message):
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
    with pytest.raises(sg.error.InvalidSpec, match=r"Here: expected x to be a finite number > 0 \(a scale\), got "):
        check_positive("Here", "x", value, "a scale")
    with pytest.raises(ValueError, match=r"^expected a finite number > 0, got "):
        parse_positive(value)


def test_text_is_a_positive_number_only_as_option_text():
    assert parse_positive("1") == 1.0
    with pytest.raises(sg.error.InvalidSpec, match=r"Here: expected x to be a finite number > 0, got '1'"):
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
    # each built parent/child themselves; utils.node_paths.child_path is the one place now
    assert hand_built_paths(path.read_text()) == [], f"{path}: build node paths with utils.node_paths.child_path"


# -- open fractions, choices, counts from zero, finite numbers, flags, texts, unique names -------------------------


@pytest.mark.parametrize("value", [0.5, 1e-9, 0.999, np.float64(0.05), Fraction(1, 3)])
def test_open_fractions_lie_strictly_between_zero_and_one(value):
    assert check_open_fraction("Here", "p", value) == float(value)


@pytest.mark.parametrize("value", [0, 0.0, 1, 1.0, -0.1, 2, math.nan, math.inf, True, "0.5", None, np.bool_(True)])
def test_an_open_fraction_is_never_an_end_nan_a_bool_or_text(value):
    message = rf"Here: expected p to be a number in \(0, 1\) \(a level\), got {re.escape(repr(value))}\n"
    with pytest.raises(sg.error.InvalidSpec, match=message):
        check_open_fraction("Here", "p", value, "a level")


def test_choices_are_checked_in_specs_and_read_from_option_text():
    assert check_choice("Spec 's'", "undecided", "xfail", ("fail", "xfail")) == "xfail"
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Spec 's': expected undecided to be one of fail, xfail, got 'maybe'\n"
    ):
        check_choice("Spec 's'", "undecided", "maybe", ("fail", "xfail"))
    with pytest.raises(sg.error.InvalidSpec, match=r"got \['fail'\]"):  # unhashable: refused, not a TypeError
        check_choice("Spec 's'", "undecided", ["fail"], ("fail", "xfail"))
    assert parse_choice(" pass ", ("fail", "pass")) == "pass"
    with pytest.raises(ValueError, match=r"^expected one of fail, pass, got 'PASS'$"):
        parse_choice("PASS", ("fail", "pass"))


@pytest.mark.parametrize("value", [0, 1, 7, np.int64(3), 2**40])
def test_natural_numbers_start_at_zero(value):
    assert check_natural("Here", "seed", value) == value and type(check_natural("Here", "seed", value)) is int


@pytest.mark.parametrize("value", [-1, np.int64(-1), True, 1.0, "3", None])
def test_a_natural_number_is_never_negative_a_bool_a_float_or_text(value):
    message = rf"Here: expected seed to be an integer >= 0 \(a seed\), got {re.escape(repr(value))}\n"
    with pytest.raises(sg.error.InvalidSpec, match=message):
        check_natural("Here", "seed", value, "a seed")


@pytest.mark.parametrize(("text", "value"), [("0", 0), (" 12 ", 12)])
def test_natural_numbers_from_option_text(text, value):
    assert parse_natural(text) == value


@pytest.mark.parametrize("text", ["-1", "00", "+1", "1.0", "", "x"])
def test_natural_option_text_is_plain_digits(text):
    with pytest.raises(ValueError, match=rf"^expected an integer >= 0 \(a seed\), got {re.escape(repr(text))}$"):
        parse_natural(text, "a seed")


@pytest.mark.parametrize("value", [0, -2.5, np.float32(1.5), Fraction(1, 2)])
def test_finite_numbers(value):
    assert check_finite("Here", "lo", value) == float(value)


@pytest.mark.parametrize("value", ["0", True, np.bool_(False), math.nan, -math.inf, None, 1j])
def test_a_finite_number_is_never_text_a_bool_or_infinite(value):
    with pytest.raises(
        sg.error.InvalidSpec, match=rf"Here: expected lo to be a finite number, got {re.escape(repr(value))}"
    ):
        check_finite("Here", "lo", value)


def test_flags_are_bools_only():
    assert check_flag("Here", "on", np.bool_(True)) is True and check_flag("Here", "on", False) is False
    for value in ("no", 1, 0, None):
        with pytest.raises(sg.error.InvalidSpec, match=rf"Here: expected on to be True or False, got {value!r}"):
            check_flag("Here", "on", value)


def test_texts_are_non_empty_strings():
    assert type(check_text("Here", "a name", type("S", (str,), {})("x"))) is str
    for value in (5, None, "", " ", b"x"):
        with pytest.raises(
            sg.error.InvalidSpec, match=rf"Here: expected a name to be a non-empty string, got {value!r}"
        ):
            check_text("Here", "a name", value)


def test_names_given_twice_are_named_with_both_values():
    assert check_unique("--starts", [("x", 1), ("y", 2)]) == {"x": 1, "y": 2}
    with pytest.raises(sg.error.InvalidSpec, match=r"^--starts: 'x' is given twice: \(0, 1\), then \(2, 3\)\n"):
        check_unique("--starts", [("x", (0, 1)), ("y", (0, 1)), ("x", (2, 3))])


# -- one voice: each rule is written in validation.py only -------------------------------------------------------


def _open_unit_checks(source: str) -> list[int]:
    """Lines of ``source`` that compare a value strictly between the literals 0 and 1 (``0 < x < 1``)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Compare) and len(node.ops) == 2 and all(isinstance(o, ast.Lt) for o in node.ops):
            ends = (node.left, node.comparators[1])
            if all(isinstance(e, ast.Constant) for e in ends) and [e.value for e in ends] == [0, 1]:  # type: ignore
                found.append(node.lineno)
    return sorted(found)


def test_the_open_interval_finder_finds_them():
    assert _open_unit_checks("if not 0.0 < a < 1.0:\n    pass\nb = 0 < c < 1\nd = 0 <= e < 1\n") == [1, 3]


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(ROOT_DIR)))
def test_every_open_interval_check_is_check_open_fraction(path):
    if path.name == "validation.py" and path.parent.name == "specguard":
        return
    assert _open_unit_checks(path.read_text()) == [], "use specguard.validation.check_open_fraction"


def test_the_default_cache_dir_is_written_once():
    package = Path(sg.__file__).parent
    writers = [p.relative_to(package) for p in sorted(package.rglob("*.py")) if '".specguard/cache"' in p.read_text()]
    assert writers == [Path("utils/atomic.py")]
