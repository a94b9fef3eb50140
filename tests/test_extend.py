"""The extension protocol's defaults and helpers (the kit in test_contract.py checks whole operators)."""

from __future__ import annotations

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

    with pytest.raises(sg.InvalidSpec, match=r"r: Bare has own state, so its goal is not a set of states"):
        goal_test(Counting(sg.Goal("a", x=(0, 1)), name="r"))


def test_check_children():
    with pytest.raises(sg.InvalidSpec, match=r"Bare 'r': expected at least one child node, got none"):
        check_children("Bare", "r", ())
    with pytest.raises(sg.InvalidSpec, match=r"two children are named 'a'"):
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
