"""``AnyOf``: the OR-operator, whose goal is the union of its children's goals.

Its semantics: docs/semantics.md, "Operators beyond the paper".

Example:
    >>> import specguard as sg
    >>> from specguard_plugins import AnyOf
    >>> def to_left(s):
    ...     return max(0.0, s.x + 2.0)
    >>> tree = AnyOf(
    ...     sg.Goal("left", x=(None, -2.0)).annotate(sg.Distance(to_left, scale=4.0)),
    ...     sg.Goal("right", x=(2.0, None)),
    ...     name="edge",
    ... )
    >>> print(tree)
    AnyOf 'edge'
    ├── Goal 'left': x <= -2
    │       + Distance(to_left, scale=4)
    └── Goal 'right': x >= 2
    >>> sg.formula(tree)
    'R = Any[edge] + 0.5*D[left]'
"""

from __future__ import annotations

import math
from collections import abc
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from specguard import Goal
from specguard.extend import MARGIN_FLOOR, Annotation, Box, ChildWeights, Context, Node, check_child_weights, set_fields
from specguard_plugins._checks import weights_text

if TYPE_CHECKING:
    from hypothesis.strategies import DrawFn, SearchStrategy

__all__ = ["AnyOf"]


@dataclass(frozen=True, init=False, repr=False)
class AnyOf(Node):
    """The OR-operator: the goal is the union of the children's goals.

    Semantics (docs/semantics.md, "Operators beyond the paper"):

    * goal: ``G = G_1 u ... u G_N``, so ``contains`` is ``any(ctx.inside)``;
    * core reward: the node's own membership difference ``1[s' in G] - 1[s in G]``
      (the default :meth:`~specguard.extend.Node.potential` and ``reward``), paid
      once for the union however many children contain the state, so re-entering
      is never paid twice;
    * children: their own core (goal) rewards are **not** added, every child is
      passed with ``ChildWeights(core=0, shaping=1, safety=1)``: their distances
      shape and their constraint penalties count exactly as they would alone;
      with ``weights=`` a child's distances and penalties are scaled by its
      weight instead (the core weight stays 0);
    * termination: the union of the children's; the node adds none of its own;
    * box: a union of boxes is not a box, so :meth:`box` is ``None`` (the flat
      evaluator evaluates the node from its definition), except with a single
      child, whose box it is.

    Refining a leaf into an ``AnyOf`` of boxes whose union is the leaf's box
    preserves the root goal exactly (:meth:`refinements` draws such refinements).

    Args:
        *children: the alternative goals, at least one, with distinct names.
        name: the node's name.
        weights: ``None`` (1 each), or one weight ``>= 0`` per child, at least
            one ``> 0``, scaling that child's distances and penalties.

    Raises:
        InvalidSpec: a bad name, no child, a child that is not a node, two
            children with one name, or weights that are not one finite
            number ``>= 0`` per child with one of them ``> 0``.

    Example:
        >>> import specguard as sg
        >>> from specguard.testing import ReplayEnv
        >>> wide = sg.Goal("wide", x=(1.0, 3.0))
        >>> narrow = sg.Goal("narrow", x=(2.0, 3.0))
        >>> tree = AnyOf(wide, narrow, name="reach", weights=(0.5, 1.0))
        >>> print(tree)
        AnyOf 'reach' weights=(0.5, 1)
        ├── Goal 'wide': 1 <= x <= 3
        └── Goal 'narrow': 2 <= x <= 3
        >>> sg.formula(tree)
        'R = Any[reach]'
        >>> env = sg.make_env(sg.InitialEnv(lambda: ReplayEnv([[0.0], [2.5]]), features=("x",)), tree)
        >>> _ = env.reset(seed=0)
        >>> obs, reward, terminated, truncated, info = env.step(0)
        >>> reward, terminated, info["reward_terms"]
        (1.0, True, {'reach/wide': 0.0, 'reach/narrow': 0.0, 'reach': 1.0})
    """

    kind: ClassVar[str] = "AnyOf"
    own_reward: ClassVar[bool] = True
    symbol: ClassVar[str] = "R"
    name: str
    nodes: tuple[Node, ...]
    weights: tuple[float, ...] | None
    annotations: tuple[Annotation, ...]

    def __init__(self, *children: Node, name: str, weights: abc.Sequence[float] | None = None) -> None:
        name, kids = self.init_node(name, children)
        parsed = check_child_weights(
            f"AnyOf {name!r}", kids, weights, scales="a child's distances and penalties", default="the default"
        )
        set_fields(self, weights=parsed)

    # -- the extension protocol ------------------------------------------------

    def child_weights(self) -> tuple[ChildWeights, ...]:
        """Per child ``(core=0, shaping=w_i, safety=w_i)``, ``w_i = 1`` unless ``weights`` are given."""
        weights = self.weights if self.weights is not None else (1.0,) * len(self.nodes)
        return tuple(ChildWeights(core=0.0, shaping=w, safety=w) for w in weights)

    def box(self, child_boxes: abc.Sequence[Box | None]) -> Box | None:
        """The single child's box; ``None`` with two or more children (a union is not a box)."""
        return child_boxes[0] if len(child_boxes) == 1 else None

    def contains(self, ctx: Context) -> bool:
        return any(ctx.inside)

    def margin(self, ctx: Context, margins: abc.Sequence[float]) -> float:
        """A union's robustness: its best child's margin (the deepest inside, or the nearest from outside).

        The default (the smallest distance, signed by membership) would score a
        state deep inside one child and far from the other as barely inside.
        """
        m = abs(max(margins, default=1.0))
        return m if self.contains(ctx) else -max(m, MARGIN_FLOOR)

    def until_end(self, children: tuple[bool, ...]) -> bool:
        # A union with a goal that must hold until the end is judged at the end too: were it a reach goal,
        # an episode starting in that child's goal would end at its first step (docs/semantics.md).
        return any(children)

    def describe(self) -> str:
        return f"AnyOf {self.name!r}{weights_text(self.weights)}"

    def formula_term(self, label: str) -> str:
        return f"Any[{label}]"

    def __repr__(self) -> str:
        kids = ", ".join(map(repr, self.nodes))
        weights = "" if self.weights is None else f", weights={self.weights!r}"
        annotated = f".annotate({', '.join(a.describe() for a in self.annotations)})" if self.annotations else ""
        return f"AnyOf({kids}, name={self.name!r}{weights}){annotated}"

    # -- Hypothesis ------------------------------------------------------------

    @classmethod
    def strategy(cls, children: abc.Sequence[Node], name: str) -> SearchStrategy[Node]:
        """``AnyOf(*children, name=name)`` with default or random weights."""
        from specguard.strategies import weights

        return weights(len(children)).map(lambda w: cls(*children, name=name, weights=w))

    @classmethod
    def refinements(cls, leaf: Node) -> SearchStrategy[Node] | None:
        """Nodes ``AnyOf(Goal, ...)`` whose boxes' union is exactly ``leaf``'s box, named like the leaf.

        The leaf's box is cut into 2 to 4 parts: a part is split on one of its
        features ``lo <= x <= hi`` at two drawn points ``c1 <= c2`` into
        ``[lo, c2]`` and ``[c1, hi]`` (boxes are inclusive, so the parts touch
        or overlap, and their union is the part). A box of exact values only
        is repeated. ``None`` for a node with children or own state, or whose
        goal is not a box.
        """
        if leaf.children or leaf.state_slots():
            return None
        box = leaf.box(())
        if box is None:
            return None
        return _union_of_parts(leaf.name, dict(box))


def _open(v: float) -> float | None:
    return None if math.isinf(v) else v


def _union_of_parts(name: str, box: dict[str, tuple[float, float]]) -> SearchStrategy[Node]:
    from hypothesis import strategies as st

    from specguard.strategies import weights

    def point(lo: float, hi: float) -> SearchStrategy[float]:
        inner = st.floats(_open(lo), _open(hi), allow_nan=False, allow_infinity=False)
        edges = [v for v in (lo, hi) if math.isfinite(v)]
        return st.sampled_from(edges) | inner if edges else inner

    @st.composite
    def draw_anyof(draw: DrawFn) -> Node:
        parts = [box]
        for _ in range(draw(st.integers(1, 3))):
            i = draw(st.integers(0, len(parts) - 1))
            part = parts[i]
            splittable = [f for f, (lo, hi) in part.items() if lo < hi]
            if not splittable:  # exact values only: a copy keeps the union
                parts.insert(i + 1, part)
                continue
            f = draw(st.sampled_from(splittable))
            lo, hi = part[f]
            c1, c2 = sorted((draw(point(lo, hi)), draw(point(lo, hi))))
            parts[i : i + 1] = [{**part, f: (lo, c2)}, {**part, f: (c1, hi)}]
        children: list[Node] = [
            Goal(f"part{k}", **{f: (_open(lo), _open(hi)) for f, (lo, hi) in p.items()}) for k, p in enumerate(parts)
        ]
        return AnyOf(*children, name=name, weights=draw(weights(len(children))))

    return draw_anyof()
