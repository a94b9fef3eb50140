"""Naming goals and safety rates, and their thresholds: the one resolver and the one threshold rule.

A result measures, per evaluation episode, two kinds of *rates* under one
mapping of keys (``RunResult.successes``):

* a **goal** per node, keyed by its path (``lunar/legs``): the episodes whose
  last state lies in the node's goal;
* a **safety rate** per safety annotation (``role == "safety"``: ``Constraint``,
  ``Avoid``), keyed ``path:name`` (``lunar:crash``): the episodes without a
  violation.

Names cannot contain ``/`` or ``:``, so the two kinds of keys never collide
(:func:`is_safety_key`). ``Spec(expect=..., xfail=...)``,
``@sg.goal_spec(expect=..., xfail=...)``, the CLI and stored baselines all go
through :func:`check_expect`, :func:`check_xfail`, :func:`resolve_goal` and
:func:`check_threshold`, so ``expect`` and ``xfail`` take the same forms, a
name means the same goal or safety rate, and a threshold the same range,
everywhere. Imports nothing heavy: the pytest plugin uses it at collection.

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
    >>> check_expect("Spec 'p'", 0.8), check_xfail("Spec 'p'", ["up"])
    ({root: 0.8}, {'up': 'expected to miss its threshold'})
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from numbers import Real
from typing import TYPE_CHECKING, Any

from specguard.error import InvalidSpec
from specguard.extend import SAFETY, annotation_key
from specguard.utils.node_paths import ANNOTATION_SEPARATOR, PATH_SEPARATOR

if TYPE_CHECKING:
    from specguard.extend import Node

__all__ = [
    "GOAL",
    "ROOT",
    "SAFETY",
    "XFAIL_REASON",
    "check_expect",
    "check_threshold",
    "check_xfail",
    "check_xfail_thresholded",
    "is_safety_key",
    "kind",
    "label",
    "require_thresholds",
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


XFAIL_REASON = "expected to miss its threshold"
"""The reason of a goal that ``xfail`` lists without one."""


def _check_goal_key(where: str, argument: str, goal: object) -> None:
    if goal is not ROOT and not isinstance(goal, str):
        raise InvalidSpec(where, f"expected goal names or paths as keys of {argument}, got {goal!r}")


def check_expect(where: str, expect: object) -> dict[Any, float]:
    """The one reading of ``expect``: ``{goal: threshold}`` from a mapping, or from one number (the :data:`ROOT` goal).

    Keys stay as given (names, paths, safety keys): whoever has the tree
    resolves them (:func:`resolve_goal`); values follow :func:`check_threshold`.
    An empty mapping gives no thresholds and is allowed here: a ``Spec`` may
    get its thresholds elsewhere (``@goal_spec(expect=...)``) or only measure
    (``specguard run`` prints its table); where thresholds are asserted,
    :func:`require_thresholds` asks for at least one.

    Raises:
        InvalidSpec: naming ``where`` (``Spec 'p'``, ``goal_spec 'test_x'``), the argument and the value.
    """
    if isinstance(expect, Real) and not isinstance(expect, bool):
        expect = {ROOT: expect}
    if not isinstance(expect, Mapping):
        raise InvalidSpec(where, f"expected expect to be {{goal: min success}} or a number, got {expect!r}")
    thresholds: dict[Any, float] = {}
    for goal, value in expect.items():
        _check_goal_key(where, "expect", goal)
        thresholds[goal] = check_threshold(f"{where}.expect[{goal!r}]", value)
    return thresholds


def check_xfail(where: str, xfail: object) -> dict[Any, str]:
    """The one reading of ``xfail``: ``{goal: reason}`` from a mapping, or from a list of goals (:data:`XFAIL_REASON`).

    ``None`` lists none. Keys stay as given, as for :func:`check_expect`;
    :func:`check_xfail_thresholded` then says they must have thresholds.

    Raises:
        InvalidSpec: a goal that is not a name or path, or a reason that is not non-empty text.
    """
    if xfail is None:
        return {}
    if isinstance(xfail, Sequence) and not isinstance(xfail, str):
        for goal in xfail:
            _check_goal_key(where, "xfail", goal)
        xfail = dict.fromkeys(xfail, XFAIL_REASON)
    if not isinstance(xfail, Mapping):
        raise InvalidSpec(where, f"expected xfail to be {{goal: reason}} or a list of goals, got {xfail!r}")
    reasons: dict[Any, str] = {}
    for goal, reason in xfail.items():
        _check_goal_key(where, "xfail", goal)
        if not isinstance(reason, str) or not reason.strip():
            raise InvalidSpec(f"{where}.xfail[{goal!r}]", f"expected the reason as non-empty text, got {reason!r}")
        reasons[goal] = str.__str__(reason)
    return reasons


def check_xfail_thresholded(where: str, reasons: Mapping[Any, str], thresholds: Mapping[Any, float]) -> None:
    """Every goal ``xfail`` lists has a threshold in ``expect``: a goal without one cannot miss it.

    Both mappings key their goals alike (both as given, or both resolved by :func:`resolve_goal`).
    """
    unknown = [goal for goal in reasons if goal not in thresholds]
    if unknown:
        raise InvalidSpec(
            where, f"expected xfail to name goals that expect gives a threshold to ({list(thresholds)}), got {unknown}"
        )


def require_thresholds(where: str, thresholds: Mapping[Any, float]) -> None:
    """There is at least one threshold: what is asserted must have something to assert.

    A ``Spec`` alone may have none (:func:`check_expect`); a goal spec, the
    decorator's own ``expect`` and the items of ``sg.goal_specs`` may not.
    """
    if not thresholds:
        raise InvalidSpec(
            where,
            f"expected at least one threshold, got {dict(thresholds)!r}: there is nothing to assert",
            hint="give expect= to the Spec or to @goal_spec (@goal_spec without expect asserts the Spec's own)",
        )


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
    named = [p for p in paths if p.rsplit(PATH_SEPARATOR, 1)[-1] == key]
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
