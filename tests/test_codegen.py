"""The generated step code: only the tree's meaning reaches it, never user text."""

from __future__ import annotations

import ast

import pytest
from hypothesis import given
from hypothesis import strategies as st

import specguard as sg
from specguard import strategies as sgst
from specguard.construction.compiled import compile_tree
from specguard.construction.reference import ReferenceEvaluator
from specguard.extend import ChildWeights, Context, Node, Slot

FEATURES = ("a", "b", "c")


class Latch(Node):
    """A general operator with own state: its goal holds once any child has held (a latch), a stateful OR."""

    kind = "Latch"

    def __init__(self, *children: Node, name: str) -> None:
        self.nodes, self.name, self.annotations = children, name, ()

    @property
    def children(self) -> tuple[Node, ...]:
        return self.nodes

    def child_weights(self) -> tuple[ChildWeights, ...]:
        return (ChildWeights(0.0, 1.0, 1.0),) * len(self.nodes)

    def state_slots(self) -> tuple[Slot, ...]:
        return (Slot("latched", 0.0, 1.0),)

    def initial_state(self, ctx: Context) -> tuple[float, ...]:
        return (1.0 if any(ctx.inside) else 0.0,)

    def next_state(self, before: Context, action: object, s2: object, inside2: tuple[bool, ...]) -> tuple[float, ...]:
        return (1.0 if before.q[0] or any(inside2) else 0.0,)

    def contains(self, ctx: Context) -> bool:
        return ctx.q[0] == 1.0

    def describe(self) -> str:
        return f"Latch {self.name!r}"


def _distance_of_b(s):  # type: ignore[no-untyped-def]
    return abs(s.b)


def _named_tree(root: str, p: str, q: str, d: str, c: str, latch: str) -> sg.Node:
    return sg.All(
        Latch(
            sg.Goal(p, a=(0, 1)).annotate(
                sg.Distance(_distance_of_b, scale=2.0, name=d), sg.Constraint(lambda s, a: s.c > 1, name=c)
            ),
            name=latch,
        ),
        sg.Goal(q, b=(None, 2.0)),
        name=root,
    )


class _BlankStrings(ast.NodeTransformer):
    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        return ast.copy_location(ast.Constant(""), node) if isinstance(node.value, str) else node


def _shape(source: str) -> str:
    """The AST of ``source`` with every string constant and comment gone."""
    return ast.dump(_BlankStrings().visit(ast.parse(source)))


_any_name = st.text(min_size=1).filter(lambda s: bool(s.strip()) and "/" not in s and ":" not in s)


@given(st.lists(_any_name, min_size=6, max_size=6, unique=True))
def test_arbitrary_names_reach_generated_code_only_as_text(names):
    # Newlines, quotes, backslashes, unicode: the code is the same as for plain names,
    # and the names come back unchanged as keys.
    tree = _named_tree(*names)
    compiled = compile_tree(tree, FEATURES)
    placeholder = compile_tree(_named_tree("n0", "n1", "n2", "n3", "n4", "n5"), FEATURES)
    assert _shape(compiled.source) == _shape(placeholder.source)
    flat, ref = compiled.evaluator(), ReferenceEvaluator(tree, FEATURES)
    assert flat.reset([0.5, 1.0, 2.0]) == ref.reset([0.5, 1.0, 2.0])
    step_flat, step_ref = flat.step(0, [0.5, 0.5, 0.0]), ref.step(0, [0.5, 0.5, 0.0])
    assert step_flat[1:3] == step_ref[1:3]
    assert step_flat[3] == pytest.approx(step_ref[3])
    root, p, q, d, c, latch = names
    leaf = f"{root}/{latch}/{p}"
    assert list(step_flat[3]) == [leaf, f"{leaf}:{d}", f"{leaf}:{c}", f"{root}/{latch}", f"{root}/{q}"]
    assert step_flat[3][leaf] == 0.0  # the latch pays for its goal itself: its child's core is weighted 0


def test_a_name_holding_code_is_never_run(capsys):
    tree = _named_tree('g\n    print("X")', "p'", 'q"""', "d\\", "c\n    raise SystemExit", "l\x00")
    ev = compile_tree(tree, FEATURES).evaluator()
    ev.reset([0.5, 1.0, 2.0])
    ev.step(0, [0.5, 0.5, 0.0])
    assert capsys.readouterr().out == ""


def test_general_nodes_are_called_and_fast_ones_inlined():
    source = compile_tree(_named_tree("r", "p", "q", "d", "c", "l"), FEATURES).source
    assert "_node1(" in source  # the latch, from its definition
    assert "0.0 <= f0 <= 1.0  # 'r/l/p'" in source  # its child, a box test
    assert "x2 = False or z[0] <= 0.0  # 'r/l/p'" in source  # the child's counter ends the child's subtree...
    assert "x1 = x2  # 'r/l'" in source  # ...and the latch's default termination, any(ended), is inlined


class EndingLatch(Latch):
    """A latch that also ends the episode once latched: its own termination is asked."""

    def terminates(self, ctx: Context, ended: tuple[bool, ...]) -> bool:
        return any(ended) or ctx.q[0] == 1.0


def test_an_own_termination_is_asked_given_the_childrens():
    tree = sg.All(EndingLatch(sg.Goal("p", a=(0, 1)), name="l"), sg.Goal("q", b=(None, 0)), name="r")
    assert "x1 = _end1((x2,))  # 'r/l'" in compile_tree(tree, FEATURES).source
    for ev in (compile_tree(tree, FEATURES).evaluator(), ReferenceEvaluator(tree, FEATURES)):
        ev.reset([5.0, 1.0, 0.0])
        assert ev.step(0, [5.0, 1.0, 0.0])[1] is False
        assert ev.step(0, [0.5, 1.0, 0.0])[1] is True  # latched: its own termination, though the root is not met


def test_a_latch_keeps_its_goal_after_leaving_the_child():
    tree = sg.All(Latch(sg.Goal("p", a=(0, 1)), name="l"), sg.Goal("q", b=(None, 0)), name="r")
    for ev in (compile_tree(tree, FEATURES).evaluator(), ReferenceEvaluator(tree, FEATURES)):
        assert ev.reset([5.0, 1.0, 0.0]) == (False, False, False, False)
        assert ev.step(0, [0.5, 1.0, 0.0])[2] == (False, True, True, False)
        _, ended, goals, _ = ev.step(0, [5.0, 0.0, 0.0])  # left p, latch holds; q reached: the root
        assert (ended, goals) == (True, (True, True, False, True))
        assert ev.own_state == [1.0]


@given(
    st.data(),
    sgst.trajectories(FEATURES, max_size=15),
)
def test_trees_mixing_fast_and_general_nodes_agree_with_the_reference(data, trajectory):
    tree = data.draw(sgst.trees(FEATURES, operators=(sg.All, Latch, EndingLatch)))
    actions = data.draw(st.lists(st.integers(0, 2), min_size=len(trajectory), max_size=len(trajectory)))
    flat, ref = compile_tree(tree, FEATURES).evaluator(), ReferenceEvaluator(tree, FEATURES)
    assert (flat.slots, flat.safety_keys) == (ref.slots, ref.safety_keys)
    assert flat.reset(trajectory[0]) == ref.reset(trajectory[0])
    for a, f in zip(actions, trajectory[1:]):
        r1, end1, goals1, terms1 = flat.step(a, f)
        r2, end2, goals2, terms2 = ref.step(a, f)
        assert r1 == pytest.approx(r2, rel=1e-9, abs=1e-12)
        assert (end1, goals1, list(terms1)) == (end2, goals2, list(terms2))
        assert (flat.own_state, flat.safe) == (ref.own_state, ref.safe)
        if end1:
            break
