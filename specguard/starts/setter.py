"""How one kind of env is put in a start state (:class:`Setter`): what the built-in and the MuJoCo setters share."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym

__all__ = ["Range", "Setter", "env_label"]

Range = tuple[float, float]
"""An inclusive range ``(lo, hi)``."""


@dataclass(frozen=True)
class Setter:
    """How one kind of env is put in a start state.

    Attributes:
        names: the state variables, in order.
        bounds: per variable, the range any start must lie in (``+-inf`` for none).
        default: per variable, the env's own reset range (the start space's default); a variable
            without one is searched only where the space names it, else keeps what reset gave.
        apply: ``apply(env, values) -> observation``: sets ``env.unwrapped``'s state.
        parameters: physical parameters a start space may also range over, by
            name: the attribute of ``env.unwrapped`` each sets (any value > 0).
        settle: ``settle(unwrapped)`` after parameters are set: recomputes what the env derives from them.
    """

    names: tuple[str, ...]
    bounds: Mapping[str, Range]
    default: Mapping[str, Range]
    apply: Callable[[gym.Env, Mapping[str, float]], Any]
    parameters: Mapping[str, str] = field(default_factory=dict)
    settle: Callable[[Any], None] | None = None

    def with_parameters(self, names: tuple[str, ...]) -> Callable[[gym.Env, Mapping[str, float]], Any]:
        """``apply`` that also sets the parameters ``names`` from the values, before the state."""
        if not names:
            return self.apply
        attributes = {n: self.parameters[n] for n in names}
        settle, apply = self.settle, self.apply

        def apply_all(env: gym.Env, values: Mapping[str, float]) -> Any:
            u = env.unwrapped
            for name, attribute in attributes.items():
                setattr(u, attribute, float(values[name]))
            if settle is not None:
                settle(u)
            return apply(env, values)

        return apply_all


def env_label(env: gym.Env) -> str:
    """The env's id, or its unwrapped class's name: for messages."""
    spec = getattr(env, "spec", None)
    return getattr(spec, "id", None) or type(env.unwrapped).__name__
