"""Goal-tree nodes and annotations (docs/semantics.md, "Goals and goal spaces" and "Reward").

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
from collections.abc import Sequence
from dataclasses import dataclass
from numbers import Real
from typing import TYPE_CHECKING, ClassVar, Literal

from specguard.error import InvalidSpec
from specguard.extend import (
    Annotation,
    Box,
    ChildWeights,
    Context,
    Node,
    Slot,
    check_child_weights,
    component_weights,
    set_fields,
)
from specguard.tree.builtin_annotations import Constraint, Distance
from specguard.utils.node_paths import ANNOTATION_SEPARATOR, PATH_SEPARATOR
from specguard.utils.text import number_text
from specguard.validation import check_choice, check_name

if TYPE_CHECKING:
    from hypothesis.strategies import SearchStrategy

__all__ = [
    "All",
    "Always",
    "Annotation",
    "Constraint",
    "Distance",
    "Goal",
    "Node",
    "component_weights",
    "keeps_to_horizon",
]

# Re-exported: modules written before the extension API import these from here.
AUTO: Literal["auto"] = "auto"  # All(weights=AUTO): adapted during training (specguard.training.auto_weights)
UNTIL = ("horizon", "termination")  # Always(until=...): what ends an episode that keeps the goal

_REEXPORTED = (ANNOTATION_SEPARATOR, PATH_SEPARATOR, Annotation, Constraint, Distance, component_weights)


def _fmt(x: float) -> str:
    return number_text(x)


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
        name = check_name("Goal", name)
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
        self.init_node(name)
        set_fields(self, bounds=parsed)

    # -- the extension protocol: a box goal, membership reward (docs/semantics.md, "Leaf reward")

    def box(self, child_boxes: Sequence[Box | None]) -> Box:
        return {f: (lo, hi) for f, lo, hi in self.bounds}

    def contains(self, ctx: Context) -> bool:
        s = ctx.s
        return all(lo <= getattr(s, f) <= hi for f, lo, hi in self.bounds)

    @classmethod
    def refinements(cls, leaf: Node) -> SearchStrategy[Node] | None:
        return None  # a leaf refines nothing; operators refine leaves

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
    children's (docs/semantics.md, "The AND operator and its weights", "Termination").

    ``weights="auto"`` starts at ``1/N`` and lets training adapt the weights
    to the children's observed success (:mod:`specguard.training.auto_weights`): the
    env built from the tree alone, as evaluation uses it, keeps ``1/N``.

    Args:
        *children: the subgoal nodes, at least one, with distinct names.
        name: the node's name.
        weights: one weight ``>= 0`` per child, ``None`` for ``1/N``, or
            ``"auto"`` to adapt them during training.

    Example:
        >>> a, b = Goal("a", x=(0, 1)), Goal("b", y=(0, 1))
        >>> All(a, b, name="ab", weights="auto").weights_in_force()
        (0.5, 0.5)
    """

    kind: ClassVar[str] = "All"
    own_reward: ClassVar[bool] = False
    name: str
    nodes: tuple[Node, ...]
    weights: tuple[float, ...] | Literal["auto"] | None
    annotations: tuple[Annotation, ...]

    def __init__(self, *children: Node, name: str, weights: Sequence[float] | Literal["auto"] | None = None) -> None:
        name, kids = self.init_node(name, children)
        parsed: tuple[float, ...] | Literal["auto"] | None = AUTO
        if not (isinstance(weights, str) and weights == AUTO):
            parsed = check_child_weights(
                f"All {name!r}",
                kids,
                weights,
                scales="a child's rewards",
                default="1/N each",
                accepted="a sequence of numbers, None or 'auto'",
                hint="weights='auto' adapts them during training; omit weights= for 1/N each",
            )
        set_fields(self, weights=parsed)

    @property
    def adapts_weights(self) -> bool:
        return self.weights == AUTO

    def weights_in_force(self) -> tuple[float, ...]:
        """The weights in force: the user's, or ``1/N`` each (also where ``"auto"`` starts)."""
        n = len(self.nodes)
        return self.weights if isinstance(self.weights, tuple) else (1.0 / n,) * n

    # -- the extension protocol (docs/semantics.md, "The AND operator and its weights") --

    def child_weights(self) -> tuple[ChildWeights, ...]:
        return tuple(ChildWeights.same(w) for w in self.weights_in_force())  # R = sum_i w_i R_i

    def box(self, child_boxes: Sequence[Box | None]) -> Box | None:
        if any(b is None for b in child_boxes):
            return None
        out: dict[str, tuple[float, float]] = {}
        for b in child_boxes:  # G = intersection of G_i
            assert b is not None
            for f, (lo, hi) in b.items():
                old_lo, old_hi = out.get(f, (-math.inf, math.inf))
                out[f] = (max(old_lo, lo), min(old_hi, hi))
        return out

    def contains(self, ctx: Context) -> bool:
        return all(ctx.inside)

    def potential(self, ctx: Context) -> float:
        return 0.0  # no own term: the children's potentials, weighted, are the node's

    def reward(self, before: Context, action: object, after: Context) -> float:
        return 0.0

    @classmethod
    def strategy(cls, children: Sequence[Node], name: str) -> SearchStrategy[Node]:
        from specguard.tree._draw import weights

        return weights(len(children)).map(lambda w: cls(*children, name=name, weights=w))

    @classmethod
    def refinements(cls, leaf: Node) -> SearchStrategy[Node] | None:
        from specguard.tree._draw import refinements

        return refinements(leaf, cls) if isinstance(leaf, Goal) else None

    def describe(self) -> str:
        if isinstance(self.weights, tuple):
            return f"All {self.name!r} weights=({', '.join(_fmt(w) for w in self.weights)})"
        return f"All {self.name!r}" + (" weights=auto" if self.adapts_weights else "")

    def __repr__(self) -> str:
        kids = ", ".join(map(repr, self.nodes))
        weights = "" if self.weights is None else f", weights={self.weights!r}"
        return f"All({kids}, name={self.name!r}{weights}){self._annotations_repr()}"


@dataclass(frozen=True, init=False, repr=False)
class Always(Node):
    """A goal that must hold until the episode's horizon: every child's goal, at every state of the episode.

    Its own state ``held`` (0 or 1, in the observation) is whether every child's
    goal has held at every state so far; the goal is ``held`` and every child's
    goal now. Entering it ends nothing: at the root, the episode runs to the
    initial env's own end and is judged at its last state. Its core reward is its
    membership difference, so leaving pays ``-1`` once and nothing is ever paid
    back; the children's goal rewards are not added (its own replaces them), their
    distances and penalties count as they would alone (docs/semantics.md, "Goals
    that hold until the end").

    **The end is the horizon.** An episode that the initial env *terminates* (a
    Hopper's fall, a car's crash) did not run to its end, so by default the goal is
    not held at that last state, whatever its children say there: ``held`` becomes
    0, the step pays ``-1`` and ``info["goals"]`` reports it. Only an episode the
    env truncates (its ``TimeLimit``) or that ends in a state that a reach goal
    beside it reaches keeps it. ``until="termination"`` takes the env's termination
    as a good end instead (an env whose episodes end by success), as a truncation.

    Under ``All``, beside a reach goal, it reads "until": ``All(Always(A), B)``
    is reached when ``B`` is, with ``A`` held at every state before.

    Args:
        *children: the goals that must hold, at least one, with distinct names.
        name: the node's name.
        until: ``"horizon"`` (default): an episode the initial env terminates has
            not kept the goal; ``"termination"``: the env's termination is an end
            like its truncation (the goal is judged on the last state alone).

    Example:
        >>> balance = Always(Goal("upright", theta=(-0.2, 0.2)), name="balance")
        >>> print(balance)
        Always 'balance'
        └── Goal 'upright': -0.2 <= theta <= 0.2
        >>> Always(Goal("upright", theta=(-0.2, 0.2)), name="balance", until="termination").describe()
        "Always 'balance' until=termination"
    """

    kind: ClassVar[str] = "Always"
    name: str
    nodes: tuple[Node, ...]
    until: Literal["horizon", "termination"]
    annotations: tuple[Annotation, ...]

    def __init__(self, *children: Node, name: str, until: Literal["horizon", "termination"] = "horizon") -> None:
        name, _ = self.init_node(name, children)
        set_fields(self, until=check_choice(f"Always {name!r}", "until", until, UNTIL))

    # -- the extension protocol (docs/semantics.md, "Goals that hold until the end") --

    def child_weights(self) -> tuple[ChildWeights, ...]:
        return (ChildWeights(core=0.0, shaping=1.0, safety=1.0),) * len(self.nodes)  # it pays for its goal itself

    def state_slots(self) -> tuple[Slot, ...]:
        return (Slot("held", 0.0, 1.0),)

    def initial_state(self, ctx: Context) -> tuple[float, ...]:
        return (1.0 if all(ctx.inside) else 0.0,)

    def next_state(self, before: Context, action: object, s2: object, inside2: tuple[bool, ...]) -> tuple[float, ...]:
        return (1.0 if before.q[0] >= 1.0 and all(inside2) else 0.0,)

    def terminated_state(self, after: Context) -> tuple[float, ...]:
        return after.q if self.until == "termination" else (0.0,)  # a fall before the horizon is not kept

    def contains(self, ctx: Context) -> bool:
        return ctx.q[0] >= 1.0 and all(ctx.inside)

    def until_end(self, children: tuple[bool, ...]) -> bool:
        return True  # judged at the last state, whatever its children are

    @classmethod
    def strategy(cls, children: Sequence[Node], name: str) -> SearchStrategy[Node]:
        from hypothesis import strategies as st

        return st.sampled_from(UNTIL).map(lambda until: cls(*children, name=name, until=until))  # type: ignore[arg-type]

    def describe(self) -> str:
        return f"Always {self.name!r}" + ("" if self.until == "horizon" else f" until={self.until}")

    def __repr__(self) -> str:
        kids = ", ".join(map(repr, self.nodes))
        until = "" if self.until == "horizon" else f", until={self.until!r}"
        return f"Always({kids}, name={self.name!r}{until}){self._annotations_repr()}"


def keeps_to_horizon(tree: Node) -> bool:
    """Whether ``tree`` has an ``Always`` that an episode the env terminates does not keep (``until="horizon"``).

    Example:
        >>> up = Goal("up", x=(0, 1))
        >>> keeps_to_horizon(Always(up, name="a")), keeps_to_horizon(Always(up, name="a", until="termination"))
        (True, False)
    """
    return any(isinstance(n, Always) and n.until == "horizon" for _, n in tree.walk())
