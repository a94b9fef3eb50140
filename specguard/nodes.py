"""Goal-tree nodes and annotations (SPEC.md sections 1, 2 and 4).

Nodes are small immutable values: building a tree computes nothing, it only
records what the user stated. Checks that need nothing but the node itself
(``lo > hi``, weights, names) run at construction, so the mistake is reported
at the line that made it; checks that need the initial environment (feature
names) run when the tree is compiled by :func:`specguard.make_env`.

Example:
    >>> import specguard as sg
    >>> position = sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259))
    >>> stabilization = sg.Goal("stabilization", omega=(-0.25, 0.25))
    >>> tree = sg.All(position, stabilization, name="pendulum", weights=(0.8, 0.2))
    >>> print(tree)
    All 'pendulum' weights=(0.8, 0.2)
    ├── Goal 'position': 0.966 <= x <= 1, -0.259 <= y <= 0.259
    └── Goal 'stabilization': -0.25 <= omega <= 0.25
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any, ClassVar

from specguard.error import InvalidSpec

__all__ = ["All", "Annotation", "Constraint", "Distance", "Goal", "Node"]

PATH_SEPARATOR = "/"
ANNOTATION_SEPARATOR = ":"


def _check_name(kind: str, name: object) -> str:
    """The name as a plain ``str`` (a ``str`` subclass could override ``__repr__`` or ``__format__``)."""
    if not isinstance(name, str) or not name.strip():
        raise InvalidSpec(f"{kind} {name!r}", f"expected a non-empty string as name, got {name!r}")
    name = str.__str__(name)
    for sep in (PATH_SEPARATOR, ANNOTATION_SEPARATOR):
        if sep in name:
            raise InvalidSpec(
                f"{kind} {name!r}",
                f"a name may not contain {sep!r}, which separates node paths",
                hint="use '_' or '-' inside names",
            )
    return name


def _check_weight(where: str, weight: object) -> float | None:
    if weight is None:
        return None
    if isinstance(weight, bool) or not isinstance(weight, Real):
        raise InvalidSpec(where, f"expected weight to be a number, got {weight!r}")
    value = float(weight)
    if not math.isfinite(value) or value < 0:
        raise InvalidSpec(where, f"expected a finite weight >= 0, got {weight!r}")
    return value


def _fmt(x: float) -> str:
    return f"{x:g}"


def _fn_label(fn: Callable[..., Any]) -> str:
    name = getattr(fn, "__qualname__", None)
    return name.rsplit("<locals>.", 1)[-1] if isinstance(name, str) else repr(fn)


# ---------------------------------------------------------------------------
# Annotations
# ---------------------------------------------------------------------------


class Annotation:
    """Base of node annotations (SPEC.md section 2, step 2 of Algorithm 1).

    Attributes:
        normalised: whether the annotation's reward takes part in the default
            ``1/N`` weighting of its node's components (distances do, the
            constraint penalty does not).
        symbol: the letter the reward formula uses for the component.
    """

    normalised: ClassVar[bool] = True
    symbol: ClassVar[str] = "A"
    name: str | None
    weight: float | None


@dataclass(frozen=True)
class Distance(Annotation):
    """Potential-based distance shaping: ``R = (fn(s) - fn(s')) / scale``.

    Args:
        fn: the distance of a state to the goal, ``>= 0``. It receives the state
            with attribute access by feature name (``s.x``).
        scale: the specified maximum distance ``d`` (``> 0``).
        weight: the component's weight inside its node; ``None`` for the
            default ``1/N``.
        name: the component's name in ``info["reward_terms"]``.
    """

    normalised: ClassVar[bool] = True
    symbol: ClassVar[str] = "D"

    fn: Callable[[Any], float]
    scale: float
    weight: float | None = None
    name: str = "distance"

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", _check_name("Distance", self.name))
        where = f"Distance {self.name!r}"
        if not callable(self.fn):
            raise InvalidSpec(where, f"expected fn to be callable as fn(s), got {self.fn!r}")
        scale = self.scale
        if isinstance(scale, bool) or not isinstance(scale, Real):
            raise InvalidSpec(where, f"expected scale to be a number, got {scale!r}")
        if not math.isfinite(scale) or scale <= 0:
            raise InvalidSpec(
                where,
                f"expected scale > 0 (the maximum distance to the goal), got {scale!r}",
                hint="scale divides the shaping reward, so it must be a positive finite number",
            )
        object.__setattr__(self, "scale", float(scale))
        object.__setattr__(self, "weight", _check_weight(where, self.weight))

    def __repr__(self) -> str:
        weight = "" if self.weight is None else f", weight={_fmt(self.weight)}"
        name = "" if self.name == "distance" else f", name={self.name!r}"
        return f"Distance({_fn_label(self.fn)}, scale={_fmt(self.scale)}{weight}{name})"


@dataclass(frozen=True)
class Constraint(Annotation):
    """A safety constraint: a violation counter with a budget (SPEC.md section 2).

    Args:
        fn: ``fn(s, a) -> bool``, true for a violating state-action pair.
        budget: ``delta >= 1``, the violations allowed in an episode; the
            episode ends when the counter ``delta - violations`` reaches 0.
        weight: the penalty's weight; defaults to 1 and is not part of the
            ``1/N`` normalisation.
        name: the component's name; defaults to ``"constraint"``.
    """

    normalised: ClassVar[bool] = False
    symbol: ClassVar[str] = "P"

    fn: Callable[[Any, Any], bool]
    budget: int = 1
    weight: float | None = None
    name: str | None = None

    def __post_init__(self) -> None:
        if self.name is None:
            object.__setattr__(self, "name", "constraint")
        object.__setattr__(self, "name", _check_name("Constraint", self.name))
        where = f"Constraint {self.name!r}"
        if not callable(self.fn):
            raise InvalidSpec(where, f"expected fn to be callable as fn(s, a), got {self.fn!r}")
        budget = self.budget
        if isinstance(budget, bool) or not isinstance(budget, Integral) or budget < 1:
            raise InvalidSpec(
                where,
                f"expected budget to be an integer >= 1 (violations allowed per episode), got {budget!r}",
            )
        object.__setattr__(self, "budget", int(budget))
        object.__setattr__(self, "weight", _check_weight(where, self.weight))

    def __repr__(self) -> str:
        weight = "" if self.weight is None else f", weight={_fmt(self.weight)}"
        name = "" if self.name == "constraint" else f", name={self.name!r}"
        return f"Constraint({_fn_label(self.fn)}, budget={self.budget}{weight}{name})"


# ---------------------------------------------------------------------------
# Nodes
# ---------------------------------------------------------------------------


class Node:
    """Base of goal-tree nodes. Subclasses are frozen dataclasses."""

    kind: ClassVar[str] = "Node"
    name: str
    annotations: tuple[Annotation, ...]

    @property
    def children(self) -> tuple[Node, ...]:
        return ()

    def annotate(self, *annotations: Annotation) -> Node:
        """Return a copy of this node with ``annotations`` appended, applied in order.

        Raises:
            InvalidSpec: an argument is not an annotation, or two annotations
                of the node share a name.
        """
        for a in annotations:
            if not isinstance(a, Annotation):
                raise InvalidSpec(
                    f"{self.kind} {self.name!r}",
                    f"annotate() expects Distance or Constraint annotations, got {a!r}",
                )
        combined = self.annotations + tuple(annotations)
        names = [a.name for a in combined]
        for n in names:
            if names.count(n) > 1:
                raise InvalidSpec(
                    f"{self.kind} {self.name!r}",
                    f"two annotations are named {n!r}; names must be unique per node",
                    hint="pass name=... to one of them",
                )
        new = object.__new__(type(self))
        for field_name, value in vars(self).items():
            object.__setattr__(new, field_name, value)
        object.__setattr__(new, "annotations", combined)
        return new

    def walk(self, prefix: str = "") -> Iterator[tuple[str, Node]]:
        """Yield ``(path, node)`` for this node and its descendants, depth first, parents first."""
        path = f"{prefix}{PATH_SEPARATOR}{self.name}" if prefix else self.name
        yield path, self
        for child in self.children:
            yield from child.walk(path)

    def describe(self) -> str:
        """One line saying what the node is, without its children."""
        raise NotImplementedError

    def pretty(self) -> str:
        """The tree as indented text, one node per line, annotations below their node."""
        lines: list[str] = []
        self._pretty(lines, "", "")
        return "\n".join(lines)

    def _pretty(self, lines: list[str], first: str, rest: str) -> None:
        lines.append(first + self.describe())
        kids = self.children
        lead = rest + ("│   " if kids else "    ")
        for a in self.annotations:
            lines.append(f"{lead}+ {a!r}")
        for i, child in enumerate(kids):
            last = i == len(kids) - 1
            child._pretty(lines, rest + ("└── " if last else "├── "), rest + ("    " if last else "│   "))

    def __str__(self) -> str:
        return self.pretty()

    def _annotations_repr(self) -> str:
        return f".annotate({', '.join(map(repr, self.annotations))})" if self.annotations else ""


Bound = tuple[float, float]


def _parse_bound(goal: str, feature: str, value: object) -> Bound:
    where = f"Goal {goal!r}, feature {feature!r}"
    if isinstance(value, Real) and not isinstance(value, bool):
        if math.isinf(value):  # features are finite: no state has an infinite value
            raise InvalidSpec(
                where,
                f"expected a finite exact value, got {float(value):g}; "
                "features are finite, so the goal could never hold",
                hint=f"give a box (lo, hi) with None for an open side, e.g. {feature}=(0, None)",
            )
        lo = hi = value  # a scalar states an exact value, e.g. leg1=1
    elif isinstance(value, Sequence) and not isinstance(value, str) and len(value) == 2:
        lo, hi = value
    else:
        raise InvalidSpec(where, f"expected a pair (lo, hi) or a number, got {value!r}")
    out = []
    for side, v, open_value in (("lo", lo, -math.inf), ("hi", hi, math.inf)):
        if v is None:
            out.append(open_value)
            continue
        if isinstance(v, bool) or not isinstance(v, Real):
            raise InvalidSpec(where, f"expected {side} to be a number or None (open side), got {v!r}")
        f = float(v)
        if math.isnan(f):
            raise InvalidSpec(where, f"{side} is NaN; expected a number, or None for an open side")
        if math.isinf(f) and f != open_value:  # lo=+inf or hi=-inf: no finite feature value fits
            raise InvalidSpec(
                where,
                f"expected {side} to be finite (or {open_value:g} or None for an open side), "
                f"got {side}={f:g}; features are finite, so the goal could never hold",
                hint=f"use {side}=None for an open side",
            )
        out.append(f)
    if out[0] > out[1]:
        raise InvalidSpec(
            where,
            f"expected lo <= hi, got lo={out[0]:g} > hi={out[1]:g}",
            hint="the box is inclusive on both sides; swap the bounds",
        )
    return out[0], out[1]


@dataclass(frozen=True, init=False, repr=False)
class Goal(Node):
    """A leaf: a box goal on named features, inclusive on both sides.

    Args:
        name: the node's name, unique among its siblings.
        **bounds: ``feature=(lo, hi)`` with ``None`` for an open side, or
            ``feature=value`` for an exact value. Features not named are
            unconstrained.

    Example:
        >>> Goal("position", x=(0.966, 1.0), y=(-0.259, None))
        Goal('position', x=(0.966, 1), y=(-0.259, None))
    """

    kind: ClassVar[str] = "Goal"
    name: str
    bounds: tuple[tuple[str, float, float], ...]
    annotations: tuple[Annotation, ...]

    def __init__(self, name: str, /, **bounds: object) -> None:
        name = _check_name("Goal", name)
        if not bounds:
            raise InvalidSpec(
                f"Goal {name!r}",
                "expected at least one feature=(lo, hi); a goal on no feature holds in every state",
            )
        parsed = tuple((f, *_parse_bound(name, f, v)) for f, v in bounds.items())
        if all(math.isinf(lo) and math.isinf(hi) for _, lo, hi in parsed):
            given = ", ".join(f"{f}=(None, None)" for f, _, _ in parsed)
            raise InvalidSpec(
                f"Goal {name!r}",
                f"a goal must bound at least one side of one feature, got {given}; every state would satisfy it",
                hint=f"give lo or hi a number, e.g. {parsed[0][0]}=(0, None)",
            )
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "bounds", parsed)
        object.__setattr__(self, "annotations", ())

    def describe(self) -> str:
        parts = []
        for f, lo, hi in self.bounds:
            if lo == hi:
                parts.append(f"{f} == {_fmt(lo)}")
            elif math.isinf(lo):
                parts.append(f"{f} <= {_fmt(hi)}" if not math.isinf(hi) else f"{f} unconstrained")
            elif math.isinf(hi):
                parts.append(f"{f} >= {_fmt(lo)}")
            else:
                parts.append(f"{_fmt(lo)} <= {f} <= {_fmt(hi)}")
        return f"Goal {self.name!r}: {', '.join(parts)}"

    def __repr__(self) -> str:
        def side(v: float) -> str:
            return "None" if math.isinf(v) else _fmt(v)

        parts = [f"{f}=({side(lo)}, {side(hi)})" for f, lo, hi in self.bounds]
        return f"Goal({self.name!r}, {', '.join(parts)}){self._annotations_repr()}"


@dataclass(frozen=True, init=False, repr=False)
class All(Node):
    """The AND-operator: the goal is the intersection of the children's goals.

    Its core reward is ``sum_i w_i R_i`` with ``w_i = 1/N`` unless ``weights``
    are given (they need not sum to 1); its termination is the union of the
    children's (SPEC.md section 2).

    Args:
        *children: the subgoal nodes, at least one, with distinct names.
        name: the node's name.
        weights: one weight ``>= 0`` per child, or ``None`` for ``1/N``.
    """

    kind: ClassVar[str] = "All"
    name: str
    nodes: tuple[Node, ...]
    weights: tuple[float, ...] | None
    annotations: tuple[Annotation, ...]

    def __init__(self, *children: Node, name: str, weights: Sequence[float] | None = None) -> None:
        name = _check_name("All", name)
        where = f"All {name!r}"
        if not children:
            raise InvalidSpec(where, "expected at least one child node, got none")
        for c in children:
            if not isinstance(c, Node):
                raise InvalidSpec(where, f"expected children to be Goal or All nodes, got {c!r}")
        seen: set[str] = set()
        for c in children:
            if c.name in seen:
                raise InvalidSpec(
                    where,
                    f"two children are named {c.name!r}; sibling names must be unique "
                    "because node paths identify goals",
                )
            seen.add(c.name)
        parsed: tuple[float, ...] | None = None
        if weights is not None:
            if isinstance(weights, (str, bytes)) or not isinstance(weights, Sequence):
                raise InvalidSpec(where, f"expected weights to be a sequence of numbers, got {weights!r}")
            if len(weights) != len(children):
                raise InvalidSpec(
                    where,
                    f"expected {len(children)} weights (one per child), got {len(weights)}: {tuple(weights)!r}",
                )
            checked = [_check_weight(f"{where}, weight of {c.name!r}", w) for c, w in zip(children, weights)]
            parsed = tuple(w for w in checked if w is not None)
            if len(parsed) != len(children):
                raise InvalidSpec(where, f"expected a number for every weight, got {tuple(weights)!r}")
            if not any(w > 0 for w in parsed):
                raise InvalidSpec(
                    where,
                    f"expected at least one weight > 0, got weights=({', '.join(_fmt(w) for w in parsed)}); "
                    "all-zero weights make the node's reward identically 0",
                    hint="weights need not sum to 1; omit weights= for 1/N each",
                )
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "nodes", tuple(children))
        object.__setattr__(self, "weights", parsed)
        object.__setattr__(self, "annotations", ())

    @property
    def children(self) -> tuple[Node, ...]:
        return self.nodes

    def child_weights(self) -> tuple[float, ...]:
        """The weights in force: the user's, or ``1/N`` each."""
        n = len(self.nodes)
        return self.weights if self.weights is not None else (1.0 / n,) * n

    def describe(self) -> str:
        weights = "" if self.weights is None else f" weights=({', '.join(_fmt(w) for w in self.weights)})"
        return f"All {self.name!r}{weights}"

    def __repr__(self) -> str:
        kids = ", ".join(map(repr, self.nodes))
        weights = "" if self.weights is None else f", weights={self.weights!r}"
        return f"All({kids}, name={self.name!r}{weights}){self._annotations_repr()}"


def component_weights(node: Node) -> tuple[float, tuple[float, ...]]:
    """The weights of a node's reward components: its core and each annotation.

    SPEC.md section 2, "Reward components and weights": ``1/N`` over the core
    and the normalised annotations (distances); a constraint defaults to 1 and
    is outside the normalisation; a weight the user set replaces its default.
    The core's weight is always its default (the parent's weight scales it).
    """
    n = 1 + sum(1 for a in node.annotations if a.normalised)
    default = 1.0 / n
    ann = tuple(a.weight if a.weight is not None else (default if a.normalised else 1.0) for a in node.annotations)
    return default, ann
