"""The errors specguard raises, in one place (as Gymnasium keeps its ``error.py``).

Every message says *where* the problem is (the node path, annotation or option),
*what was expected* and *what was given*, and where it helps, a hint. Callers can
catch :class:`SpecError` to handle all of them.
"""

from __future__ import annotations

__all__ = [
    "EvaluationError",
    "FingerprintError",
    "InitialEnvError",
    "InvalidSpec",
    "SpecError",
    "StateMappingError",
    "UnknownFeature",
]


class SpecError(Exception):
    """Base class of every error specguard raises on purpose."""


class InvalidSpec(SpecError, ValueError):
    """A goal tree node or annotation is malformed.

    Attributes:
        where: the node path (``"pendulum/position"``) or annotation
            (``"pendulum/position:distance"``) at fault.
    """

    def __init__(self, where: str, message: str, hint: str | None = None) -> None:
        self.where = where
        self.message = message
        self.hint = hint
        text = f"{where}: {message}"
        if hint:
            text += f"\nHint: {hint}"
        super().__init__(text)

    def __reduce__(self) -> tuple[type, tuple[str, str, str | None]]:
        # Raised in training worker processes: must survive pickling.
        return type(self), (self.where, self.message, self.hint)


class UnknownFeature(InvalidSpec):
    """A goal or annotation names a feature the initial environment does not have."""


class InitialEnvError(SpecError):
    """The initial environment cannot be built or does not fit its declaration."""


class StateMappingError(InitialEnvError):
    """``state()`` returned something that is not a feature vector of the declared length."""


class EvaluationError(SpecError):
    """A user function (distance, constraint, ``state``) failed or returned a bad value during a step."""


class FingerprintError(InvalidSpec):
    """A value in a spec cannot be fingerprinted exactly, so its runs could not be cached safely."""
