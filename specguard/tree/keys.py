"""Naming goals and safety rates, and their thresholds: the one resolver and the one threshold rule.

A result measures, per evaluation episode, two kinds of *rates* under one
mapping of keys (``RunResult.successes``):

* a **goal** per node, keyed by its path (``lunar/legs``): the episodes whose
  last state lies in the node's goal;
* a **safety rate** per safety annotation (``role == "safety"``: ``Constraint``,
  ``Avoid``), keyed ``path:name`` (``lunar:crash``): the episodes without a
  violation.

Names cannot contain ``/`` or ``:``, so the two kinds of keys never collide
(:func:`is_safety_key`). ``Spec(expect=...)``, ``@sg.goal_spec(expect=...)``,
the CLI and stored baselines all go through :func:`resolve_goal` and
:func:`check_threshold`, so a name means the same goal or safety rate, and a
threshold the same range, everywhere. Imports nothing heavy: the pytest plugin
uses it at collection.

Example:
    >>> import specguard as sg
    >>> up = sg.Goal("up", x=(0.9, 1.0)).annotate(sg.Constraint(lambda s, a: s.x > 1.5, name="spin"))
    >>> tree = sg.All(up, sg.Goal("slow", v=(-0.1, 0.1)), name="pendulum")
    >>> resolve_goal(tree, "up", "expect"), resolve_goal(tree, ROOT, "expect")
    ('pendulum/up', 'pendulum')
    >>> resolve_goal(tree, "pendulum/up:spin", "expect"), resolve_goal(tree, "spin", "expect")
    ('pendulum/up:spin', 'pendulum/up:spin')
    >>> result_keys(tree)
    ['pendulum', 'pendulum/up', 'pendulum/slow', 'pendulum/up:spin']
    >>> label("pendulum/up:spin")
    'pendulum/up:spin (safe)'
    >>> check_threshold("expect['up']", 0.9)
    0.9
"""

from __future__ import annotations

import math
from numbers import Real
from typing import TYPE_CHECKING, Any

from specguard.error import InvalidSpec
from specguard.extend import SAFETY, annotation_key
from specguard.validation import ANNOTATION_SEPARATOR

if TYPE_CHECKING:
    from specguard.extend import Node

__all__ = [
    "GOAL",
    "ROOT",
    "SAFETY",
    "check_threshold",
    "is_safety_key",
    "kind",
    "label",
    "resolve_goal",
    "result_keys",
    "safety_keys",
]

GOAL = "goal"
"""The kind of a node's goal rate (:func:`kind`); a safety rate's kind is :data:`SAFETY`."""


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


def safety_keys(tree: Node) -> list[str]:
    """The key ``path:name`` of every safety annotation in ``tree``, in tree order (parents first).

    These are the keys of ``info["safe"]`` and of the safety rates in a result.
    """
    return [annotation_key(p, a) for p, node in tree.walk() for a in node.annotations if a.role == SAFETY]


def result_keys(tree: Node) -> list[str]:
    """Every key a run's result measures: the node paths (tree order), then the safety keys."""
    return [p for p, _ in tree.walk()] + safety_keys(tree)


def is_safety_key(key: str) -> bool:
    """Whether a result key names a safety rate (``path:name``) rather than a node's goal (``path``)."""
    return ANNOTATION_SEPARATOR in key


def kind(key: str) -> str:
    """``"goal"`` (:data:`GOAL`) or ``"safety"`` (:data:`SAFETY`): what a result key measures."""
    return SAFETY if is_safety_key(key) else GOAL


def label(key: str) -> str:
    """A result key as tables and messages show it: a safety rate reads ``path:name (safe)``."""
    return f"{key} (safe)" if is_safety_key(key) else key


def resolve_goal(tree: Node, key: object, where: str) -> str:
    """The one goal-name resolver: the full key (node path or safety key) that ``key`` names in ``tree``.

    ``key`` is :data:`ROOT`, a full node path, a full safety key
    (``path:name`` of a ``Constraint``, ``Avoid`` or any annotation whose
    ``role`` is ``"safety"``), or the name of exactly one node or safety
    annotation. A full path or key wins over a name; node and annotation names
    share one namespace, so a name that both a node and a safety annotation
    carry is ambiguous. Nothing else is special, a node named "root" included.

    Raises:
        InvalidSpec: an unknown or ambiguous name, naming ``where`` and the
            tree's goals and safety rates.
    """
    paths = [p for p, _ in tree.walk()]
    safety = safety_keys(tree)
    if key is ROOT:
        return paths[0]
    if not isinstance(key, str):
        raise InvalidSpec(where, f"expected a node path or name as goal, got {key!r}")
    if key in paths or key in safety:
        return key
    named = [p for p in paths if p.rsplit("/", 1)[-1] == key]
    named += [k for k in safety if k.rsplit(ANNOTATION_SEPARATOR, 1)[-1] == key]
    if len(named) == 1:
        return named[0]
    if named:
        what = "keys" if any(is_safety_key(k) for k in named) else "paths"
        raise InvalidSpec(where, f"the name {key!r} is ambiguous; use one of the {what} {', '.join(named)}")
    known = f"the tree's goals are {', '.join(paths)}"
    if safety:
        known += f"; its safety rates are {', '.join(safety)}"
    other = [
        annotation_key(p, a)
        for p, node in tree.walk()
        for a in node.annotations
        if a.role != SAFETY and key in (annotation_key(p, a), a.name)
    ]
    if other:
        raise InvalidSpec(
            where,
            f"{key!r} names an annotation that is not a safety annotation ({', '.join(other)}); {known}",
            hint="thresholds apply to goals and to safety rates (Constraint, Avoid: role 'safety'), "
            "not to shaping annotations such as Distance",
        )
    kinds = "node or safety annotation" if safety else "node"
    raise InvalidSpec(
        where,
        f"no {kinds} is named {key!r}; {known}",
        hint="name a goal by its path or its unique name, a safety rate by its key path:name or the "
        "annotation's unique name; a single number asserts the root goal",
    )
