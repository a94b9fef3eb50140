"""Hypothesis strategies for goal trees, states and trajectories.

Public so that authors of custom operators and annotations can property-test
them the way specguard tests its own definitions (``tests/test_reference.py``).
Hypothesis is installed with specguard (the kit and these strategies are one of its uses).

Example:
    >>> from hypothesis import given
    >>> from specguard import strategies as sgst
    >>> @given(sgst.feature_names().flatmap(lambda fs: sgst.trees(fs)))
    ... def test_every_tree_has_a_root_path(tree):
    ...     assert next(tree.walk())[0] == tree.name
    >>> test_every_tree_has_a_root_path()
"""

from __future__ import annotations

import keyword
from collections.abc import Sequence

from hypothesis import strategies as st

from specguard.extend import Annotation, Node
from specguard.tree import _draw
from specguard.tree._draw import bounds, weights
from specguard.tree._draw import values as _values
from specguard.tree.builtin_annotations import Constraint, Distance
from specguard.tree.nodes import All, Goal

__all__ = [
    "bounds",
    "constraints",
    "distances",
    "feature_names",
    "goals",
    "node_names",
    "refinements",
    "states",
    "trajectories",
    "trees",
    "weights",
]


def feature_names(min_size: int = 1, max_size: int = 5) -> st.SearchStrategy[tuple[str, ...]]:
    """Tuples of distinct feature names usable as ``InitialEnv(features=...)``."""
    name = st.from_regex(r"[a-z][a-z0-9_]{0,6}", fullmatch=True).filter(lambda s: not keyword.iskeyword(s))
    return st.lists(name, min_size=min_size, max_size=max_size, unique=True).map(tuple)


def node_names() -> st.SearchStrategy[str]:
    """Valid node names (no ``/`` or ``:``)."""
    return st.from_regex(r"[A-Za-z][A-Za-z0-9_\-]{0,8}", fullmatch=True)


@st.composite
def goals(draw: st.DrawFn, features: Sequence[str], name: str | None = None) -> Goal:
    """A leaf with a box on a non-empty subset of ``features``."""
    chosen = draw(st.lists(st.sampled_from(list(features)), min_size=1, max_size=len(features), unique=True))
    box = {f: draw(bounds()) for f in chosen}
    if all(lo is None and hi is None for lo, hi in box.values()):  # a goal must bound something
        box[chosen[0]] = (draw(_values), None)
    return Goal(name or draw(node_names()), **box)


def distances(features: Sequence[str], name: str = "distance") -> st.SearchStrategy[Distance]:
    """A distance ``|s.f - c|`` with a random scale and weight (works on scalars and column arrays)."""
    return _draw.distances(Distance, features, name)  # type: ignore[return-value]


def constraints(features: Sequence[str], name: str = "constraint") -> st.SearchStrategy[Constraint]:
    """A constraint ``s.f > c`` with a small budget."""
    return _draw.constraints(Constraint, features, name)  # type: ignore[return-value]


def refinements(leaf: Goal, max_children: int = 3, loosen: bool = True) -> st.SearchStrategy[All]:
    """An ``All`` whose children's boxes intersect to exactly ``leaf``'s box.

    Each of the leaf's bounds goes to at least one child. With ``loosen``,
    children may also carry looser bounds on features that another child
    bounds exactly, which leaves the intersection unchanged.
    """
    return _draw.refinements(leaf, All, max_children, loosen)  # type: ignore[return-value]


def _annotated(node: Node, features: Sequence[str], kinds: Sequence[type[Annotation]]) -> st.SearchStrategy[Node]:
    """``node`` with 0-2 annotations drawn from ``kinds`` (each class's ``strategy``)."""
    if not kinds:
        return st.just(node)

    def one(i: int) -> st.SearchStrategy[Annotation]:
        return st.sampled_from(list(kinds)).flatmap(lambda k: k.strategy(features, f"{k.__name__.lower()}{i}"))

    extra = st.integers(0, 2).flatmap(lambda n: st.tuples(*(one(i) for i in range(n))))
    return extra.map(lambda anns: node.annotate(*anns) if anns else node)


def trees(
    features: Sequence[str],
    max_depth: int = 3,
    max_children: int = 3,
    annotations: bool | Sequence[type[Annotation]] = True,
    name: str | None = None,
    operators: Sequence[type[Node]] = (All,),
) -> st.SearchStrategy[Node]:
    """Random goal trees over ``features``: ``Goal`` leaves combined by ``operators``, optionally annotated.

    Built with ``st.recursive``, so counterexamples shrink towards small trees.

    Args:
        features: the feature names goals may bound.
        max_depth: the deepest a tree may be (1: a single leaf).
        max_children: the most children per operator.
        annotations: ``True`` for ``Distance`` and ``Constraint``, ``False`` for
            none, or the annotation classes to draw (each with a ``strategy``).
        name: the root's name (a leaf root when ``max_depth`` is 1); random if ``None``.
        operators: the operator classes to combine children with; each is drawn
            through its ``strategy(children, name)`` classmethod.
    """
    kinds: tuple[type[Annotation], ...] = (
        (Distance, Constraint) if annotations is True else () if annotations is False else tuple(annotations)
    )
    ops = tuple(operators)

    def leaf(leaf_name: str | None = None) -> st.SearchStrategy[Node]:
        return goals(features, name=leaf_name).flatmap(lambda g: _annotated(g, features, kinds))

    def combine(kids: st.SearchStrategy[Node], op_name: st.SearchStrategy[str]) -> st.SearchStrategy[Node]:
        children = st.lists(kids, min_size=1, max_size=max_children, unique_by=lambda n: n.name)
        drawn = st.tuples(st.sampled_from(ops), children, op_name)
        return drawn.flatmap(lambda t: t[0].strategy(t[1], t[2])).flatmap(lambda n: _annotated(n, features, kinds))

    if max_depth <= 1 or not ops:
        return leaf(name)
    inner = st.recursive(leaf(), lambda kids: combine(kids, node_names()), max_leaves=max_children ** (max_depth - 1))
    if name is None:
        return inner
    return st.one_of(leaf(name), combine(inner, st.just(name)))


def states(features: Sequence[str]) -> st.SearchStrategy[list[float]]:
    """Feature vectors (Python floats), often exactly on box edges."""
    return st.lists(_values, min_size=len(features), max_size=len(features))


def trajectories(
    features: Sequence[str], min_size: int = 2, max_size: int = 12
) -> st.SearchStrategy[list[list[float]]]:
    """Sequences of feature vectors ``s_0 .. s_T``."""
    return st.lists(states(features), min_size=min_size, max_size=max_size)
