"""The operator extension API (docs/semantics.md, "The operator contract"): what every node and annotation states.

Every operator, built-in or not, is a :class:`Node` subclass and every
annotation an :class:`Annotation` subclass. The constructed env, both
evaluators, the formula printer, the fingerprint and the Hypothesis
strategies read nodes only through the methods below, so a new operator needs
nothing but a subclass (and, to be found by name, an entry point; see
:mod:`specguard.registry`).

What a node states (all methods are pure functions of their arguments; a
node keeps no episode state of its own, the evaluators hold it):

* **own state** ``q``: :meth:`Node.state_slots` (bounded numbers appended to
  the observation), :meth:`Node.initial_state`, :meth:`Node.next_state`;
* **goal**: :meth:`Node.contains` of ``(s, q)`` given the children's
  memberships; a goal that is a box also says so in :meth:`Node.box`, and the
  flat evaluator then tests the box directly;
* **core reward**: :meth:`Node.reward`, telescoping to :meth:`Node.potential`;
  how the children's rewards enter the node's (:meth:`Node.child_weights`);
* **termination**: :meth:`Node.terminates`, given the children's (it must include them);
  whether the goal, at the root, ends the episode when reached (a *reach* goal, the
  paper's) or is judged when the episode ends (:meth:`Node.until_end`, ``Always``);
  the own state when the initial env terminates an episode before its horizon
  (:meth:`Node.terminated_state`);
* **description**: :meth:`Node.describe`, exact and deterministic.

Example: an "at least k of the children" operator.

    >>> import specguard as sg
    >>> from specguard.extend import ChildWeights, Context, Node
    >>> from specguard.testing import ReplayEnv
    >>> class AtLeast(Node):
    ...     kind = "AtLeast"
    ...     def __init__(self, k, *children, name):
    ...         self.init_node(name, children)  # checked; children() returns them
    ...         self.k = k
    ...     def child_weights(self):  # pay once for the goal (own term), pass only the children's annotations
    ...         return (ChildWeights(core=0.0, shaping=1.0, safety=1.0),) * len(self.nodes)
    ...     def contains(self, ctx: Context) -> bool:
    ...         return sum(ctx.inside) >= self.k
    ...     def describe(self) -> str:
    ...         return f"AtLeast {self.name!r} k={self.k}"
    >>> tree = AtLeast(1, sg.Goal("left", x=(None, -1)), sg.Goal("right", x=(1, None)), name="edge")
    >>> env = sg.make_env(sg.InitialEnv(lambda: ReplayEnv([[0.0], [2.0]]), features=("x",)), tree)
    >>> _ = env.reset(seed=0)
    >>> env.step(0)[1:3]
    (1.0, True)

The kit
:func:`specguard.testing.parametrize_with_checks` checks a new operator
against every invariant above.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

from specguard.error import InvalidSpec
from specguard.utils.node_paths import ANNOTATION_SEPARATOR, child_path
from specguard.utils.text import number_text
from specguard.validation import check_name, check_weight

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator

    from hypothesis.strategies import SearchStrategy

__all__ = [
    "MARGIN_FLOOR",
    "SAFETY",
    "SHAPING",
    "Annotation",
    "Box",
    "ChildWeights",
    "Context",
    "CounterForm",
    "Node",
    "ShapingForm",
    "Slot",
    "StagesForm",
    "adapted_annotations",
    "annotation_key",
    "check_child_weights",
    "check_children",
    "component_weights",
    "goal_test",
    "set_fields",
    "until_end",
]

Box = Mapping[str, tuple[float, float]]
"""A box goal: per named feature an inclusive ``(lo, hi)``, ``+-inf`` for an open side."""

MARGIN_FLOOR = 1e-9
"""The smallest size of a margin outside a goal (so that its sign says it is outside)."""

SHAPING = "shaping"
"""Role of an annotation that shapes towards a goal (``Distance``): part of the ``1/N`` weighting."""
SAFETY = "safety"
"""Role of a constraint-like annotation (``Constraint``, ``Avoid``): a counter, a penalty, a safety rate."""


class Context(NamedTuple):
    """What a node sees of one state.

    Attributes:
        s: the features, with attribute access by name (``s.x``).
        q: the node's own state (``()`` for a node without one).
        inside: each child's membership of its goal in this state, in child order.
    """

    s: Any
    q: tuple[float, ...]
    inside: tuple[bool, ...]


class Slot(NamedTuple):
    """One number of own state, appended to the observation: its name and bounds."""

    name: str
    low: float
    high: float


class ChildWeights(NamedTuple):
    """How one child's reward components enter its parent's reward, by role.

    Attributes:
        core: weight of the child's goal rewards (its core and its subtree's cores).
        shaping: weight of the distances on the child and in its subtree.
        safety: weight of the constraint penalties on the child and in its subtree.
    """

    core: float
    shaping: float
    safety: float

    @classmethod
    def same(cls, weight: float) -> ChildWeights:
        """Every component of the child with one weight, as ``All`` passes them."""
        return cls(weight, weight, weight)

    def of(self, role: str) -> float:
        """The weight of a component of ``role`` (``"core"``, :data:`SHAPING` or :data:`SAFETY`)."""
        return {"core": self.core, SHAPING: self.shaping, SAFETY: self.safety}[role]


class ShapingForm(NamedTuple):
    """Declares an annotation's reward is ``(fn(s) - fn(s')) / scale`` (potential ``-fn(s) / scale``)."""

    fn: Callable[[Any], float]
    scale: float


class CounterForm(NamedTuple):
    """Declares a violation counter: one slot from ``budget`` down, ``-1`` per violation, ending at 0.

    Attributes:
        fn: the violation test, ``fn(s, a)`` or, with ``on_next_state``, ``fn(s')``.
        budget: the counter's start.
        on_next_state: whether a step violates by its next state ``s'`` (``Avoid``)
            rather than by its state-action pair ``(s, a)`` (``Constraint``).
    """

    fn: Callable[..., Any]
    budget: int
    on_next_state: bool = False


# ---------------------------------------------------------------------------
# Annotations
# ---------------------------------------------------------------------------


class Annotation:
    """Base of annotations: a reward component (and maybe own state) added to one node.

    Class attributes:
        role: :data:`SHAPING` or :data:`SAFETY` (safety annotations get a safety rate).
        normalised: whether the component takes part in the default ``1/N``
            weighting of its node (distances do, penalties do not: their weight defaults to 1).
        symbol: the letter the reward formula uses (``D[position]``).
    """

    role: ClassVar[str] = SHAPING
    normalised: ClassVar[bool] = True
    symbol: ClassVar[str] = "A"
    name: str
    weight: float | None

    def state_slots(self) -> tuple[Slot, ...]:
        """The annotation's own state (a counter is one slot ``[0, budget]``)."""
        return ()

    def initial_state(self, s: Any) -> tuple[float, ...]:
        """Its state at the start of an episode in state ``s``."""
        return ()

    def next_state(self, s: Any, q: tuple[float, ...], action: Any, s2: Any) -> tuple[float, ...]:
        """Its state after the step ``(s, a, s')``."""
        return q

    def last_state(self, s: Any, q: tuple[float, ...], action: Any) -> tuple[float, ...]:
        """Its state once the episode has ended in ``s``, reached by ``action`` (docs/semantics.md, "The last state").

        The last state has no action of its own: an annotation judged on ``(s, a)`` judges it here, with the
        action that led to it; the change is paid as ``reward(s, q, action, s, q')``. Default: ``q``, nothing
        judged (right for an annotation judged on ``s'``, which judged the last state on the step into it).
        """
        return q

    def potential(self, s: Any, q: tuple[float, ...]) -> float:
        """``Phi``: the reward of a trajectory sums to ``Phi(last) - Phi(first)``."""
        return 0.0

    def reward(self, s: Any, q: tuple[float, ...], action: Any, s2: Any, q2: tuple[float, ...]) -> float:
        """The unweighted component of the step; by default the potential difference."""
        return self.potential(s2, q2) - self.potential(s, q)

    def terminates(self, q: tuple[float, ...]) -> bool:
        """Whether its state ends the episode (a counter at 0)."""
        return False

    def violations(self, q: tuple[float, ...]) -> int:
        """Safety annotations: violations so far this episode (its safety rate counts episodes with none)."""
        return 0

    def margin(self, s: Any, q: tuple[float, ...]) -> float:
        """Safety annotations: how robustly the episode that ended in ``(s, q)`` kept it, ``< 0`` when it did not.

        The falsifier (:mod:`specguard.falsify.robustness`) steers its search
        by it. Default: ``1`` without a violation, else minus the violations.
        """
        n = self.violations(q)
        return 1.0 if n == 0 else -float(n)

    def avoids(self) -> Node | None:
        """Safety annotations: the region of states whose entering is a violation, where there is one (``None``).

        The falsifier grades an episode without a violation by its closest approach to that region over the
        episode (:mod:`specguard.falsify.robustness`), instead of :meth:`margin`'s flat ``1``. Default: ``None``.
        """
        return None

    def fast_form(self) -> ShapingForm | CounterForm | None:
        """A declared closed form the flat evaluator compiles to straight-line code, or ``None``.

        It must agree with the methods above; ``specguard.testing`` checks that it does.
        """
        return None

    def describe(self) -> str:
        """Exact text of the annotation (its ``repr``)."""
        return repr(self)

    @classmethod
    def strategy(cls, features: Sequence[str], name: str) -> SearchStrategy[Annotation]:
        """Hypothesis strategy of annotations of this class over ``features`` (for the kit)."""
        raise NotImplementedError(f"{cls.__qualname__} defines no strategy(features, name) for random trees")


# ---------------------------------------------------------------------------
# Nodes
# ---------------------------------------------------------------------------


class StagesForm(NamedTuple):
    """Declares a node a stage counter over its children (``Sequence``), which the flat evaluator compiles to
    straight-line code.

    The node has one own-state slot ``q``, a whole number in ``[0, N]`` for ``N`` children: ``q_0`` counts
    the leading children whose goals hold in the first state, in order, and a step advances ``q`` while
    ``q < N`` and the goal of child ``q`` (counted from 0) holds in the next state. The node's goal is
    ``q = N``; its core reward is the default potential difference, with
    ``Phi(s, q) = stage[q] + (0.0 + w * -(fn(s) / scale) + ...)`` summed in order over ``shapers[q]``
    (nothing for ``q = N``), each ``fn(s)`` a finite distance ``>= 0``; its termination and
    :meth:`Node.terminated_state` are the defaults.

    Attributes:
        stage: ``stage[q]`` for ``q = 0 .. N``.
        shapers: per child, its ``(fn, scale, w)`` triples.
    """

    stage: tuple[float, ...]
    shapers: tuple[tuple[tuple[Callable[[Any], float], float, float], ...], ...]


class Node:
    """Base of goal-tree nodes: leaves and operators.

    Class attributes:
        kind: the word :meth:`describe` and errors use (``"Goal"``, ``"All"``).
        own_reward: whether the node pays a core term of its own, reported as
            ``info["reward_terms"][path]`` (a leaf, ``AnyOf``), or only passes
            on its children's (``All``).
        symbol: the letter of its own term in the reward formula (``R[position]``).
    """

    kind: ClassVar[str] = "Node"
    own_reward: ClassVar[bool] = True
    symbol: ClassVar[str] = "R"
    name: str
    annotations: tuple[Annotation, ...]

    # -- structure -----------------------------------------------------------

    def init_node(self, name: object, children: Sequence[object] | None = None) -> tuple[str, tuple[Node, ...]]:
        """A constructor's first step: check and set the node's name and children, with no annotations.

        The name is checked as ``check_name(self.kind, name)``; the children, if
        given (a leaf gives none), by :func:`check_children` and kept as ``nodes``,
        which :attr:`children` returns. Works on frozen dataclasses; set the other
        fields with :func:`set_fields`.

        Returns:
            The checked name and children, for the constructor's further checks.

        Raises:
            InvalidSpec: a bad name or children, naming the node.
        """
        name = check_name(self.kind, name)
        kids = () if children is None else check_children(self.kind, name, children)
        set_fields(self, name=name, **({} if children is None else {"nodes": kids}), annotations=())
        return name, kids

    @property
    def children(self) -> tuple[Node, ...]:
        """The child nodes, in order: the ``nodes`` that :meth:`init_node` keeps (``()`` for a leaf)."""
        nodes: tuple[Node, ...] = getattr(self, "nodes", ())
        return nodes

    def child_weights(self) -> tuple[ChildWeights, ...]:
        """How each child's components enter this node's reward: ``1/N`` each by default."""
        n = len(self.children)
        return (ChildWeights.same(1.0 / n),) * n if n else ()

    @property
    def adapts_weights(self) -> bool:
        """Whether training may replace :meth:`child_weights` by one adapted weight per child.

        The weights of the node's own safety annotations left at their default
        weight adapt with them (:func:`adapted_annotations`).
        ``All(weights="auto")`` does (:mod:`specguard.training.auto_weights`); the tree
        as declared keeps its own weights, so an env built from it alone is
        unchanged.
        """
        return False

    # -- goal ----------------------------------------------------------------

    def box(self, child_boxes: Sequence[Box | None]) -> Box | None:
        """The goal as a box when it is one (given the children's boxes), else ``None``."""
        return None

    def contains(self, ctx: Context) -> bool:
        """Whether ``(s, q)`` lies in the node's goal, given the children's memberships."""
        raise NotImplementedError(f"{type(self).__qualname__} must define contains(ctx)")

    def margin(self, ctx: Context, margins: tuple[float, ...]) -> float:
        """Robustness of ``(s, q)`` for the node's goal: ``>= 0`` inside, ``< 0`` outside, its size how far.

        ``margins`` are the children's, in child order; a box goal's margin is
        its box's, computed by the falsifier and never asked here
        (:mod:`specguard.falsify.robustness`). Default: the smallest of the
        children's distances to their boundaries (``1`` for a leaf), signed
        by :meth:`contains`. An operator that knows better (a union: the
        largest child margin) overrides it.
        """
        m = min((abs(x) for x in margins), default=1.0)
        return m if self.contains(ctx) else -max(m, MARGIN_FLOOR)

    # -- own state -----------------------------------------------------------

    def state_slots(self) -> tuple[Slot, ...]:
        """The node's own state, a few bounded numbers (``()``: none)."""
        return ()

    def initial_state(self, ctx: Context) -> tuple[float, ...]:
        """``q_0``, from the first state (``ctx.q`` is ``()``)."""
        return ()

    def next_state(self, before: Context, action: Any, s2: Any, inside2: tuple[bool, ...]) -> tuple[float, ...]:
        """``q'`` after the step from ``before`` to ``s2``, whose children's memberships are ``inside2``."""
        return before.q

    def terminated_state(self, after: Context) -> tuple[float, ...]:
        """``q'`` when the initial env *terminated* the episode in ``after`` before its horizon.

        docs/semantics.md, "Goals that hold until the end": asked only where the root goal holds until the
        end (:func:`until_end`), at the step whose base env reported ``terminated`` (whatever ``truncated``
        says), right after :meth:`next_state`, children first, so a parent sees its children's answer.
        ``after.q`` is the state :meth:`next_state` gave. Default: ``after.q``, a termination changes
        nothing; ``Always`` (``until="horizon"``) answers not held, since the episode did not reach its end.
        """
        return after.q

    def fast_form(self) -> StagesForm | None:
        """A declared closed form the flat evaluator compiles to straight-line code, or ``None``.

        It must agree with the methods above; ``specguard.testing`` checks that it does
        (``check_flat_matches_reference``).
        """
        return None

    # -- core reward and termination ----------------------------------------

    def potential(self, ctx: Context) -> float:
        """``Phi`` of the node's own core term; by default membership of its goal."""
        return 1.0 if self.contains(ctx) else 0.0

    def reward(self, before: Context, action: Any, after: Context) -> float:
        """The node's own core term of a step; it must telescope to :meth:`potential`."""
        return self.potential(after) - self.potential(before)

    def terminates(self, ctx: Context, ended: tuple[bool, ...]) -> bool:
        """Whether the node ends the episode in ``ctx``, given whether each child's subtree does (``ended``).

        docs/semantics.md, "Termination": the union of the children's terminations, plus the
        operator's own; so an override must return ``True`` whenever
        ``any(ended)`` (the kit checks it).
        """
        return any(ended)

    def until_end(self, children: tuple[bool, ...]) -> bool:
        """Whether the goal must hold until the episode ends, given whether each child's must (``children``).

        docs/semantics.md, "Goals that hold until the end": a *reach* goal (``False``, the paper's) ends
        the episode when the root's is reached; a goal that holds until the end (``True``, ``Always``) ends
        nothing and is judged at the episode's last state. Default: a leaf is a reach goal, and an operator
        holds until the end when every child does, so an ``All`` with a reach child is reached (``A`` until
        ``B``). A union (``AnyOf``) holds until the end when any child does.
        """
        return bool(children) and all(children)

    # -- description ---------------------------------------------------------

    def describe(self) -> str:
        """One exact line saying what the node is, without its children."""
        raise NotImplementedError(f"{type(self).__qualname__} must define describe()")

    def formula_term(self, label: str) -> str:
        """How the reward formula writes the node's own term."""
        return f"{self.symbol}[{label}]"

    # -- Hypothesis ------------------------------------------------------------

    @classmethod
    def strategy(cls, children: Sequence[Node], name: str) -> SearchStrategy[Node]:
        """Nodes of this class over ``children`` (for random trees); by default ``cls(*children, name=name)``."""
        from hypothesis import strategies as st

        return st.just(cls(*children, name=name))  # type: ignore[call-arg]

    @classmethod
    def refinements(cls, leaf: Node) -> SearchStrategy[Node] | None:
        """Nodes of this class whose goal equals ``leaf``'s box goal, or ``None`` if it does not refine."""
        return None

    # -- tree helpers (not part of the protocol) -------------------------------

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
                    f"annotate() expects annotations (Distance, Constraint, ...), got {a!r}",
                )
        combined = tuple(getattr(self, "annotations", ())) + tuple(annotations)
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
        path = child_path(prefix, self.name)
        yield path, self
        for child in self.children:
            yield from child.walk(path)

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
            lines.append(f"{lead}+ {a.describe()}")
        for i, child in enumerate(kids):
            last = i == len(kids) - 1
            child._pretty(lines, rest + ("└── " if last else "├── "), rest + ("    " if last else "│   "))

    def __str__(self) -> str:
        return self.pretty()

    def _annotations_repr(self) -> str:
        return f".annotate({', '.join(a.describe() for a in self.annotations)})" if self.annotations else ""


def check_children(kind: str, name: str, children: Sequence[object]) -> tuple[Node, ...]:
    """The children of an operator, checked: at least one, every one a node, names unique among siblings."""
    where = f"{kind} {name!r}"
    if not children:
        raise InvalidSpec(where, "expected at least one child node, got none")
    seen: set[str] = set()
    for c in children:
        if not isinstance(c, Node):
            raise InvalidSpec(where, f"expected children to be nodes (Goal, All, ...), got {c!r}")
        if c.name in seen:
            raise InvalidSpec(
                where,
                f"two children are named {c.name!r}; sibling names must be unique because node paths identify goals",
            )
        seen.add(c.name)
    return tuple(children)  # type: ignore[arg-type]


def set_fields(obj: object, **fields: object) -> None:
    """Set ``obj``'s attributes from a constructor, also on a frozen dataclass (as ``object.__setattr__``)."""
    for field, value in fields.items():
        object.__setattr__(obj, field, value)


def check_child_weights(
    where: str,
    children: Sequence[Node],
    weights: object,
    *,
    scales: str,
    default: str,
    accepted: str = "a sequence of numbers (one per child)",
    hint: str | None = None,
) -> tuple[float, ...] | None:
    """An operator's per-child weights: ``None``, or one finite weight ``>= 0`` per child, at least one ``> 0``.

    Args:
        where: the node at fault, as errors name it (``"AnyOf 'reach'"``).
        children: the node's checked children.
        weights: what the user passed.
        scales: what a weight scales, for the message (``"a child's distances and penalties"``).
        default: what omitting ``weights=`` gives (``"1/N each"``).
        accepted: what ``weights`` may be, for the message when it is not a sequence.
        hint: the hint when it is not a sequence.

    Raises:
        InvalidSpec: ``weights`` is not a sequence, has the wrong length, holds
            something other than a finite number ``>= 0``, or is all zeros.

    Example:
        >>> import specguard as sg
        >>> kids = (sg.Goal("a", x=1), sg.Goal("b", x=2))
        >>> check_child_weights("AnyOf 'r'", kids, (0.5, 1), scales="a child's distances", default="1 each")
        (0.5, 1.0)
    """
    if weights is None:
        return None
    if isinstance(weights, (str, bytes)) or not isinstance(weights, Sequence):
        raise InvalidSpec(where, f"expected weights to be {accepted}, got {weights!r}", hint=hint)
    if len(weights) != len(children):
        raise InvalidSpec(
            where, f"expected {len(children)} weights (one per child), got {len(weights)}: {tuple(weights)!r}"
        )
    parsed = []
    for child, w in zip(children, weights):
        checked = check_weight(f"{where}, weight of {child.name!r}", w)
        if checked is None:
            raise InvalidSpec(where, f"expected a number for every weight, got {tuple(weights)!r}")
        parsed.append(checked)
    if not any(w > 0 for w in parsed):
        raise InvalidSpec(
            where,
            f"expected at least one weight > 0, got weights=({', '.join(number_text(w) for w in parsed)}); "
            f"a weight scales {scales}, and all-zero weights make them identically 0",
            hint=f"weights need not sum to 1; omit weights= for {default}",
        )
    return tuple(parsed)


def component_weights(node: Node) -> tuple[float, tuple[float, ...]]:
    """The weights of a node's reward components: its core and each annotation.

    docs/semantics.md, "Weights inside a node": ``1/N`` over the core
    and the normalised annotations (distances); a constraint defaults to 1 and
    is outside the normalisation; a weight the user set replaces its default.
    The core's weight is always its default (the parent's weight scales it).
    """
    n = 1 + sum(1 for a in node.annotations if a.normalised)
    default = 1.0 / n
    ann = tuple(a.weight if a.weight is not None else (default if a.normalised else 1.0) for a in node.annotations)
    return default, ann


def adapted_annotations(node: Node) -> tuple[int, ...]:
    """Indices in ``node.annotations`` of the ones whose weight a node that adapts its weights adapts.

    The rule: its safety annotations left at their default weight; a weight the
    user set is kept. The compiled tree, the reward formula and the training-time
    adapter (:mod:`specguard.training.auto_weights`) all read it here.
    """
    return tuple(i for i, a in enumerate(node.annotations) if a.role == SAFETY and a.weight is None)


def annotation_key(path: str, annotation: Annotation) -> str:
    """The key of an annotation's reward term and safety rate: ``path:name``."""
    return f"{path}{ANNOTATION_SEPARATOR}{annotation.name}"


def until_end(tree: Node) -> bool:
    """Whether ``tree``'s goal holds until the end (judged at the last state) rather than ending the episode.

    :meth:`Node.until_end` of the tree, children first.

    Example:
        >>> import specguard as sg
        >>> upright = sg.Goal("upright", theta=(-0.2, 0.2))
        >>> until_end(upright), until_end(sg.Always(upright, name="balance"))
        (False, True)
        >>> until_end(sg.All(sg.Always(upright, name="balance"), sg.Goal("home", x=(0.9, None)), name="carry"))
        False
    """
    return bool(tree.until_end(tuple(until_end(c) for c in tree.children)))


def goal_test(node: Node) -> Callable[[Any], bool]:
    """Membership of a state in the goal of a node without own state, as a function ``test(s)``.

    For regions such as ``Avoid(region)``: any node's goal, evaluated from its
    definition (children first).

    Raises:
        InvalidSpec: the node, or a node below it, has own state (its goal is
            not a function of one state).
    """
    for path, n in node.walk():
        if n.state_slots():
            raise InvalidSpec(
                path, f"{n.kind} has own state, so its goal is not a set of states and cannot serve as a region"
            )

    def member(n: Node, s: Any) -> bool:
        return bool(n.contains(Context(s, (), tuple(member(c, s) for c in n.children))))

    def test(s: Any) -> bool:
        return member(node, s)

    return test
