"""Algorithm 1 of the source paper, written plainly: the reference implementation.

``process(node)`` builds the goal ``G`` and requirements ``(S_G, A_G, T_G, R_G)``
of a node depth first, exactly as docs/semantics.md states them ("Reward", "The operator contract"), asking
every node and annotation only through the extension protocol
(:mod:`specguard.extend`). It is slow (closures calling closures) and meant to
be read: the fast evaluator in :mod:`specguard.construction.compiled` is tested against it
on random trees and states.

States here are *extended* states: the feature vector plus the own state of
every node and annotation that has one (a constraint's counter, a sequence's
stage), by key.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

from specguard.construction.evaluator import StepResult
from specguard.construction.initial_env import state_type
from specguard.error import EvaluationError
from specguard.extend import Annotation, Context, Node, Slot, annotation_key, component_weights, until_end
from specguard.utils.node_paths import child_path

__all__ = [
    "ExtendedState",
    "ReferenceEvaluator",
    "Requirements",
    "call_definition",
    "check_distance",
    "distance_value",
    "process",
]

FLOAT_MAX = sys.float_info.max
"""``0.0 <= d <= FLOAT_MAX`` holds exactly for the finite ``d >= 0`` (NaN fails every comparison)."""

OwnStates = Mapping[str, tuple[float, ...]]
Terms = dict[str, float]


class ExtendedState(NamedTuple):
    """A state of ``S_G``: the named features and the own states by key (node path or ``path:annotation``)."""

    s: Any  # the feature namedtuple of :func:`state_type`
    states: OwnStates


@dataclass(frozen=True)
class Requirements:
    """The output of ``process(node)``: the goal and ``(S_G, T_G, R_G)`` (``A_G`` is unchanged by every node).

    Attributes:
        goal: membership of an extended state in ``G``.
        reward: the weighted reward terms of a step, by key.
        terminal: whether an extended state is in ``T_G``.
        initial: the own states of the subtree at the start of an episode in features ``s``.
        transition: the own states after the step ``(x, a, s', fell)`` (the automaton of ``S_G``); ``fell``: the
            initial env terminated the episode in ``s'`` where the root goal holds until the end
            (:meth:`Node.terminated_state`).
        slots: ``S_G`` beyond the features: ``(key, slot)`` in Algorithm 1's processing order.
        roles: the role of each reward term (``"core"``, ``"shaping"``, ``"safety"``), by key.
        goals: every node's goal, by path (``info["goals"]``).
        violations: the safety annotations' violation counts, by key.
        last: the judgement of the state ``x`` an episode ended in, reached by action ``a``
            (docs/semantics.md, "The last state"): the own states it changes, and their weighted reward terms.
    """

    goal: Callable[[ExtendedState], bool]
    reward: Callable[[ExtendedState, Any, ExtendedState], Terms]
    terminal: Callable[[ExtendedState], bool]
    initial: Callable[[Any], dict[str, tuple[float, ...]]]
    transition: Callable[[ExtendedState, Any, Any, bool], dict[str, tuple[float, ...]]]
    slots: tuple[tuple[str, Slot], ...]
    roles: Mapping[str, str]
    goals: Mapping[str, Callable[[ExtendedState], bool]]
    violations: Mapping[str, Callable[[ExtendedState], int]]
    last: Callable[[ExtendedState, Any], tuple[dict[str, tuple[float, ...]], Terms]]


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


def call_definition(key: str, what: str, fn: Callable[..., Any], *args: Any) -> Any:
    """Call one protocol method; an exception becomes an :class:`EvaluationError` naming the node or annotation."""
    try:
        return fn(*args)
    except EvaluationError as e:  # a definition's own diagnosis: prefix the key once
        if str(e).startswith(f"{key}: "):
            raise
        raise EvaluationError(f"{key}: {e.message}", e.hint) from e
    except Exception as e:
        raise EvaluationError(f"{key}: {what} raised {type(e).__name__}: {e}") from e


def _operator(path: str, node: Node, kids: Sequence[Requirements]) -> Requirements:
    """Step 1 of Algorithm 1 for any node: combine the children's requirements through the protocol."""
    weights = node.child_weights()

    def inside(x: ExtendedState) -> tuple[bool, ...]:
        return tuple(k.goal(x) for k in kids)

    def ctx(x: ExtendedState) -> Context:
        return Context(x.s, x.states.get(path, ()), inside(x))

    def goal(x: ExtendedState) -> bool:
        return bool(call_definition(path, "contains()", node.contains, ctx(x)))

    def reward(x: ExtendedState, a: Any, x2: ExtendedState) -> Terms:
        out: Terms = {}
        for w, k in zip(weights, kids):  # each child's components, weighted by their role
            out.update({key: w.of(k.roles[key]) * v for key, v in k.reward(x, a, x2).items()})
        if node.own_reward:
            out[path] = float(call_definition(path, "reward()", node.reward, ctx(x), a, ctx(x2)))
        return out

    def terminal(x: ExtendedState) -> bool:  # T = union of T_i, plus the node's own
        ended = tuple(k.terminal(x) for k in kids)
        return bool(call_definition(path, "terminates()", node.terminates, ctx(x), ended))

    def initial(s: Any) -> dict[str, tuple[float, ...]]:
        states: dict[str, tuple[float, ...]] = {}
        for k in kids:
            states.update(k.initial(s))
        if node.state_slots():
            x = ExtendedState(s, states)
            q0 = call_definition(path, "initial_state()", node.initial_state, Context(s, (), inside(x)))
            states[path] = tuple(float(v) for v in q0)
        return states

    def transition(x: ExtendedState, a: Any, s2: Any, fell: bool) -> dict[str, tuple[float, ...]]:
        states: dict[str, tuple[float, ...]] = {}
        for k in kids:
            states.update(k.transition(x, a, s2, fell))
        if node.state_slots():
            inside2 = inside(ExtendedState(s2, states))
            q2 = tuple(float(v) for v in call_definition(path, "next_state()", node.next_state, ctx(x), a, s2, inside2))
            if fell:  # the initial env ended the episode before its horizon (docs/semantics.md)
                after = Context(s2, q2, inside2)
                q2 = tuple(float(v) for v in call_definition(path, "terminated_state()", node.terminated_state, after))
            states[path] = q2
        return states

    def last(x: ExtendedState, a: Any) -> tuple[dict[str, tuple[float, ...]], Terms]:
        states: dict[str, tuple[float, ...]] = {}
        out: Terms = {}
        for w, k in zip(weights, kids):  # weighted by role, as the children's rewards are
            changed, terms = k.last(x, a)
            states.update(changed)
            out.update({key: w.of(k.roles[key]) * v for key, v in terms.items()})
        return states, out

    slots = tuple(e for k in kids for e in k.slots) + tuple((path, slot) for slot in node.state_slots())
    roles = {key: role for k in kids for key, role in k.roles.items()}
    if node.own_reward:
        roles[path] = "core"
    goals: dict[str, Callable[[ExtendedState], bool]] = {path: goal}
    violations: dict[str, Callable[[ExtendedState], int]] = {}
    for k in kids:
        goals.update(k.goals)
        violations.update(k.violations)
    return Requirements(goal, reward, terminal, initial, transition, slots, roles, goals, violations, last)


def _annotation(key: str, w: float, a: Annotation, req: Requirements) -> Requirements:
    """Step 2 of Algorithm 1: one annotation updates the node's requirements."""
    has_state = bool(a.state_slots())

    def q(x: ExtendedState) -> tuple[float, ...]:
        return x.states.get(key, ())

    def reward(x: ExtendedState, act: Any, x2: ExtendedState) -> Terms:
        out = req.reward(x, act, x2)
        out[key] = w * float(call_definition(key, "reward()", a.reward, x.s, q(x), act, x2.s, q(x2)))
        return out

    def terminal(x: ExtendedState) -> bool:
        return req.terminal(x) or bool(call_definition(key, "terminates()", a.terminates, q(x)))

    def initial(s: Any) -> dict[str, tuple[float, ...]]:
        states = req.initial(s)
        if has_state:
            states[key] = tuple(float(v) for v in call_definition(key, "initial_state()", a.initial_state, s))
        return states

    def transition(x: ExtendedState, act: Any, s2: Any, fell: bool) -> dict[str, tuple[float, ...]]:
        states = req.transition(x, act, s2, fell)
        if has_state:
            states[key] = tuple(
                float(v) for v in call_definition(key, "next_state()", a.next_state, x.s, q(x), act, s2)
            )
        return states

    def last(x: ExtendedState, act: Any) -> tuple[dict[str, tuple[float, ...]], Terms]:
        states, out = req.last(x, act)
        if has_state:
            q0 = q(x)
            q2 = tuple(float(v) for v in call_definition(key, "last_state()", a.last_state, x.s, q0, act))
            if q2 != q0:  # judged: the change is paid as a step from s to s
                states[key] = q2
                out[key] = w * float(call_definition(key, "reward()", a.reward, x.s, q0, act, x.s, q2))
        return states, out

    slots = req.slots + tuple((key, slot) for slot in a.state_slots())
    roles = {**req.roles, key: a.role}
    violations = dict(req.violations)
    if a.role == "safety":
        violations[key] = lambda x: int(a.violations(q(x)))
    return Requirements(req.goal, reward, terminal, initial, transition, slots, roles, req.goals, violations, last)


def process(node: Node, path: str | None = None, *, root: bool = True) -> Requirements:
    """Algorithm 1: the requirements of ``node``, children first, then annotations, then root specifics."""
    path = node.name if path is None else path
    # Step 1: leaf or operator (a leaf is an operator without children).
    kids = [process(c, child_path(path, c.name), root=False) for c in node.children]
    req = _operator(path, node, kids)
    # Step 2: annotations, in order. The core keeps its default weight; each
    # annotation brings its own (docs/semantics.md, "Weights inside a node").
    core_w, ann_w = component_weights(node)
    core = req
    req = Requirements(
        core.goal,
        lambda x, a, x2: {k: core_w * v for k, v in core.reward(x, a, x2).items()},
        core.terminal,
        core.initial,
        core.transition,
        core.slots,
        core.roles,
        core.goals,
        core.violations,
        lambda x, a: _weighted(core.last(x, a), core_w),
    )
    for a, w in zip(node.annotations, ann_w):
        req = _annotation(annotation_key(path, a), w, a, req)
    # Step 3: the root goal ends the episode, for all actions (unless it holds until the end).
    if root and not until_end(node):
        inner, goal = req.terminal, req.goal
        req = Requirements(
            req.goal,
            req.reward,
            lambda x: inner(x) or goal(x),
            req.initial,
            req.transition,
            req.slots,
            req.roles,
            req.goals,
            req.violations,
            req.last,
        )
    return req


def _weighted(last: tuple[dict[str, tuple[float, ...]], Terms], w: float) -> tuple[dict[str, tuple[float, ...]], Terms]:
    states, terms = last
    return states, {k: w * v for k, v in terms.items()}


class ReferenceEvaluator:
    """Steps the requirements of :func:`process` along a trajectory of feature vectors.

    An :class:`~specguard.construction.evaluator.Evaluator`, as the flat one
    (:class:`specguard.construction.compiled.FlatEvaluator`) is, so the constructed
    env can run either (``make_env(..., evaluator="reference")``).
    """

    def __init__(self, tree: Node, features: Sequence[str]) -> None:
        self.req = process(tree)
        self.horizon = until_end(tree)
        """The root goal holds until the end: an episode the initial env terminates ended before its horizon."""
        self.state_cls = state_type(tuple(features))
        self.paths = tuple(self.req.goals)
        self.slots = self.req.slots
        self.safety_keys = tuple(self.req.violations)
        self._x: ExtendedState | None = None
        self.goals: dict[str, bool] = {}
        """Every node's membership of the last state, by path."""

    def _members(self, x: ExtendedState) -> tuple[bool, ...]:
        """Every node's membership of ``x`` (the state just reached), also kept by path in :attr:`goals`."""
        members = tuple(g(x) for g in self.req.goals.values())
        self.goals = dict(zip(self.paths, members))
        return members

    def reset(self, f: Sequence[float]) -> tuple[bool, ...]:
        s = self.state_cls._make(f)
        self._x = ExtendedState(s, self.req.initial(s))
        return self._members(self._x)

    def restore(self, f: Sequence[float], own: Sequence[float]) -> tuple[bool, ...]:
        """Start from features ``f`` and the own-state slots ``own`` (an observation's tail)."""
        states: dict[str, list[float]] = {}
        for (key, _), v in zip(self.slots, own, strict=True):
            states.setdefault(key, []).append(float(v))
        self._x = ExtendedState(self.state_cls._make(f), {k: tuple(v) for k, v in states.items()})
        return self._members(self._x)

    @property
    def state(self) -> Any:
        """The features of the last state reset or stepped to (``s.x`` by name); None before a reset."""
        return None if self._x is None else self._x.s

    @property
    def own_state(self) -> list[float]:
        """The own-state slots in observation order (zeros before a reset, as the flat evaluator's)."""
        if self._x is None:
            return [0.0] * len(self.slots)
        out: list[float] = []
        done: set[str] = set()
        for key, _ in self.slots:
            if key not in done:
                out.extend(self._x.states[key])
                done.add(key)
        return out

    @property
    def safe(self) -> tuple[bool, ...]:
        """Per safety annotation, whether the episode has had no violation so far (none before a reset)."""
        x = self._x
        if x is None:
            return (True,) * len(self.safety_keys)
        return tuple(v(x) == 0 for v in self.req.violations.values())

    def safe_info(self) -> dict[str, bool]:
        """:attr:`safe` by safety key."""
        return dict(zip(self.safety_keys, self.safe))

    def step(self, action: Any, f: Sequence[float], last: bool | None = False, terminated: bool = False) -> StepResult:
        """Advance by one transition to features ``f``: reward, spec termination, goals, weighted terms.

        When the episode ends at ``f`` (the spec ends it, or ``last``: the base env terminated or truncated),
        the last state is judged too (docs/semantics.md, "The last state"), in this step's terms; with
        ``last`` None never (the transition's own reward, as :meth:`CompiledTree.reward_terms` gives it).
        ``terminated``: the base env terminated the episode at ``f``; where the root goal holds until the
        end, the episode ended before its horizon (:meth:`~specguard.extend.Node.terminated_state`).
        """
        x = self._x
        assert x is not None, "reset() first"
        s2 = self.state_cls._make(f)
        x2 = ExtendedState(s2, self.req.transition(x, action, s2, bool(terminated) and self.horizon))
        terms = self.req.reward(x, action, x2)
        ended = self.req.terminal(x2)
        if last or (ended and last is not None):
            changed, extra = self.req.last(x2, action)
            if changed:
                x2 = ExtendedState(s2, {**x2.states, **changed})
                for key, v in extra.items():
                    terms[key] += v
                ended = self.req.terminal(x2)
        self._x = x2
        return StepResult(float(sum(terms.values())), ended, self._members(x2), terms)
