"""Naming goals and their thresholds: the one resolver and the one threshold rule.

``Spec(expect=...)``, ``@sg.goal_spec(expect=...)``, the CLI and stored
baselines all go through :func:`resolve_goal` and :func:`check_threshold`, so
a name means the same goal, and a threshold the same range, everywhere.
Imports nothing heavy: the pytest plugin uses it at collection.

Example:
    >>> import specguard as sg
    >>> tree = sg.All(sg.Goal("up", x=(0.9, 1.0)), sg.Goal("slow", v=(-0.1, 0.1)), name="pendulum")
    >>> resolve_goal(tree, "up", "expect"), resolve_goal(tree, ROOT, "expect")
    ('pendulum/up', 'pendulum')
    >>> check_threshold("expect['up']", 0.9)
    0.9
"""

from __future__ import annotations

import math
from numbers import Real
from typing import TYPE_CHECKING, Any

from specguard.error import InvalidSpec

if TYPE_CHECKING:
    from specguard.nodes import Node

__all__ = ["ROOT", "check_threshold", "resolve_goal"]


class _RootGoal:
    """The root goal, whatever its name: what a single-number ``expect`` asserts."""

    def __repr__(self) -> str:
        return "root"

    def __reduce__(self) -> str:
        return "ROOT"  # one instance, also after pickling


ROOT: Any = _RootGoal()


def check_threshold(where: str, value: object) -> float:
    """The one rule for a success threshold: a number in ``[0, 1)``.

    1 is refused: a run meets a threshold when its whole confidence interval
    lies at or above it, and an interval from finitely many episodes never
    lies entirely at 1.

    Raises:
        InvalidSpec: naming ``where``, the value given and the range expected.
    """
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        raise InvalidSpec(where, f"expected a success rate in [0, 1), got {value!r}")
    if value == 1.0:
        raise InvalidSpec(
            where,
            "a threshold of 1 can never be met: a run meets a threshold when its whole confidence interval lies "
            "at or above it, and an interval from finitely many episodes never lies entirely at 1",
            hint="ask for e.g. 0.95 (30 of 30 successful episodes give the 95% interval [0.884, 1])",
        )
    rate = float(value)
    if not 0.0 <= rate < 1.0:
        raise InvalidSpec(where, f"expected a success rate in [0, 1), got {value!r}")
    return rate


def resolve_goal(tree: Node, key: object, where: str) -> str:
    """The one goal-name resolver: the full node path that ``key`` names in ``tree``.

    ``key`` is :data:`ROOT`, a full node path, or the name of exactly one node
    (a path wins over a name; nothing else is special, a node named "root"
    included).

    Raises:
        InvalidSpec: an unknown or ambiguous name, naming ``where`` and the
            tree's paths.
    """
    paths = [p for p, _ in tree.walk()]
    if key is ROOT:
        return paths[0]
    if not isinstance(key, str):
        raise InvalidSpec(where, f"expected a node path or name as goal, got {key!r}")
    if key in paths:
        return key
    named = [p for p in paths if p.rsplit("/", 1)[-1] == key]
    if len(named) == 1:
        return named[0]
    if named:
        raise InvalidSpec(where, f"the name {key!r} is ambiguous; use one of the paths {', '.join(named)}")
    raise InvalidSpec(
        where,
        f"no node is named {key!r}; the tree's goals are {', '.join(paths)}",
        hint="name a goal by its path or its unique name; a single number asserts the root goal",
    )
