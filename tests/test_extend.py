"""The extension protocol's defaults and helpers (the kit in test_contract.py checks whole operators)."""

from __future__ import annotations

import re

import pytest

import specguard as sg
from specguard.construction.initial_env import state_type
from specguard.extend import ChildWeights, Context, Node, Slot, check_children, component_weights, goal_test

State = state_type(("x", "y"))


class Bare(Node):
    kind = "Bare"

    def __init__(self, *children: Node, name: str) -> None:
        self.nodes, self.name, self.annotations = children, name, ()

    @property
    def children(self) -> tuple[Node, ...]:
        return self.nodes

    def contains(self, ctx: Context) -> bool:
        return all(ctx.inside)

    def describe(self) -> str:
        return f"Bare {self.name!r}"


def test_defaults_are_the_and_operators():
    node = Bare(sg.Goal("a", x=(0, 1)), sg.Goal("b", y=(0, 1)), name="r")
    assert node.child_weights() == (ChildWeights.same(0.5),) * 2
    ctx = Context(State(0.5, 0.5), (), (True, True))
    assert node.potential(ctx) == 1.0  # membership
    assert node.reward(Context(State(5.0, 0.5), (), (False, True)), 0, ctx) == 1.0
    assert node.terminates(ctx, (False, True)) is True and node.terminates(ctx, (False, False)) is False
    assert node.state_slots() == () and node.box([None, None]) is None
    assert node.formula_term("r") == "R[r]"
    assert sg.formula(node) == "R = R[r] + 0.5*R[a] + 0.5*R[b]"


def test_child_weights_by_role():
    w = ChildWeights(core=0.0, shaping=1.0, safety=0.5)
    assert (w.of("core"), w.of("shaping"), w.of("safety")) == (0.0, 1.0, 0.5)


def test_goal_test_evaluates_any_stateless_node_from_its_definition():
    test = goal_test(Bare(sg.Goal("a", x=(0, 1)), sg.Goal("b", y=(0, 1)), name="r"))
    assert test(State(0.5, 0.5)) is True and test(State(0.5, 2.0)) is False


def test_goal_test_refuses_a_node_with_own_state():
    class Counting(Bare):
        def state_slots(self) -> tuple[Slot, ...]:
            return (Slot("n", 0.0, 1.0),)

    with pytest.raises(sg.error.InvalidSpec, match=r"r: Bare has own state, so its goal is not a set of states"):
        goal_test(Counting(sg.Goal("a", x=(0, 1)), name="r"))


def test_check_children():
    with pytest.raises(sg.error.InvalidSpec, match=r"Bare 'r': expected at least one child node, got none"):
        check_children("Bare", "r", ())
    with pytest.raises(sg.error.InvalidSpec, match=r"two children are named 'a'"):
        check_children("Bare", "r", (sg.Goal("a", x=1), sg.Goal("a", y=1)))


def test_component_weights_normalise_shaping_only():
    g = sg.Goal("g", x=(0, 1)).annotate(sg.Distance(abs, scale=1.0), sg.Constraint(lambda s, a: False))
    assert component_weights(g) == (0.5, (0.5, 1.0))


def test_protocol_methods_a_node_must_state():
    class Nothing(Node):
        name, annotations = "n", ()

    with pytest.raises(NotImplementedError, match="Nothing must define contains"):
        Nothing().contains(Context(State(0.0, 0.0), (), ()))
    with pytest.raises(NotImplementedError, match="Nothing must define describe"):
        Nothing().describe()


# -- the constructor helpers: an operator states what it is, not how to set a frozen field ----------


def test_init_node_checks_and_sets_name_and_children_with_no_annotations():
    from dataclasses import dataclass

    @dataclass(frozen=True, init=False, repr=False)
    class Pair(Node):
        kind = "Pair"
        nodes: tuple[Node, ...]
        name: str

        def __init__(self, *children: Node, name: str) -> None:
            self.init_node(name, children)

        def contains(self, ctx: Context) -> bool:
            return all(ctx.inside)

        def describe(self) -> str:
            return f"Pair {self.name!r}"

    a, b = sg.Goal("a", x=(0, 1)), sg.Goal("b", y=(0, 1))
    pair = Pair(a, b, name="p")
    assert (pair.name, pair.children, pair.nodes, pair.annotations) == ("p", (a, b), (a, b), ())
    assert [path for path, _ in pair.walk()] == ["p", "p/a", "p/b"]
    assert pair.annotate(sg.Distance(abs, scale=1.0)).children == (a, b)
    with pytest.raises(sg.error.InvalidSpec, match="Pair 'p': expected at least one child node, got none"):
        Pair(name="p")
    with pytest.raises(sg.error.InvalidSpec, match=r"Pair 3: expected a non-empty string as name, got 3"):
        Pair(a, name=3)


def test_set_fields_sets_fields_of_a_frozen_dataclass():
    from dataclasses import FrozenInstanceError, dataclass

    from specguard.extend import set_fields

    @dataclass(frozen=True, init=False)
    class Frozen:
        x: int
        y: str

        def __init__(self) -> None:
            set_fields(self, x=1, y="two")

    frozen = Frozen()
    assert (frozen.x, frozen.y) == (1, "two")
    with pytest.raises(FrozenInstanceError):
        frozen.x = 2  # type: ignore[misc]


def test_a_leaf_has_no_children_by_default():
    assert sg.Goal("g", x=(0, 1)).children == ()


KIDS = (sg.Goal("a", x=1), sg.Goal("b", x=2))


def test_child_weights_none_is_the_default_and_numbers_become_floats():
    from specguard.extend import check_child_weights

    def check(weights):
        return check_child_weights("Op 'o'", KIDS, weights, scales="it", default="1 each")

    assert check(None) is None
    assert check([1, 0]) == (1.0, 0.0)
    assert all(type(w) is float for w in check((2, 3)))


@pytest.mark.parametrize(
    ("weights", "message"),
    [
        ((1,), "Op 'o': expected 2 weights (one per child), got 1: (1,)"),
        ((0, 0.0), "Op 'o': expected at least one weight > 0, got weights=(0, 0); a weight scales it, and all-zero"),
        ((1, -2), "Op 'o', weight of 'b': expected a finite weight >= 0, got -2"),
        ((1, None), "Op 'o': expected a number for every weight, got (1, None)"),
        ((True, 1), "Op 'o', weight of 'a': expected weight to be a number, got True"),
        ("ab", "Op 'o': expected weights to be a sequence of numbers (one per child), got 'ab'"),
        (3, "expected weights to be a sequence of numbers"),
    ],
)
def test_bad_child_weights_name_the_node_and_what_was_given(weights, message):
    from specguard.extend import check_child_weights

    with pytest.raises(sg.error.InvalidSpec) as e:
        check_child_weights("Op 'o'", KIDS, weights, scales="it", default="1 each")
    assert message in str(e.value)
    if "at least one" in message:
        assert e.value.hint == "weights need not sum to 1; omit weights= for 1 each"


def test_all_and_the_plugins_share_the_child_weights_rule():
    from specguard_plugins import AnyOf, Sequence

    for make in (sg.All, AnyOf, Sequence):
        for weights, says in [((1,), "expected 2 weights (one per child)"), ((0, 0), "at least one weight > 0")]:
            with pytest.raises(sg.error.InvalidSpec, match=re.escape(says)):
                make(*KIDS, name="n", weights=weights)
    with pytest.raises(sg.error.InvalidSpec, match="expected weights to be a sequence of numbers, None or 'auto'"):
        sg.All(*KIDS, name="n", weights="sometimes")
    assert sg.All(*KIDS, name="n", weights="auto").adapts_weights


def test_operators_carry_no_constructor_boilerplate():
    # The name/children/annotations block and the children property live in extend.Node, once.
    import inspect
    from pathlib import Path

    import specguard_plugins

    from specguard.tree import nodes

    root = Path(__file__).resolve().parent.parent
    sources = {
        "specguard/tree/nodes.py": inspect.getsource(nodes),
        "example_specs/at_least.py": (root / "example_specs" / "at_least.py").read_text(encoding="utf-8"),
        **{
            f"plugins/{m}.py": (Path(specguard_plugins.__file__).parent / f"{m}.py").read_text(encoding="utf-8")
            for m in ("anyof", "sequence", "avoid")
        },
    }
    for where, source in sources.items():
        assert "object.__setattr__(self" not in source, where
        assert "def children(self)" not in source, where
