"""Text shared by the operators (not public); the per-child weights rule is ``specguard.extend.check_child_weights``."""

from __future__ import annotations

from specguard.validation import number_text

__all__ = ["weights_text"]


def weights_text(weights: tuple[float, ...] | None) -> str:
    """``" weights=(0.5, 1)"`` with every number exact, or ``""`` for the default."""
    return "" if weights is None else f" weights=({', '.join(number_text(w) for w in weights)})"
