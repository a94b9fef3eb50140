"""Algorithm 1 of the source paper, written plainly: the reference implementation.

``process(node)`` builds the goal ``G`` and requirements ``(S_G, A_G, T_G, R_G)``
of a node depth first, exactly as SPEC.md section 2 states them. It is slow
(closures calling closures) and meant to be read: the fast evaluator in
:mod:`specguard.compiled` is tested against it on random trees and states.

States here are *extended* states: the feature vector plus the constraint
counters that constraint annotations add to ``S_G``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

from specguard.error import EvaluationError
from specguard.initial_env import state_type
from specguard.nodes import ANNOTATION_SEPARATOR, All, Constraint, Distance, Goal, Node, component_weights

__all__ = ["ExtendedState", "ReferenceEvaluator", "Requirements", "check_distance", "distance_value", "process"]

FLOAT_MAX = sys.float_info.max
"""``0.0 <= d <= FLOAT_MAX`` holds exactly for the finite ``d >= 0`` (NaN fails every comparison)."""


class ExtendedState(NamedTuple):
    """A state of ``S_G``: the named features and the constraint counters by key."""

    s: Any  # the feature namedtuple of :func:`state_type`
    counters: Mapping[str, int]


Terms = dict[str, float]


@dataclass(frozen=True)
class Requirements:
    """The output of ``process(node)``: the goal and ``(S_G, T_G, R_G)`` (``A_G`` is unchanged by every node)."""

    goal: Callable[[Any], bool]
    reward: Callable[[ExtendedState, Any, ExtendedState], Terms]
    terminal: Callable[[ExtendedState], bool]
    # S_G beyond the features: (key, budget, violation fn) per constraint counter.
    counters: tuple[tuple[str, int, Callable[[Any, Any], bool]], ...]
    goals: Mapping[str, Callable[[Any], bool]]  # every node's goal, by path, for info["goals"]


def _scaled(terms: Terms, w: float) -> Terms:
    return {k: w * v for k, v in terms.items()}


def _leaf(path: str, goal: Goal) -> Requirements:
    bounds = goal.bounds

    def g(s: Any) -> bool:
        return all(lo <= getattr(s, f) <= hi for f, lo, hi in bounds)

    def reward(s: ExtendedState, a: Any, s2: ExtendedState) -> Terms:
        before, after = g(s.s), g(s2.s)
        r = 1.0 if (not before and after) else -1.0 if (before and not after) else 0.0
        return {path: r}

    return Requirements(g, reward, lambda s: False, (), {path: g})


def _and(path: str, node: All, children: Sequence[Requirements]) -> Requirements:
    weights = node.child_weights()

    def g(s: Any) -> bool:
        return all(c.goal(s) for c in children)  # G = intersection of G_i

    def reward(s: ExtendedState, a: Any, s2: ExtendedState) -> Terms:
        out: Terms = {}
        for w, c in zip(weights, children):  # R = sum_i w_i R_i
            out.update(_scaled(c.reward(s, a, s2), w))
        return out

    def terminal(s: ExtendedState) -> bool:
        return any(c.terminal(s) for c in children)  # T = union of T_i

    goals: dict[str, Callable[[Any], bool]] = {path: g}
    for c in children:
        goals.update(c.goals)
    return Requirements(g, reward, terminal, tuple(x for c in children for x in c.counters), goals)


def distance_value(key: str, fn: Callable[[Any], Any], s: Any) -> float:
    """``fn(s)`` as a float, which must be finite and ``>= 0``; errors name the annotation ``key``.

    Raises:
        EvaluationError: ``fn`` raised, or returned a negative, infinite or NaN distance.
    """
    try:
        d = float(fn(s))
    except Exception as e:
        raise EvaluationError(f"{key}: the distance function raised {type(e).__name__}: {e} (state {s})") from e
    return check_distance(key, d, s)


def check_distance(key: str, d: float, s: Any) -> float:
    """``d`` if it is a finite float ``>= 0``; else an :class:`EvaluationError` naming ``key``, ``d`` and ``s``."""
    if not 0.0 <= d <= FLOAT_MAX:  # NaN fails it too
        raise EvaluationError(f"{key}: expected a finite distance >= 0, got {d!r} (state {s})")
    return d


def _distance(key: str, w: float, d: Distance, req: Requirements) -> Requirements:
    def reward(s: ExtendedState, a: Any, s2: ExtendedState) -> Terms:
        out = req.reward(s, a, s2)
        # (fn(s) - fn(s')) / d
        out[key] = w * (distance_value(key, d.fn, s.s) - distance_value(key, d.fn, s2.s)) / d.scale
        return out

    return Requirements(req.goal, reward, req.terminal, req.counters, req.goals)


def _constraint(key: str, w: float, c: Constraint, req: Requirements) -> Requirements:
    def reward(s: ExtendedState, a: Any, s2: ExtendedState) -> Terms:
        out = req.reward(s, a, s2)
        out[key] = w * (-1.0 if c.fn(s.s, a) else 0.0)  # R_pen = -1 if (s, a) in C
        return out

    def terminal(s: ExtendedState) -> bool:
        return req.terminal(s) or s.counters[key] == 0  # T <- T u {s_C = 0}

    assert isinstance(c.budget, int)
    counters = (*req.counters, (key, c.budget, c.fn))  # S_G <- S_G x N
    return Requirements(req.goal, reward, terminal, counters, req.goals)


def process(node: Node, path: str | None = None, *, root: bool = True) -> Requirements:
    """Algorithm 1: the requirements of ``node``, children first, then annotations, then root specifics."""
    path = node.name if path is None else path
    # Step 1: leaf or operator.
    if isinstance(node, Goal):
        req = _leaf(path, node)
    elif isinstance(node, All):
        kids = [process(c, f"{path}/{c.name}", root=False) for c in node.children]
        req = _and(path, node, kids)
    else:
        raise TypeError(f"the reference construction has no definition for {type(node).__name__} nodes")
    # Step 2: annotations, in order. The core keeps its default weight; each
    # annotation brings its own (SPEC.md "Reward components and weights").
    core_w, ann_w = component_weights(node)
    core = req
    req = Requirements(
        core.goal, lambda s, a, s2: _scaled(core.reward(s, a, s2), core_w), core.terminal, core.counters, core.goals
    )
    for a, w in zip(node.annotations, ann_w):
        key = f"{path}{ANNOTATION_SEPARATOR}{a.name}"
        if isinstance(a, Distance):
            req = _distance(key, w, a, req)
        elif isinstance(a, Constraint):
            req = _constraint(key, w, a, req)
        else:
            raise TypeError(f"the reference construction has no definition for {type(a).__name__} annotations")
    # Step 3: the root goal ends the episode, for all actions.
    if root:
        inner, goal = req.terminal, req.goal
        req = Requirements(req.goal, req.reward, lambda s: inner(s) or goal(s.s), req.counters, req.goals)
    return req


class ReferenceEvaluator:
    """Steps the requirements of :func:`process` along a trajectory of feature vectors.

    Same interface as :class:`specguard.compiled.Evaluator`, so the constructed
    env can run either (``make_env(..., evaluator="reference")``).
    """

    def __init__(self, tree: Node, features: Sequence[str]) -> None:
        self.req = process(tree)
        self.state_cls = state_type(tuple(features))
        self.paths = tuple(self.req.goals)
        self.counter_keys = tuple(k for k, _, _ in self.req.counters)
        self.budgets = tuple(b for _, b, _ in self.req.counters)
        self._s: ExtendedState | None = None

    def reset(self, f: Sequence[float]) -> tuple[bool, ...]:
        s = self.state_cls._make(f)
        self._s = ExtendedState(s, {k: b for k, b, _ in self.req.counters})
        return tuple(g(s) for g in self.req.goals.values())

    @property
    def counters(self) -> list[int]:
        assert self._s is not None
        return list(self._s.counters.values())

    def step(self, action: Any, f: Sequence[float]) -> tuple[float, bool, tuple[bool, ...], Terms]:
        """Advance by one transition to features ``f``: reward, spec termination, goals, weighted terms."""
        s = self._s
        assert s is not None, "reset() first"
        s2 = self.state_cls._make(f)
        # The constraint automaton: s_C' = s_C - cnt_C(s, a).
        counters = {k: s.counters[k] - (1 if fn(s.s, action) else 0) for k, _, fn in self.req.counters}
        ext2 = ExtendedState(s2, counters)
        terms = self.req.reward(s, action, ext2)
        self._s = ext2
        goals = tuple(g(s2) for g in self.req.goals.values())
        return sum(terms.values()), self.req.terminal(ext2), goals, terms
