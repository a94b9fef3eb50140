"""Argument checks shared by the operators, built on :mod:`specguard.validation` (not public)."""

from __future__ import annotations

from collections.abc import Sequence

from specguard.error import InvalidSpec
from specguard.extend import Node
from specguard.validation import check_weight, number_text

__all__ = ["check_weights", "weights_text"]


def check_weights(where: str, children: tuple[Node, ...], weights: object, what: str) -> tuple[float, ...] | None:
    """``None``, or one finite weight ``>= 0`` per child, at least one of them ``> 0``.

    Args:
        where: the node at fault, as errors name it (``"AnyOf 'reach'"``).
        children: the node's checked children.
        weights: what the user passed.
        what: what a weight scales, for the message (``"its distances and penalties"``).

    Raises:
        InvalidSpec: ``weights`` is not a sequence, has the wrong length, holds
            something other than a finite number ``>= 0``, or is all zeros.
    """
    if weights is None:
        return None
    if isinstance(weights, (str, bytes)) or not isinstance(weights, Sequence):
        raise InvalidSpec(where, f"expected weights to be a sequence of numbers (one per child), got {weights!r}")
    if len(weights) != len(children):
        raise InvalidSpec(
            where,
            f"expected {len(children)} weights (one per child), got {len(weights)}: {tuple(weights)!r}",
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
            f"a weight scales {what}, and all-zero weights make them identically 0",
            hint="weights need not sum to 1; omit weights= for the default",
        )
    return tuple(parsed)


def weights_text(weights: tuple[float, ...] | None) -> str:
    """``" weights=(0.5, 1)"`` with every number exact, or ``""`` for the default."""
    return "" if weights is None else f" weights=({', '.join(number_text(w) for w in weights)})"
