"""Deliberately broken operators, written on the public extension API, for ``tests/test_contract.py``.

Each breaks one invariant of the operator contract (docs/semantics.md) the way a plausible bug would,
and one check of :mod:`specguard.contract.invariants` must catch it (``CAUGHT_BY``).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import specguard as sg
from specguard.extend import ChildWeights, Context, Node, Slot


class _Combiner(Node):
    """An ``All``-like operator (goal: every child's), the base of the broken ones below."""

    kind = "Combiner"

    def __init__(self, *children: Node, name: str) -> None:
        self.init_node(name, children)

    def child_weights(self) -> tuple[ChildWeights, ...]:
        return (ChildWeights(core=0.0, shaping=1.0, safety=1.0),) * len(self.nodes)

    def contains(self, ctx: Context) -> bool:
        return all(ctx.inside)

    def describe(self) -> str:
        return f"{self.kind} {self.name!r}"


class PaysEveryStep(_Combiner):
    """Pays 1 for every step spent inside its goal, not for entering it: re-entry and staying are paid again."""

    kind = "PaysEveryStep"

    def reward(self, before: Context, action: Any, after: Context) -> float:
        return 1.0 if self.contains(after) else 0.0  # the potential stays membership: it does not telescope


class HiddenSequence(_Combiner):
    """A sequence that keeps its stage in a mutable attribute instead of ``state_slots``: not in the observation."""

    kind = "HiddenSequence"

    def __init__(self, *children: Node, name: str) -> None:
        super().__init__(*children, name=name)
        self.progress = [0]  # hidden episode state, never reset

    def child_weights(self) -> tuple[ChildWeights, ...]:
        return (ChildWeights(core=0.0, shaping=0.0, safety=1.0),) * len(self.nodes)

    def contains(self, ctx: Context) -> bool:
        while self.progress[0] < len(self.nodes) and ctx.inside[self.progress[0]]:
            self.progress[0] += 1
        return self.progress[0] == len(self.nodes)


_STAGES: dict[str, int] = {}  # ModuleStateSequence's episode state, by node name, outside every tree


class ModuleStateSequence(_Combiner):
    """A sequence whose stage lives in a module-level dict, restarted whenever no stage holds: in no observation.

    Written as an outside author might from the operator API alone. Every copy of
    the tree shares the stage, so transitions replayed in the trajectory's order
    see it evolve exactly as the env did.
    """

    kind = "ModuleStateSequence"

    def child_weights(self) -> tuple[ChildWeights, ...]:
        return (ChildWeights(core=0.0, shaping=0.0, safety=1.0),) * len(self.nodes)

    def _stage(self) -> int:
        return _STAGES.get(self.name, 0)

    def _set_stage(self, stage: int) -> None:
        _STAGES[self.name] = stage

    def contains(self, ctx: Context) -> bool:
        stage = self._stage() if any(ctx.inside) else 0  # outside every stage: start over
        while stage < len(self.nodes) and ctx.inside[stage]:
            stage += 1
        self._set_stage(stage)
        return stage == len(self.nodes)


class ClassStateSequence(ModuleStateSequence):
    """The same sequence with its stage kept on the class: shared by every instance, in no observation."""

    kind = "ClassStateSequence"
    stages: ClassVar[dict[str, int]] = {}

    def _stage(self) -> int:
        return type(self).stages.get(self.name, 0)

    def _set_stage(self, stage: int) -> None:
        type(self).stages[self.name] = stage


_PROGRESS: dict[str, int] = {}  # SlotlessSequence's stage, by node name, written by its state methods


class SlotlessSequence(_Combiner):
    """A sequence that keeps its stage in a module-level dict from ``initial_state``/``next_state``, with no slots.

    Written as an outside author might who overrides the state methods but forgets
    ``state_slots``: no evaluator calls the state methods of a node without slots, so
    nothing writes the stage, and ``contains`` answers from a dict nobody writes. The
    node is a constant "never reached" goal: Markov, and alike in every evaluator.
    """

    kind = "SlotlessSequence"

    def child_weights(self) -> tuple[ChildWeights, ...]:
        return (ChildWeights(core=0.0, shaping=0.0, safety=1.0),) * len(self.nodes)

    def _advance(self, stage: int, inside: tuple[bool, ...]) -> int:
        while stage < len(self.nodes) and inside[stage]:
            stage += 1
        _PROGRESS[self.name] = stage
        return stage

    def initial_state(self, ctx: Context) -> tuple[float, ...]:
        self._advance(0, ctx.inside)
        return ()

    def next_state(self, before: Context, action: Any, s2: Any, inside2: tuple[bool, ...]) -> tuple[float, ...]:
        self._advance(_PROGRESS.get(self.name, 0), inside2)
        return ()

    def contains(self, ctx: Context) -> bool:
        return _PROGRESS.get(self.name, 0) == len(self.nodes)


class DropsTermination(_Combiner):
    """Never terminates, even when a child's subtree ended (a constraint below it ran out of budget)."""

    kind = "DropsTermination"

    def terminates(self, ctx: Context, ended: tuple[bool, ...]) -> bool:
        return False


class AddressInDescribe(_Combiner):
    """Describes itself with ``object.__repr__``: a memory address, different in every process."""

    kind = "AddressInDescribe"

    def describe(self) -> str:
        return object.__repr__(self)


class UnorderedDescribe(_Combiner):
    """Lists its children from a set: the order follows the string hash seed, so it differs between processes."""

    kind = "UnorderedDescribe"

    def describe(self) -> str:
        return f"{self.kind} {self.name!r} of {', '.join({c.name for c in self.nodes})}"


class OverfullLatch(_Combiner):
    """Remembers having been in its goal, but counts entries in a slot declared ``[0, 1]``, so it overflows."""

    kind = "OverfullLatch"

    def state_slots(self) -> tuple[Slot, ...]:
        return (Slot("latched", 0.0, 1.0),)

    def initial_state(self, ctx: Context) -> tuple[float, ...]:
        return (1.0 if all(ctx.inside) else 0.0,)

    def next_state(self, before: Context, action: Any, s2: Any, inside2: tuple[bool, ...]) -> tuple[float, ...]:
        return (before.q[0] + 1.0,) if all(inside2) else before.q  # should be min(q + 1, 1)

    def contains(self, ctx: Context) -> bool:
        return ctx.q[0] >= 1.0


class FallOverflow(_Combiner):
    """Holds until the end, like ``Always``, but marks a fall ``-1`` in a slot declared ``[0, 1]``.

    Only a base env that terminates the episode (a fall) asks ``terminated_state``, so only the examples
    that end by termination can catch it.
    """

    kind = "FallOverflow"

    def state_slots(self) -> tuple[Slot, ...]:
        return (Slot("held", 0.0, 1.0),)

    def initial_state(self, ctx: Context) -> tuple[float, ...]:
        return (1.0 if all(ctx.inside) else 0.0,)

    def next_state(self, before: Context, action: Any, s2: Any, inside2: tuple[bool, ...]) -> tuple[float, ...]:
        return (1.0 if before.q[0] >= 1.0 and all(inside2) else 0.0,)

    def terminated_state(self, after: Context) -> tuple[float, ...]:
        return (-1.0,)  # should be (0.0,): a fall is not kept, and the slot's bounds are [0, 1]

    def contains(self, ctx: Context) -> bool:
        return ctx.q[0] >= 1.0 and all(ctx.inside)

    def until_end(self, children: tuple[bool, ...]) -> bool:
        return True


class WrongBox(_Combiner):
    """An OR operator (goal: any child's) that declares the intersection of its children's boxes as its box.

    The flat evaluator trusts a declared box; the reference evaluator asks ``contains``.
    """

    kind = "WrongBox"
    own_reward = False

    def child_weights(self) -> tuple[ChildWeights, ...]:
        return (ChildWeights.same(1.0 / len(self.nodes)),) * len(self.nodes)

    def box(self, child_boxes: Any) -> Any:
        return sg.All.box(self, child_boxes)  # type: ignore[arg-type]  # wrong: the union is not this box

    def contains(self, ctx: Context) -> bool:
        return any(ctx.inside)

    def potential(self, ctx: Context) -> float:
        return 0.0


class InfiniteOutside(_Combiner):
    """Its potential is ``-inf`` outside its goal, so its rewards are ``inf`` or NaN."""

    kind = "InfiniteOutside"

    def potential(self, ctx: Context) -> float:
        return 0.0 if self.contains(ctx) else -math.inf


class LooseRefinement(_Combiner):
    """Refines a leaf into one child whose box is wider by 1 on the leaf's first feature: not the leaf's goal."""

    kind = "LooseRefinement"

    @classmethod
    def refinements(cls, leaf: Node) -> Any:
        from hypothesis import strategies as st

        if not isinstance(leaf, sg.Goal):
            return None

        def side(v: float, widen: float) -> float | None:
            return None if math.isinf(v) else v + widen

        (f, lo, hi), *rest = leaf.bounds
        box = {f: (side(lo, -1.0), side(hi, 1.0)), **{g: (side(a, 0.0), side(b, 0.0)) for g, a, b in rest}}
        return st.just(cls(sg.Goal("part0", **box), name=leaf.name))


CAUGHT_BY = {
    PaysEveryStep: "check_core_reward_telescopes",
    HiddenSequence: "check_markov",
    ModuleStateSequence: "check_markov",
    ClassStateSequence: "check_markov",
    SlotlessSequence: "check_state_methods_have_slots",
    DropsTermination: "check_termination_includes_children",
    AddressInDescribe: "check_description_is_exact",
    UnorderedDescribe: "check_description_is_exact",
    OverfullLatch: "check_observations_in_space",
    FallOverflow: "check_observations_in_space",
    WrongBox: "check_flat_matches_reference",
    InfiniteOutside: "check_rewards_are_finite_sums_of_terms",
    LooseRefinement: "check_refinement_preserves_root_goal",
}
"""Each broken operator and the check that must catch it."""
