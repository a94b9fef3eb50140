"""``Avoid``: a safety annotation counting the steps that end inside a region.

Its semantics: docs/semantics.md, "Operators beyond the paper".

Example:
    >>> import specguard as sg
    >>> from specguard_plugins import Avoid
    >>> tree = sg.Goal("centre", x=(-0.5, 0.5)).annotate(Avoid({"x": (2.4, None)}, budget=2, name="edges"))
    >>> print(tree)
    Goal 'centre': -0.5 <= x <= 0.5
        + Avoid(Goal 'edges': x >= 2.4, budget=2, name='edges')
    >>> sg.formula(tree)
    'R = R[centre] + P[centre:edges]'
"""

from __future__ import annotations

from collections import abc
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from specguard import Goal
from specguard.error import InvalidSpec
from specguard.extend import SAFETY, Annotation, CounterForm, Node, Slot, goal_test, set_fields
from specguard.validation import check_budget, check_name, check_weight, number_text

if TYPE_CHECKING:
    from hypothesis.strategies import DrawFn, SearchStrategy

__all__ = ["Avoid"]

DEFAULT_NAME = "avoid"


def region_text(node: Node) -> str:
    """The exact text of a region: the node's description, then its children's in brackets."""
    kids = node.children
    if not kids:
        return node.describe()
    return f"{node.describe()} [{'; '.join(region_text(c) for c in kids)}]"


@dataclass(frozen=True, init=False, repr=False)
class Avoid(Annotation):
    """A safety annotation: every step whose next state ``s'`` lies in ``region`` is a violation.

    Semantics (docs/semantics.md, "Operators beyond the paper"), a counter as for ``Constraint``:

    * own state: one slot ``counter`` in ``[0, budget]``, appended to the
      observation, ``budget`` at the start of an episode;
    * a step ``(s, a, s')`` violates when ``s'`` is in ``region`` (judged on the
      next state, not on ``(s, a)`` as a ``Constraint`` is; the first state
      ``s_0`` is never a violation; the last state is judged by the step into
      it, so ``last_state`` judges nothing more); each violation lowers the counter by 1;
    * reward: ``-1`` per violation (the potential is the counter), weighted by
      ``weight``, which defaults to 1 and is outside the ``1/N`` normalisation;
    * termination: the episode ends when the counter reaches 0;
    * safety rate: the engine reports the share of episodes without a violation
      under ``path:name``; ``info["safe"]`` says whether this episode had none.

    The flat evaluator compiles it to straight-line code from its
    :class:`~specguard.extend.CounterForm` (``on_next_state=True``).

    Args:
        region: a node without own state (``Goal``, ``All``, ``AnyOf``, ...),
            whose goal is the region, or a mapping ``{feature: (lo, hi)}`` (or
            ``{feature: value}``), which becomes ``Goal(name, **region)``.
        budget: the violations allowed per episode, an integer ``>= 1``.
        weight: the penalty's weight, a finite number ``>= 0``; ``None`` for 1.
        name: the annotation's name (its reward term is ``path:name``);
            ``"avoid"`` by default.

    Raises:
        InvalidSpec: a bad name, budget or weight; a region that is neither a
            node nor a mapping, an empty or malformed box, or a node with own
            state (a ``Sequence``), whose goal is not a set of states.

    Example:
        >>> import specguard as sg
        >>> from specguard.testing import ReplayEnv
        >>> edges = sg.Goal("edges", x=(2.0, None))
        >>> tree = sg.Goal("far", x=(10.0, None)).annotate(Avoid(edges, budget=2))
        >>> print(tree)
        Goal 'far': x >= 10
            + Avoid(Goal 'edges': x >= 2, budget=2)
        >>> sg.formula(tree)
        'R = R[far] + P[far:avoid]'
        >>> initial = sg.InitialEnv(lambda: ReplayEnv([[0.0], [3.0], [0.0], [2.0], [0.0]]), features=("x",))
        >>> env = sg.make_env(initial, tree)
        >>> obs, info = env.reset(seed=0)
        >>> obs.tolist(), info["safe"]  # x, then the counter
        ([0.0, 2.0], {'far:avoid': True})
        >>> [env.step(0)[1:3] for _ in range(3)]  # the second violation ends the episode
        [(-1.0, False), (0.0, False), (-1.0, True)]
    """

    role: ClassVar[str] = SAFETY
    normalised: ClassVar[bool] = False
    symbol: ClassVar[str] = "P"

    region: Node
    budget: int
    weight: float | None
    name: str

    def __init__(
        self,
        region: Node | abc.Mapping[str, object],
        budget: int = 1,
        weight: float | None = None,
        name: str | None = None,
    ) -> None:
        name = check_name("Avoid", DEFAULT_NAME if name is None else name)
        where = f"Avoid {name!r}"
        node = _region(where, name, region)
        try:
            test = goal_test(node)
        except InvalidSpec as e:
            raise InvalidSpec(
                where,
                f"the region {e.where!r} is not a set of states: {e.message}",
                hint="give a box {feature: (lo, hi)} or a node without own state (Goal, All, AnyOf)",
            ) from e
        set_fields(
            self,
            region=node,
            budget=check_budget(where, budget),
            weight=check_weight(where, weight),
            name=name,
            _test=test,
        )

    def avoids(self) -> Node:
        """The region: the falsifier grades a kept ``Avoid`` by its closest approach to it over the episode."""
        return self.region

    # The membership test is derived from ``region``: not pickled, rebuilt on load.
    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in vars(self).items() if k != "_test"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        set_fields(self, **state)
        set_fields(self, _test=goal_test(self.region))

    def in_region(self, s: Any) -> bool:
        """Whether the state ``s`` (features by attribute) lies in the region."""
        return bool(self._test(s))  # type: ignore[attr-defined]

    # -- the extension protocol: a counter from ``budget`` down ---------------

    def state_slots(self) -> tuple[Slot, ...]:
        return (Slot("counter", 0.0, float(self.budget)),)

    def initial_state(self, s: Any) -> tuple[float, ...]:
        return (float(self.budget),)

    def next_state(self, s: Any, q: tuple[float, ...], action: Any, s2: Any) -> tuple[float, ...]:
        return (q[0] - 1.0,) if self.in_region(s2) else q  # judged on s'

    def potential(self, s: Any, q: tuple[float, ...]) -> float:
        return q[0]  # -1 per violation

    def terminates(self, q: tuple[float, ...]) -> bool:
        return q[0] <= 0.0

    def violations(self, q: tuple[float, ...]) -> int:
        return int(self.budget - q[0])

    def fast_form(self) -> CounterForm:
        return CounterForm(fn=self.in_region, budget=self.budget, on_next_state=True)

    def describe(self) -> str:
        return repr(self)

    def __repr__(self) -> str:
        weight = "" if self.weight is None else f", weight={number_text(self.weight)}"
        name = "" if self.name == DEFAULT_NAME else f", name={self.name!r}"
        return f"Avoid({region_text(self.region)}, budget={self.budget}{weight}{name})"

    # -- Hypothesis ------------------------------------------------------------

    @classmethod
    def strategy(cls, features: abc.Sequence[str], name: str) -> SearchStrategy[Annotation]:
        """``Avoid``\\s of a random box region over ``features``, budget 1 to 4, default or random weight."""
        from hypothesis import strategies as st

        from specguard.strategies import goals

        @st.composite
        def draw_avoid(draw: DrawFn) -> Annotation:
            region = draw(goals(features, name=name))
            budget = draw(st.integers(1, 4))
            weight = draw(st.none() | st.floats(0.0, 10.0))
            return cls(region, budget=budget, weight=weight, name=name)

        return draw_avoid()


def _region(where: str, name: str, region: object) -> Node:
    """The region as a node: a node as given, a mapping as ``Goal(name, **region)``."""
    if isinstance(region, Node):
        return region
    if isinstance(region, abc.Mapping):
        if not region:
            raise InvalidSpec(where, "expected a region box {feature: (lo, hi)} with at least one feature, got {}")
        bad = [k for k in region if not isinstance(k, str)]
        if bad:
            raise InvalidSpec(where, f"expected feature names (str) as the region's keys, got {bad[0]!r}")
        try:
            return Goal(name, **region)
        except InvalidSpec as e:
            raise InvalidSpec(where, f"the region box is malformed: {e.where}: {e.message}", hint=e.hint) from e
    raise InvalidSpec(
        where,
        f"expected region to be a node (Goal, All, AnyOf, ...) or a box {{feature: (lo, hi)}}, got {region!r}",
    )
