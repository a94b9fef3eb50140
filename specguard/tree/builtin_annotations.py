"""The built-in annotations: ``Distance`` and ``Constraint`` (docs/semantics.md, "Reward"), on the extension API.

Example:
    >>> import specguard as sg
    >>> sg.Distance(abs, scale=2.0)
    Distance(abs, scale=2)
    >>> sg.Constraint(lambda s, a: s.x > 1, budget=3, name="edge")
    Constraint(<lambda>, budget=3, name='edge')
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

from specguard.error import EvaluationError
from specguard.extend import SAFETY, SHAPING, Annotation, CounterForm, ShapingForm, Slot
from specguard.utils.text import function_text, number_text
from specguard.validation import check_budget, check_callable, check_name, check_positive, check_truth, check_weight

if TYPE_CHECKING:
    from hypothesis.strategies import SearchStrategy

__all__ = ["Constraint", "Distance"]

_FLOAT_MAX = sys.float_info.max  # read every step by operators that shape with a Distance (a Sequence)


def _text(a: Distance | Constraint, default_name: str, arguments: str) -> str:
    """The exact description: ``Kind(fn, arguments[, weight=...][, name=...])``, defaults left out."""
    weight = "" if a.weight is None else f", weight={number_text(a.weight)}"
    name = "" if a.name == default_name else f", name={a.name!r}"
    return f"{type(a).__name__}({function_text(a.fn)}, {arguments}{weight}{name})"


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

    role: ClassVar[str] = SHAPING
    normalised: ClassVar[bool] = True
    symbol: ClassVar[str] = "D"

    fn: Callable[[Any], float]
    scale: float
    weight: float | None = None
    name: str = "distance"

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", check_name("Distance", self.name))
        where = f"Distance {self.name!r}"
        check_callable(where, self.fn, "fn(s)")
        scale = check_positive(where, "scale", self.scale, "the maximum distance to the goal")
        object.__setattr__(self, "scale", scale)
        object.__setattr__(self, "weight", check_weight(where, self.weight))

    def value(self, s: Any) -> float:
        """``fn(s)``, checked to be a finite number ``>= 0`` (docs/semantics.md, "Distance shaping").

        Raises:
            EvaluationError: ``fn`` raised, or returned a negative, infinite or NaN distance.
        """
        try:
            d = float(self.fn(s))
        except Exception as e:
            raise EvaluationError(f"the distance function raised {type(e).__name__}: {e} (state {s})") from e
        if not 0.0 <= d <= _FLOAT_MAX:  # NaN fails it too
            raise EvaluationError(f"expected a finite distance >= 0, got {d!r} (state {s})")
        return d

    def potential(self, s: Any, q: tuple[float, ...]) -> float:
        # Phi = -fn(s) / d, so R = (fn(s) - fn(s')) / d. A Sequence asks it every step: the checks of
        # value() written out here; it calls value() for the message when fn raised or returned a bad distance.
        try:
            d = float(self.fn(s))
        except Exception:
            d = self.value(s)
        if not 0.0 <= d <= _FLOAT_MAX:  # NaN fails it too
            d = self.value(s)
        return -d / self.scale

    def reward(self, s: Any, q: tuple[float, ...], action: Any, s2: Any, q2: tuple[float, ...]) -> float:
        return (self.value(s) - self.value(s2)) / self.scale  # as the docs write it (same rounding as the fast path)

    def fast_form(self) -> ShapingForm:
        return ShapingForm(self.fn, self.scale)

    def __repr__(self) -> str:
        return _text(self, "distance", f"scale={number_text(self.scale)}")

    @classmethod
    def strategy(cls, features: Sequence[str], name: str) -> SearchStrategy[Annotation]:
        from specguard.tree._draw import distances

        return distances(cls, features, name=name)


@dataclass(frozen=True)
class Constraint(Annotation):
    """A safety constraint: a violation counter with a budget (docs/semantics.md, "Constraint penalties").

    Args:
        fn: ``fn(s, a) -> bool``, true for a violating state-action pair. The state an episode ends
            in is judged too, with the action that led to it (docs/semantics.md, "The last state").
        budget: ``delta >= 1``, the violations allowed in an episode; the
            episode ends when the counter ``delta - violations`` reaches 0.
        weight: the penalty's weight; defaults to 1 and is not part of the
            ``1/N`` normalisation.
        name: the component's name; defaults to ``"constraint"``.
    """

    role: ClassVar[str] = SAFETY
    normalised: ClassVar[bool] = False
    symbol: ClassVar[str] = "P"

    fn: Callable[[Any, Any], bool]
    budget: int = 1
    weight: float | None = None
    name: str = None  # type: ignore[assignment]  # None: "constraint"

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", check_name("Constraint", "constraint" if self.name is None else self.name))
        where = f"Constraint {self.name!r}"
        check_callable(where, self.fn, "fn(s, a)")
        object.__setattr__(self, "budget", check_budget(where, self.budget))
        object.__setattr__(self, "weight", check_weight(where, self.weight))

    # The counter s_C = delta - violations (docs/semantics.md, "Constraint penalties").
    def state_slots(self) -> tuple[Slot, ...]:
        return (Slot("counter", 0.0, float(self.budget)),)

    def initial_state(self, s: Any) -> tuple[float, ...]:
        return (float(self.budget),)

    def next_state(self, s: Any, q: tuple[float, ...], action: Any, s2: Any) -> tuple[float, ...]:
        violated = check_truth(None, self.fn(s, action))  # the evaluator names the key, as the flat one does
        return (q[0] - 1.0,) if violated else q  # judged on (s, a), as R_pen is

    def last_state(self, s: Any, q: tuple[float, ...], action: Any) -> tuple[float, ...]:
        # The last state s_T, with the action a_{T-1} that led to it; a spent counter stays at 0.
        if q[0] <= 0.0 or not check_truth(None, self.fn(s, action)):
            return q
        return (q[0] - 1.0,)

    def potential(self, s: Any, q: tuple[float, ...]) -> float:
        return q[0]  # R_pen = -1 per violation = s_C' - s_C

    def terminates(self, q: tuple[float, ...]) -> bool:
        return q[0] <= 0.0  # T <- T u {s_C = 0}

    def violations(self, q: tuple[float, ...]) -> int:
        return int(self.budget - q[0])

    def fast_form(self) -> CounterForm:
        return CounterForm(self.fn, int(self.budget))

    def __repr__(self) -> str:
        return _text(self, "constraint", f"budget={self.budget}")

    @classmethod
    def strategy(cls, features: Sequence[str], name: str) -> SearchStrategy[Annotation]:
        from specguard.tree._draw import constraints

        return constraints(cls, features, name=name)
