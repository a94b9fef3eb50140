"""``Sequence``: the THEN-operator, its children's goals reached one after the other.

Its semantics: docs/semantics.md, "Operators beyond the paper".

Example:
    >>> import specguard as sg
    >>> from specguard_plugins import Sequence
    >>> def to_b(s):
    ...     return abs(s.x - 2.0)
    >>> tree = Sequence(
    ...     sg.Goal("a", x=(None, -1.0)),
    ...     sg.Goal("b", x=(2.0, None)).annotate(sg.Distance(to_b, scale=4.0)),
    ...     name="there_and_back",
    ... )
    >>> print(tree)
    Sequence 'there_and_back'
    ├── Goal 'a': x <= -1
    └── Goal 'b': x >= 2
            + Distance(to_b, scale=4)
    >>> sg.formula(tree)
    'R = Seq[there_and_back]'
"""

from __future__ import annotations

from collections import abc
from dataclasses import dataclass
from itertools import accumulate
from typing import TYPE_CHECKING, Any, ClassVar

from specguard.error import InvalidSpec
from specguard.extend import (
    SHAPING,
    Annotation,
    ChildWeights,
    Context,
    Node,
    ShapingForm,
    Slot,
    StagesForm,
    check_child_weights,
    set_fields,
)
from specguard_plugins._checks import weights_text

if TYPE_CHECKING:
    from hypothesis.strategies import SearchStrategy

__all__ = ["Sequence"]


@dataclass(frozen=True, init=False, repr=False)
class Sequence(Node):
    """The THEN-operator: reach ``c_1``, then ``c_2``, ..., then ``c_N``.

    Semantics (docs/semantics.md, "Operators beyond the paper"):

    * own state: one slot ``stage`` in ``[0, N]``, appended to the observation.
      ``q_0`` is the number of leading children whose goals already hold in
      ``s_0``, in order; after a step, ``while q < N and s' in G_{q+1}: q += 1``
      (so one step may pass several stages);
    * goal: ``G = {q = N}``; the node's success is ``q_T = N``, and at the root
      reaching it ends the episode. Being inside a child's goal out of order
      (``c_2`` before ``c_1``) counts for nothing;
    * core reward: the potential difference ``Phi(s', q') - Phi(s, q)`` with
      ``Phi(s, q) = stage(q) + shaping(s, q)``, which telescopes exactly:

      - ``stage(q) = q / N``, so advancing pays ``(q' - q) / N``; with
        ``weights=`` passing stage ``i`` pays ``weights[i]`` instead
        (``stage(q) = weights[0] + ... + weights[q-1]``);
      - ``shaping(s, q)`` is the **active** stage's weight ``w_{q+1}`` (``1/N``
        by default) times the sum over the active child ``c_{q+1}``'s own
        shaping annotations (``Distance``) of ``w * a.potential(s, ())``, i.e.
        ``-w * fn(s) / scale``, where ``w`` is the annotation's ``weight`` if the
        user set one, else 1; ``shaping(s, N) = 0``. Shaping annotations deeper
        in a child's subtree do not shape.

        Decision (the unscaled form is ``Phi(s, q) = -fn_{q+1}(s) / d_{q+1}``, without
        the stage weight): unscaled, entering a stage whose next goal is far
        costs up to ``1 - 1/N`` net (``1/N`` for the stage, ``-fn/d`` down to
        ``-1`` for the new distance), and trained agents learn to stop short of
        the stage. Measured on ``example_specs/cartpole.py``: PPO agents drifted
        to ``x = 0.38`` and held there, never entering ``x >= 0.5``. Scaled by
        the stage weight, with ``fn <= d`` as a scale promises, advancing never
        loses reward when the stages weigh the same; the sum still telescopes;
    * children: ``ChildWeights(core=0, shaping=0, safety=1)`` each: their own
      goal rewards are not added (the stage reward replaces them), their
      distances are taken over by the sequence (their terms are reported with
      weight 0, and the formula shows them inside ``Seq[name]``), their
      constraints and ``Avoid`` penalties stay in force;
    * termination: the union of the children's; the node adds none of its own;
    * it is not a set of states (its goal depends on ``q``), so it has no box,
      no refinements and cannot serve as an ``Avoid`` region.

    Decision: one child is allowed (the minimum ``check_children`` enforces);
    ``Sequence(c, name=...)`` is then "reach ``c`` once", which stays achieved
    when the agent leaves ``G_c`` (unlike ``c`` itself).

    Args:
        *children: the stages in order, at least one, with distinct names.
        name: the node's name.
        weights: ``None`` (``1/N`` per stage), or one weight ``>= 0`` per stage,
            at least one ``> 0``: what passing that stage pays.

    Raises:
        InvalidSpec: a bad name, no child, a child that is not a node, two
            children with one name, weights that are not one finite number
            ``>= 0`` per child with one of them ``> 0``, or a child's shaping
            annotation with own state (its potential must depend on ``s`` only).

    Example:
        >>> import specguard as sg
        >>> from specguard.testing import ReplayEnv
        >>> tree = Sequence(sg.Goal("a", x=(None, -1.0)), sg.Goal("b", x=(2.0, None)), name="seq")
        >>> print(tree)
        Sequence 'seq'
        ├── Goal 'a': x <= -1
        └── Goal 'b': x >= 2
        >>> sg.formula(tree)
        'R = Seq[seq]'
        >>> replay = sg.InitialEnv(lambda: ReplayEnv([[0.0], [3.0], [-2.0], [3.0], [0.0]]), features=("x",))
        >>> env = sg.make_env(replay, tree)
        >>> obs, info = env.reset(seed=0)
        >>> obs.tolist()  # x, then the stage
        [0.0, 0.0]
        >>> [env.step(0)[1] for _ in range(3)]  # b before a pays nothing
        [0.0, 0.5, 0.5]
    """

    kind: ClassVar[str] = "Sequence"
    own_reward: ClassVar[bool] = True
    symbol: ClassVar[str] = "R"
    name: str
    nodes: tuple[Node, ...]
    weights: tuple[float, ...] | None
    annotations: tuple[Annotation, ...]

    def __init__(self, *children: Node, name: str, weights: abc.Sequence[float] | None = None) -> None:
        name, kids = self.init_node(name, children)
        where = f"Sequence {name!r}"
        parsed = check_child_weights(where, kids, weights, scales="what passing a stage pays", default="the default")
        for child in kids:
            for a in child.annotations:
                if a.role == SHAPING and a.state_slots():
                    raise InvalidSpec(
                        where,
                        f"child {child.name!r} has the shaping annotation {a.describe()} with own state; "
                        "a sequence shapes with the active child's potentials of s alone",
                        hint="use a stateless shaping annotation (Distance) on the sequence's children",
                    )
        set_fields(self, weights=parsed)
        # Derived once, read every step: stage(q) for q = 0..N, and each child's (annotation, weight) shapers.
        stage_weights = self.stage_weights()
        shapers = tuple(
            tuple(
                (a, stage_weights[i] * (1.0 if a.weight is None else a.weight))
                for a in c.annotations
                if a.role == SHAPING
            )
            for i, c in enumerate(kids)
        )
        set_fields(self, _stage=tuple(accumulate(stage_weights, initial=0.0)), _shapers=shapers)

    def stage_weights(self) -> tuple[float, ...]:
        """What passing each stage pays: the user's weights, or ``1/N`` each."""
        n = len(self.nodes)
        return self.weights if self.weights is not None else (1.0 / n,) * n

    # -- the extension protocol ------------------------------------------------

    def child_weights(self) -> tuple[ChildWeights, ...]:
        """Per child ``(core=0, shaping=0, safety=1)``: only the child's penalties reach the parent."""
        return (ChildWeights(core=0.0, shaping=0.0, safety=1.0),) * len(self.nodes)

    def state_slots(self) -> tuple[Slot, ...]:
        return (Slot("stage", 0.0, float(len(self.nodes))),)

    def initial_state(self, ctx: Context) -> tuple[float, ...]:
        q = 0
        while q < len(self.nodes) and ctx.inside[q]:
            q += 1
        return (float(q),)

    def next_state(self, before: Context, action: Any, s2: Any, inside2: tuple[bool, ...]) -> tuple[float, ...]:
        q = int(before.q[0])
        while q < len(self.nodes) and inside2[q]:
            q += 1
        return (float(q),)

    def contains(self, ctx: Context) -> bool:
        return ctx.q[0] >= len(self.nodes)

    def stage_potential(self, q: int) -> float:
        """``stage(q)``: the stage rewards paid for reaching stage ``q`` from 0."""
        return float(self._stage[q])  # type: ignore[attr-defined]

    def shaping_potential(self, s: Any, q: int) -> float:
        """``shaping(s, q)``: the active child's own shaping potentials in ``s``, scaled by its stage's weight.

        0 once every stage is passed.
        """
        if q >= len(self.nodes):
            return 0.0
        total = 0.0
        for a, w in self._shapers[q]:  # type: ignore[attr-defined]
            total += w * a.potential(s, ())
        return total

    def potential(self, ctx: Context) -> float:
        q = int(ctx.q[0])
        return self._stage[q] + self.shaping_potential(ctx.s, q)  # type: ignore[attr-defined, no-any-return]

    def fast_form(self) -> StagesForm | None:
        """The stage counter compiled to straight-line code, when every shaper declares a distance.

        Each shaper's weight is its stage's times its own (:meth:`shaping_potential`); a shaper without a
        :class:`~specguard.extend.ShapingForm` leaves the node evaluated from its methods.
        """
        shapers = []
        for stage in self._shapers:  # type: ignore[attr-defined]
            forms = [(a.fast_form(), w) for a, w in stage]
            if not all(isinstance(form, ShapingForm) for form, _ in forms):
                return None
            shapers.append(tuple((form.fn, form.scale, w) for form, w in forms))
        return StagesForm(self._stage, tuple(shapers))  # type: ignore[attr-defined]

    def describe(self) -> str:
        return f"Sequence {self.name!r}{weights_text(self.weights)}"

    def formula_term(self, label: str) -> str:
        return f"Seq[{label}]"

    def __repr__(self) -> str:
        kids = ", ".join(map(repr, self.nodes))
        weights = "" if self.weights is None else f", weights={self.weights!r}"
        annotated = f".annotate({', '.join(a.describe() for a in self.annotations)})" if self.annotations else ""
        return f"Sequence({kids}, name={self.name!r}{weights}){annotated}"

    # -- Hypothesis ------------------------------------------------------------

    @classmethod
    def strategy(cls, children: abc.Sequence[Node], name: str) -> SearchStrategy[Node]:
        """``Sequence(*children, name=name)`` with default or random stage weights."""
        from specguard.strategies import weights

        return weights(len(children)).map(lambda w: cls(*children, name=name, weights=w))
