"""Hypothesis primitives the built-in nodes and annotations draw from (support of :mod:`specguard.strategies`).

The built-ins' ``strategy``/``refinements`` classmethods import this module when
called, and it imports none of them: each builder takes the class it builds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from hypothesis import strategies as st

from specguard.extend import Annotation, Node

__all__ = ["GRID", "LIMIT", "bounds", "constraints", "distances", "refinements", "values", "weights"]

# Goal bounds and state values share one small grid plus arbitrary floats in
# [-LIMIT, LIMIT]: the grid makes states land exactly on box edges often.
LIMIT = 4.0
GRID = (-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0)

values = st.one_of(
    st.sampled_from(GRID),
    st.floats(-LIMIT, LIMIT, allow_nan=False, allow_infinity=False),
)


@st.composite
def bounds(draw: st.DrawFn, values: st.SearchStrategy[float] = values) -> tuple[float | None, float | None]:
    """An inclusive interval ``(lo, hi)``, ``lo <= hi``, either side possibly open (``None``)."""
    a, b = sorted((draw(values), draw(values)))
    lo = None if draw(st.integers(0, 5)) == 0 else a
    hi = None if draw(st.integers(0, 5)) == 0 else b
    return lo, hi


def weights(n: int) -> st.SearchStrategy[list[float] | None]:
    """``None`` (the default ``1/N``) or ``n`` weights >= 0, at least one of them > 0."""
    return st.none() | st.lists(st.floats(0.0, 10.0), min_size=n, max_size=n).filter(lambda w: any(x > 0 for x in w))


def _distance_fn(feature: str, target: float) -> Any:
    def fn(s: Any) -> Any:
        return abs(getattr(s, feature) - target)

    fn.__qualname__ = f"|{feature} - {target:g}|"
    return fn


def _constraint_fn(feature: str, threshold: float) -> Any:
    def fn(s: Any, a: Any) -> Any:
        return getattr(s, feature) > threshold

    fn.__qualname__ = f"{feature} > {threshold:g}"
    return fn


@st.composite
def distances(draw: st.DrawFn, cls: type[Annotation], features: Sequence[str], name: str = "distance") -> Annotation:
    """A ``cls`` (``Distance``) ``|s.f - c|`` with a random scale and weight (works on scalars and column arrays)."""
    f = draw(st.sampled_from(list(features)))
    weight = draw(st.none() | st.floats(0.0, 10.0))
    return cls(_distance_fn(f, draw(values)), scale=draw(st.floats(0.1, 10.0)), weight=weight, name=name)  # type: ignore[call-arg]


@st.composite
def constraints(
    draw: st.DrawFn, cls: type[Annotation], features: Sequence[str], name: str = "constraint"
) -> Annotation:
    """A ``cls`` (``Constraint``) ``s.f > c`` with a small budget."""
    f = draw(st.sampled_from(list(features)))
    weight = draw(st.none() | st.floats(0.0, 10.0))
    return cls(_constraint_fn(f, draw(values)), budget=draw(st.integers(1, 4)), weight=weight, name=name)  # type: ignore[call-arg]


@st.composite
def refinements(draw: st.DrawFn, leaf: Node, operator: type[Node], max_children: int = 3, loosen: bool = True) -> Node:
    """An ``operator`` node (an AND, such as ``All``) whose children's boxes intersect to exactly ``leaf``'s box.

    The children are of ``leaf``'s class. Each of the leaf's bounds goes to at
    least one child. With ``loosen``, children may also carry looser bounds on
    features that another child bounds exactly, which leaves the intersection
    unchanged.
    """
    items = list(leaf.bounds)  # type: ignore[attr-defined]
    n = draw(st.integers(1, max_children))
    owner = [draw(st.integers(0, n - 1)) for _ in items]
    children = []
    for k in range(n):
        box: dict[str, tuple[float | None, float | None]] = {}
        for (f, lo, hi), o in zip(items, owner):
            if o == k:
                box[f] = (None if math.isinf(lo) else lo, None if math.isinf(hi) else hi)
            elif loosen and draw(st.booleans()):
                wider_lo = None if math.isinf(lo) or draw(st.booleans()) else lo - draw(st.floats(0.0, 1.0))
                wider_hi = None if math.isinf(hi) or draw(st.booleans()) else hi + draw(st.floats(0.0, 1.0))
                box[f] = (wider_lo, wider_hi)
        if all(lo is None and hi is None for lo, hi in box.values()):  # a child must bound something
            bounded = [(f, lo, hi) for f, lo, hi in items if not (math.isinf(lo) and math.isinf(hi))]
            f, lo, hi = bounded[k % len(bounded)]  # repeating one of the leaf's bounds leaves the intersection
            box[f] = (None if math.isinf(lo) else lo, None if math.isinf(hi) else hi)
        children.append(type(leaf)(f"part{k}", **box))  # type: ignore[call-arg]
    return operator(*children, name=leaf.name, weights=draw(weights(n)))  # type: ignore[call-arg]
