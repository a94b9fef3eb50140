"""What every evaluator of a goal tree is: the :class:`Evaluator` protocol and its :class:`StepResult`.

Two evaluators implement it: the flat one, compiled once per tree
(:class:`specguard.construction.compiled.FlatEvaluator`), and Algorithm 1 as written
(:class:`specguard.construction.reference.ReferenceEvaluator`). The constructed env, the
baseline env, ``step_batch`` and the contract kit read an evaluator through this protocol
alone, so either serves (``make_env(..., evaluator="reference")``).

Example:
    >>> import specguard as sg
    >>> from specguard.construction.reference import ReferenceEvaluator
    >>> tree = sg.Goal("far", x=(1.0, None))
    >>> for ev in (sg.compile_tree(tree, ("x",)).evaluator(), ReferenceEvaluator(tree, ("x",))):
    ...     assert isinstance(ev, Evaluator)
    ...     _ = ev.reset([0.0])
    ...     print(ev.step(0, [2.0]))
    StepResult(reward=1.0, terminated=True, goals=(True,), terms={'far': 1.0})
    StepResult(reward=1.0, terminated=True, goals=(True,), terms={'far': 1.0})
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple, Protocol, runtime_checkable

from specguard.extend import Slot

__all__ = ["Evaluator", "StepResult"]


class StepResult(NamedTuple):
    """What one transition gives (:meth:`Evaluator.step`).

    Attributes:
        reward: the root requirements' reward, a Python float.
        terminated: whether the spec ends the episode (the root goal reached, a counter at 0, a node's own
            termination); the initial env's own end is not in it.
        goals: every node's membership of the state reached, in :attr:`Evaluator.paths` order.
        terms: every weighted reward component by key, in Algorithm 1's processing order, summing to ``reward``.
    """

    reward: float
    terminated: bool
    goals: tuple[bool, ...]
    terms: dict[str, float]


@runtime_checkable
class Evaluator(Protocol):
    """Steps a goal tree along one episode at a time, holding the episode's state (own-state slots, memberships).

    Attributes:
        paths: every node's path, parents before children (the root first).
        slots: the own-state slots ``(key, slot)``, in observation order.
        safety_keys: the keys of the safety annotations, ``path:name``.
        goals: every node's membership of the last state reset or stepped to, by path (``info["goals"]``).
    """

    paths: tuple[str, ...]
    slots: tuple[tuple[str, Slot], ...]
    safety_keys: tuple[str, ...]
    goals: dict[str, bool]

    @property
    def horizon(self) -> bool:
        """The root goal holds until the end: an episode the initial env terminates ended before its horizon."""
        ...

    @property
    def own_state(self) -> list[float]:
        """The own-state slots in observation order."""
        ...

    @property
    def state(self) -> Any:
        """The features of the last state reset or stepped to (``s.x`` by name)."""
        ...

    @property
    def safe(self) -> tuple[bool, ...]:
        """Per safety annotation, whether the episode has had no violation so far."""
        ...

    def safe_info(self) -> dict[str, bool]:
        """:attr:`safe` by safety key, a new dict (``info["safe"]``)."""
        ...

    def reset(self, f: Sequence[float]) -> tuple[bool, ...]:
        """Start an episode in features ``f``; every node's membership."""
        ...

    def restore(self, f: Sequence[float], own: Sequence[float]) -> tuple[bool, ...]:
        """Start from features ``f`` and the own-state slots ``own`` (an observation's tail)."""
        ...

    def step(self, action: Any, f: Sequence[float], last: bool | None = False, terminated: bool = False) -> StepResult:
        """Advance by one transition to features ``f``.

        ``last``: the initial env ended the episode at ``f``, whose state is judged too (docs/semantics.md,
        "The last state"); ``None``: never judged (the transition's own reward). ``terminated``: that end was
        a termination, before the horizon (:meth:`specguard.extend.Node.terminated_state`).
        """
        ...
