"""The goal tree compiled once into a flat evaluator.

Algorithm 1 (see :mod:`specguard.construction.reference`) nests closures; evaluated per
step it made Pendulum training 1.7-2x slower than on the raw env. Every
reward component is linear in the tree's atomic terms, so the root reward is
a plain weighted sum: one term per node that pays its own core reward, one
per annotation, each with a constant coefficient (the product of the weights
on its path for the term's role, see :class:`specguard.extend.ChildWeights`).

Two kinds of node and annotation are compiled differently:

* the **fast** ones declare a closed form the evaluator understands: a node
  without own state whose goal is a box (:meth:`Node.box`) and whose core
  reward is the default membership difference (a leaf) or absent (``All``);
  an annotation with a :class:`~specguard.extend.ShapingForm` (``Distance``)
  or :class:`~specguard.extend.CounterForm` (``Constraint``, ``Avoid``).
  Their goals are two arrays ``lo``/``hi`` of shape ``(nodes, features)``,
  tested in one vectorised comparison for batches (:meth:`CompiledTree.members`);
* every other one is **general**: evaluated from its definition, by calling
  its protocol methods (:mod:`specguard.extend`), unless it declares a
  :class:`~specguard.extend.StagesForm` (``Sequence``), whose stage counter and
  potential the generated code writes out.

For the single state of an env step, numpy's per-call overhead would exceed
the whole budget of a Pendulum step, so each tree is also turned into small
generated Python functions (:attr:`CompiledTree.source`, see
:mod:`specguard.construction.codegen`), as dataclasses generate ``__init__``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from types import CodeType
from typing import Any, NoReturn

import numpy as np

from specguard.construction.codegen import build_namespace, source_of
from specguard.construction.evaluator import StepResult
from specguard.construction.initial_env import state_type
from specguard.construction.reference import FLOAT_MAX, check_distance, distance_value
from specguard.error import EvaluationError, InvalidSpec, UnknownFeature
from specguard.extend import (
    Annotation,
    Box,
    ChildWeights,
    CounterForm,
    Node,
    ShapingForm,
    Slot,
    StagesForm,
    adapted_annotations,
    annotation_key,
    component_weights,
    until_end,
)
from specguard.utils.node_paths import child_path
from specguard.validation import check_truth

__all__ = ["CompiledTree", "FlatEvaluator", "compile_tree"]

_isfinite = math.isfinite
_result = tuple.__new__  # a StepResult from a tuple, without NamedTuple.__new__'s argument handling


@dataclass(frozen=True)
class _Term:
    key: str  # "path" for a node's own core term, "path:name" for an annotation
    kind: str  # "member" | "node" | "distance" | "counter" | "annotation" | "zero" (a shaping weighted 0)
    coef: float  # product of the weights on the path for its role, times its own weight (and 1/scale)
    node: int = -1  # member/node: index of its node in ``paths``
    fn: Callable[..., Any] | None = None  # distance/counter: the user's function
    budget: int = 0  # counter: its start
    on_next_state: bool = False  # counter: judged on s' rather than (s, a)
    slot: int = -1  # counter/annotation/node: first own-state slot
    annotation: Annotation | None = None  # general annotation, or any safety one
    owner: int = -1  # annotation: index of the node it annotates


@dataclass(frozen=True)
class CompiledTree:
    """The flat form of a goal tree over a fixed feature tuple.

    Attributes:
        features: the feature names, the columns of ``lo`` and ``hi``.
        paths: every node's path, parents before children (root first).
        nodes: the node at each path.
        lo, hi: ``(len(paths), len(features))`` inclusive boxes, ``+-inf`` where
            open; a node whose goal is not a box is unbounded here.
        boxed: per node, whether its goal is a box (``lo``/``hi`` say it exactly).
        fast: per node, whether it compiles to box tests (see the module docstring).
        terms: the reward components in Algorithm 1's processing order
            (a node's subtree, then the node's own term, then its annotations).
        children: per node, the indices of its children in ``paths``.
        slots: the own-state slots (node or annotation key, slot), in observation order.
        slot_start: per node, the index of its first own-state slot (``-1``: none).
        stages: per node, its :class:`~specguard.extend.StagesForm` when it declares one (a general node
            compiled to straight-line code, ``Sequence``), else ``None``.
        weights: the adapted weights it was compiled with (``compile_tree(weights=...)``),
            by path; empty for the tree's own.
    """

    features: tuple[str, ...]
    paths: tuple[str, ...]
    nodes: tuple[Node, ...]
    lo: np.ndarray
    hi: np.ndarray
    boxed: tuple[bool, ...]
    fast: tuple[bool, ...]
    terms: tuple[_Term, ...]
    children: tuple[tuple[int, ...], ...]
    slots: tuple[tuple[str, Slot], ...]
    slot_start: tuple[int, ...]
    stages: tuple[StagesForm | None, ...]
    weights: tuple[tuple[str, tuple[float, ...]], ...] = ()

    def __getstate__(self) -> dict[str, Any]:
        # The generated code is made again after unpickling: the standard pickle cannot pickle code objects.
        return {k: v for k, v in self.__dict__.items() if k != "code"}

    @property
    def term_keys(self) -> tuple[str, ...]:
        return tuple(t.key for t in self.terms)

    @property
    def distances(self) -> tuple[_Term, ...]:
        return tuple(t for t in self.terms if t.kind == "distance")

    @property
    def counters(self) -> tuple[_Term, ...]:
        return tuple(t for t in self.terms if t.kind == "counter")

    @property
    def safety(self) -> tuple[_Term, ...]:
        """The terms of safety annotations (constraint-like), whose keys get a safety rate."""
        return tuple(t for t in self.terms if t.annotation is not None and t.annotation.role == "safety")

    @property
    def safety_keys(self) -> tuple[str, ...]:
        return tuple(t.key for t in self.safety)

    @property
    def all_fast(self) -> bool:
        """Whether every node and annotation compiled to a closed form (no own state beyond counters)."""
        return all(self.fast) and all(t.kind in ("member", "distance", "counter", "zero") for t in self.terms)

    @property
    def reach(self) -> bool:
        """Whether reaching the root goal ends the episode (a reach goal), rather than holding until the end.

        docs/semantics.md, "Goals that hold until the end" (:func:`specguard.extend.until_end`).
        """
        return not until_end(self.nodes[0])

    @property
    def stateful(self) -> bool:
        """Whether some node has own state (so membership depends on more than one state)."""
        return any(i >= 0 for i in self.slot_start)

    # -- batch evaluation (numpy) ------------------------------------------

    def members(self, states: np.ndarray) -> np.ndarray:
        """``(B, nodes)`` membership of every state (rows of features, or of observations) in every goal.

        For a node with own state, membership is that at the start of an episode in the state.
        """
        s = np.asarray(states, dtype=np.float64)[:, : len(self.features)]
        if all(self.fast):
            return np.asarray(((s[:, None, :] >= self.lo) & (s[:, None, :] <= self.hi)).all(axis=2))
        ev = self.evaluator()
        return np.array([ev.reset(row) for row in s.tolist()], dtype=bool).reshape(len(s), len(self.paths))

    def reward_terms(self, states: np.ndarray, actions: Any, next_states: np.ndarray) -> np.ndarray:
        """``(B, terms)`` weighted reward components of the transitions ``(s, a, s')``.

        ``states`` are rows of features, or of observations (features, then own
        state) where the tree has own state that rewards depend on. Counters
        are per episode: the penalty of a step depends on ``(s, a)`` (or ``s'``) only.
        """
        s = np.asarray(states, dtype=np.float64)
        s2 = np.asarray(next_states, dtype=np.float64)[:, : len(self.features)]
        if not self.all_fast:
            return self._rows(s, actions, s2)
        s = s[:, : len(self.features)]
        m, m2 = self.members(s), self.members(s2)
        out = np.empty((len(s), len(self.terms)))
        for j, t in enumerate(self.terms):
            if t.kind == "zero":
                out[:, j] = 0.0
            elif t.kind == "member":
                out[:, j] = t.coef * (m2[:, t.node].astype(np.float64) - m[:, t.node])
            elif t.kind == "distance":
                out[:, j] = t.coef * (self._apply(t, s) - self._apply(t, s2))
            elif t.on_next_state:
                out[:, j] = -t.coef * self._apply(t, s2)
            else:
                out[:, j] = -t.coef * self._apply(t, s, actions)
        return out

    def rewards(self, states: np.ndarray, actions: Any, next_states: np.ndarray) -> np.ndarray:
        """``(B,)`` rewards of the transitions: the sum of :meth:`reward_terms`."""
        return np.asarray(self.reward_terms(states, actions, next_states).sum(axis=1))

    def step_batch(
        self,
        observations: np.ndarray,
        actions: Any,
        next_states: np.ndarray,
        last: Sequence[bool] | None = None,
        terminated: Sequence[bool] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Each transition evaluated alone, from its observation: what a Markov env must reproduce.

        Args:
            observations: ``(B, features + slots)`` observations of the constructed env.
            actions: ``B`` actions.
            next_states: ``(B, features...)`` the next states' features (extra columns ignored).
            last: ``B`` flags: the base env ended the episode in the next state, which is judged
                (:meth:`FlatEvaluator.step`); ``None``: no base env ended one.
            terminated: ``B`` flags: the base env's end was a termination (``FlatEvaluator.step``'s
                ``terminated``); ``None``: none was.

        Returns:
            ``(rewards, terminated, goals, next_own)``: the rewards ``(B,)``, the
            spec's termination ``(B,)``, every node's membership of ``s'``
            ``(B, nodes)`` and the next own state ``(B, slots)``.
        """
        obs = np.asarray(observations, dtype=np.float64)
        s2 = np.asarray(next_states, dtype=np.float64)[:, : len(self.features)]
        n = len(self.features)
        rewards, ended, goals, own = [], [], [], []
        ev = self.evaluator()
        ends = [False] * len(obs) if last is None else [bool(v) for v in last]
        falls = [False] * len(obs) if terminated is None else [bool(v) for v in terminated]
        for row, a, f2, base_end, fell in zip(obs.tolist(), list(actions), s2.tolist(), ends, falls, strict=True):
            ev.restore(row[:n], row[n:])
            result = ev.step(a, f2, base_end, fell)
            rewards.append(result.reward)
            ended.append(result.terminated)
            goals.append(result.goals)
            own.append(list(ev.own_state))
        shape = (len(obs), len(self.slots))
        return np.asarray(rewards), np.asarray(ended), np.asarray(goals, dtype=bool), np.asarray(own).reshape(shape)

    def _rows(self, s: np.ndarray, actions: Any, s2: np.ndarray) -> np.ndarray:
        n = len(self.features)
        if self.slots and s.shape[1] < n + len(self.slots):
            if self.stateful:
                raise ValueError(
                    f"the tree has own state ({', '.join(k for k, _ in self.slots)}): pass observations "
                    f"(features, then {len(self.slots)} own-state slots) as states"
                )
            ev = self.evaluator()  # annotations' own state as at the start of an episode in s
            own = []
            for row in s[:, :n].tolist():
                ev.reset(row)
                own.append(list(ev.own_state))
            s = np.concatenate([s[:, :n], np.asarray(own).reshape(len(s), -1)], axis=1)
        ev = self.evaluator()
        out = []
        for row, a, f2 in zip(s.tolist(), list(actions), s2.tolist()):
            ev.restore(row[:n], row[n : n + len(self.slots)])
            out.append(list(ev.step(a, f2, None).terms.values()))
        return np.asarray(out, dtype=np.float64).reshape(len(s), len(self.terms))

    def _apply(self, t: _Term, s: np.ndarray, actions: Any = None) -> np.ndarray:
        # Most user functions are written with numpy and accept column arrays;
        # those that branch in Python (``a and b``) or use ``math`` cannot, and
        # are applied row by row instead.
        assert t.fn is not None
        cls = state_type(self.features)
        args: tuple[Any, ...] = (cls(*s.T),) if actions is None else (cls(*s.T), actions)
        try:
            raw = np.asarray(t.fn(*args))
            if t.kind == "counter" and raw.dtype != np.bool_:
                raise TypeError("not a column of truth values")  # checked row by row below, each named
            out = raw.astype(np.float64)
        except Exception:
            pass
        else:
            if out.shape == (len(s),):
                if t.kind == "distance":
                    valid = (out >= 0.0) & (out <= FLOAT_MAX)
                    if not valid.all():
                        i = int(np.argmin(valid))  # the first bad row
                        check_distance(t.key, float(out[i]), cls._make(s[i].tolist()))
                return out
        rows = [cls._make(row) for row in s.tolist()]
        if t.kind == "distance":
            return np.array([distance_value(t.key, t.fn, r) for r in rows], dtype=np.float64)
        if actions is None:
            return np.array([1.0 if check_truth(t.key, t.fn(r)) else 0.0 for r in rows], dtype=np.float64)
        truths = [check_truth(t.key, t.fn(r, a)) for r, a in zip(rows, actions)]
        return np.array([1.0 if v else 0.0 for v in truths], dtype=np.float64)

    # -- the per-step kernel -------------------------------------------------

    @cached_property
    def source(self) -> str:
        """The generated per-step code (``start``, ``step`` and ``safe``), for reading and debugging."""
        return source_of(self)

    @cached_property
    def code(self) -> CodeType:
        """:attr:`source` compiled, once per compiled tree: every evaluator runs it in a namespace of its own."""
        return compile(self.source, f"<specguard evaluator of {self.paths[0]!r}>", "exec")

    def evaluator(self) -> FlatEvaluator:
        """A fresh per-episode evaluator (one per env); evaluators of one compiled tree share its generated code."""
        return FlatEvaluator(self)


def _box_rows(
    node: Node, path: str, child_boxes: Sequence[Box | None], index: dict[str, int], features: tuple[str, ...]
) -> tuple[Box | None, np.ndarray, np.ndarray]:
    lo, hi = np.full(len(features), -np.inf), np.full(len(features), np.inf)
    box = node.box(child_boxes)
    if box is None:
        return None, lo, hi
    for f, (b_lo, b_hi) in box.items():
        if f not in index:
            raise UnknownFeature(
                path,
                f"goal names unknown feature {f!r}; known features: {', '.join(features)}",
                hint="features come from InitialEnv(features=...); compute new ones in state()",
            )
        lo[index[f]], hi[index[f]] = b_lo, b_hi
    return box, lo, hi


def _is_fast(node: Node, box: Box | None) -> bool:
    """A node compiles to box tests: no own state, a box goal, and the default (or no) core reward."""
    kind = type(node)
    default_reward = kind.reward is Node.reward and kind.potential is Node.potential
    return (
        box is not None
        and not node.state_slots()
        and kind.terminates is Node.terminates
        and (default_reward or not node.own_reward)
    )


def _stages_form(node: Node, path: str) -> StagesForm | None:
    """The node's declared :class:`~specguard.extend.StagesForm`, checked against its children and slots."""
    form = node.fast_form()
    if form is None:
        return None
    n = len(node.children)
    if not isinstance(form, StagesForm):
        raise InvalidSpec(path, f"fast_form() must return a StagesForm or None, got {form!r}")
    if len(node.state_slots()) != 1 or len(form.stage) != n + 1 or len(form.shapers) != n:
        raise InvalidSpec(
            path,
            f"a StagesForm needs one own-state slot, N + 1 stage values and N shaper tuples for N = {n} "
            f"children; got {len(node.state_slots())} slots, {len(form.stage)} stage values, "
            f"{len(form.shapers)} shaper tuples",
        )
    numbers = [*form.stage, *(x for shapers in form.shapers for _, scale, w in shapers for x in (scale, w))]
    if not all(isinstance(x, (int, float)) and math.isfinite(x) for x in numbers):
        raise InvalidSpec(path, f"a StagesForm's stage values, scales and weights must be finite numbers: {form!r}")
    if not all(scale > 0 for shapers in form.shapers for _, scale, _ in shapers):
        raise InvalidSpec(path, f"a StagesForm's scales must be > 0: {form!r}")
    return form


def compile_tree(
    tree: Node, features: Sequence[str], *, weights: Mapping[str, Sequence[float]] | None = None
) -> CompiledTree:
    """Validate ``tree`` against ``features`` and flatten it.

    Args:
        tree: the goal tree.
        features: the feature names.
        weights: per path of a node that adapts its weights
            (:attr:`Node.adapts_weights`), one weight per child and then one
            per adapted safety annotation of the node, replacing the node's
            own (:mod:`specguard.training.auto_weights`).

    Raises:
        UnknownFeature: a goal names a feature not in ``features``.
        InvalidSpec: a weight or scale makes a coefficient overflow, or
            ``weights`` names a path that does not adapt its weights.
    """
    features = tuple(features)
    overrides = _check_overrides(tree, weights or {})
    index = {f: i for i, f in enumerate(features)}
    paths: list[str] = []
    nodes: list[Node] = []
    rows: list[tuple[np.ndarray, np.ndarray]] = []
    boxed: list[bool] = []
    fast: list[bool] = []
    children: list[list[int]] = []
    terms: list[_Term] = []
    slots: list[tuple[str, Slot]] = []
    slot_start: list[int] = []
    stages: list[StagesForm | None] = []

    def visit(node: Node, path: str, coef: ChildWeights) -> tuple[int, Box | None]:
        me = len(paths)
        paths.append(path)
        nodes.append(node)
        children.append([])
        rows.append((np.empty(0), np.empty(0)))
        boxed.append(False)
        fast.append(False)
        slot_start.append(-1)
        stages.append(None)
        core_w, ann_w = component_weights(node)
        kid_boxes = []
        kid_weights = node.child_weights()
        if path in overrides:
            kid_weights, ann_w = overrides[path]
        for child, w in zip(node.children, kid_weights):
            # A child's term of role r is scaled by this node's core weight and the child's weight for r.
            passed = ChildWeights(*(c * core_w * x for c, x in zip((coef.core, coef.shaping, coef.safety), w)))
            k, child_box = visit(child, child_path(path, child.name), passed)
            children[me].append(k)
            kid_boxes.append(child_box)
        box, lo, hi = _box_rows(node, path, kid_boxes, index, features)
        rows[me], boxed[me], fast[me] = (lo, hi), box is not None, _is_fast(node, box)
        if node.state_slots():
            slot_start[me] = len(slots)
            slots.extend((path, s) for s in node.state_slots())
        stages[me] = None if fast[me] else _stages_form(node, path)
        if node.own_reward:
            terms.append(_Term(path, "member" if fast[me] else "node", coef.core * core_w, node=me))
        for a, a_w in zip(node.annotations, ann_w):
            terms.append(_annotation_term(annotation_key(path, a), a, coef.of(a.role) * a_w, slots, me))
        return me, box

    visit(tree, tree.name, ChildWeights.same(1.0))
    for t in terms:
        if not math.isfinite(t.coef):
            raise InvalidSpec(
                t.key,
                f"the component's coefficient (the weights on its path times its own weight"
                f"{', divided by scale' if t.kind == 'distance' else ''}) is {t.coef!r}",
                hint="use weights and scales of moderate size; only their ratios matter",
            )
    lo = np.stack([r[0] for r in rows])
    hi = np.stack([r[1] for r in rows])
    lo.setflags(write=False)
    hi.setflags(write=False)
    return CompiledTree(
        features,
        tuple(paths),
        tuple(nodes),
        lo,
        hi,
        tuple(boxed),
        tuple(fast),
        tuple(terms),
        tuple(tuple(c) for c in children),
        tuple(slots),
        tuple(slot_start),
        tuple(stages),
        tuple(sorted((path, tuple(float(w) for w in ws)) for path, ws in (weights or {}).items())),
    )


def _check_overrides(
    tree: Node, weights: Mapping[str, Sequence[float]]
) -> dict[str, tuple[tuple[ChildWeights, ...], tuple[float, ...]]]:
    """``weights`` as each adapting node's children's :class:`ChildWeights` and annotation weights, checked."""
    nodes = dict(tree.walk())
    out = {}
    for path, ws in weights.items():
        node = nodes.get(path)
        if node is None or not node.adapts_weights:
            adapting = [p for p, n in nodes.items() if n.adapts_weights]
            raise InvalidSpec(
                f"weights[{path!r}]",
                f"expected the path of a node with weights='auto', got {path!r}; "
                f"such nodes: {', '.join(map(repr, adapting)) or 'none'}",
            )
        values = tuple(float(w) for w in ws)
        adapted = adapted_annotations(node)
        n = len(node.children)
        if len(values) != n + len(adapted) or not all(math.isfinite(w) and w >= 0 for w in values):
            per = "one per child" + (f", then one per constraint of the node ({len(adapted)})" if adapted else "")
            raise InvalidSpec(
                f"weights[{path!r}]",
                f"expected {n + len(adapted)} finite weights >= 0 ({per}), got {values!r}",
            )
        annotation_weights = list(component_weights(node)[1])
        for i, w in zip(adapted, values[n:]):
            annotation_weights[i] = w
        out[path] = tuple(ChildWeights.same(w) for w in values[:n]), tuple(annotation_weights)
    return out


def _annotation_term(key: str, a: Annotation, coef: float, slots: list[tuple[str, Slot]], owner: int) -> _Term:
    form = a.fast_form()
    start = len(slots)
    slots.extend((key, s) for s in a.state_slots())
    if isinstance(form, ShapingForm):  # the two closed forms the kernel knows (a tagged union, not a ladder)
        if coef == 0.0:  # weighted 0 on its path (a Sequence takes over its children's distances): never called
            return _Term(key, "zero", 0.0, annotation=a, owner=owner)
        return _Term(key, "distance", coef / form.scale, fn=form.fn, annotation=a, owner=owner)
    if isinstance(form, CounterForm):
        if len(slots) - start != 1:
            raise InvalidSpec(key, f"a CounterForm annotation must have one state slot, got {len(slots) - start}")
        return _Term(
            key,
            "counter",
            coef,
            fn=form.fn,
            budget=form.budget,
            on_next_state=form.on_next_state,
            slot=start,
            annotation=a,
            owner=owner,
        )
    return _Term(key, "annotation", coef, slot=start if len(slots) > start else -1, annotation=a, owner=owner)


class FlatEvaluator:
    """Steps a :class:`CompiledTree` along one episode at a time: an
    :class:`~specguard.construction.evaluator.Evaluator`.

    Holds the episode's state: the previous memberships, distances and
    feature namedtuple, and the own-state slots (counters, stages).

    Attributes:
        goals: every node's membership of the last state reset or stepped to, by path: a new
            dict each time (the env hands it out as ``info["goals"]``).
        step: ``step(action, f, last=False, terminated=False)``, the protocol's: advance by one transition to
            features ``f``. When the episode ends at ``f`` (the spec ends it, or ``last``: the base env
            terminated or truncated), the last state is judged too (docs/semantics.md, "The last state"), in
            this step's terms; with ``last`` None never (the transition's own reward, as
            :meth:`CompiledTree.reward_terms` gives it). ``terminated``: the base env terminated the episode
            at ``f``; where the root goal holds until the end (:attr:`horizon`), the episode ended before its
            horizon (:meth:`~specguard.extend.Node.terminated_state`). Returns the
            :class:`~specguard.construction.evaluator.StepResult`. It is the generated code's own function
            (no method around it: one Python call a step); the episode state changes only once the step
            succeeded, and a failing user function is named by a checked re-run.
    """

    def __init__(self, tree: CompiledTree) -> None:
        self.tree = tree
        self.paths = tree.paths
        self.slots = tree.slots
        self.safety_keys = tree.safety_keys
        self._state_cls = state_type(tree.features)
        namespace = build_namespace(tree, self._state_cls)
        # The generated step reads and writes this evaluator's episode state (one Python call a step).
        namespace.update(
            _ev=self, _result=_result, _StepResult=StepResult, _EvaluationError=EvaluationError, _isfinite=_isfinite
        )
        exec(tree.code, namespace)
        self._start: Callable[..., Any] = namespace["start"]
        self.step: Callable[..., StepResult] = namespace["step"]
        self._safe: Callable[[list[float]], tuple[bool, ...]] = namespace["safe"]
        self._safe_info: Callable[[list[float]], dict[str, bool]] = namespace["safe_info"]
        self.horizon = not tree.reach
        """The root goal holds until the end: an episode the initial env terminates ended before its horizon."""
        self._m: tuple[bool, ...] = ()
        self._q: tuple[float, ...] = ()
        self._s: Any = None
        self.own_state: list[float] = [0.0] * len(tree.slots)
        self.goals: dict[str, bool] = {}

    @property
    def state(self) -> Any:
        """The features of the last state reset or stepped to (``s.x`` by name)."""
        return self._s

    def members(self, f: Sequence[float]) -> tuple[bool, ...]:
        """Every node's membership of one feature vector, at the start of an episode (no episode state)."""
        members: tuple[bool, ...] = self._start(f, [0.0] * len(self.slots), True)[0]
        return members

    def reset(self, f: Sequence[float]) -> tuple[bool, ...]:
        """Start an episode in features ``f``; returns every node's membership."""
        own = [0.0] * len(self.slots)
        try:
            self._m, self.goals, self._s, self._q = self._start(f, own, True)
        except EvaluationError:
            raise
        except Exception as e:
            self._diagnose(None, f, e)
        self.own_state = own
        return self._m

    def restore(self, f: Sequence[float], own: Sequence[float]) -> tuple[bool, ...]:
        """Start from features ``f`` with the own-state slots ``own`` (an observation's tail)."""
        if len(own) != len(self.slots):
            raise ValueError(f"expected {len(self.slots)} own-state values, got {len(own)}")
        state = [float(v) for v in own]
        self._m, self.goals, self._s, self._q = self._start(f, state, False)
        self.own_state = state
        return self._m

    @property
    def safe(self) -> tuple[bool, ...]:
        """Per safety annotation (``safety_keys``), whether the episode has had no violation so far."""
        return self._safe(self.own_state)

    def safe_info(self) -> dict[str, bool]:
        """:attr:`safe` by safety key, a new dict (the env's ``info["safe"]``)."""
        return self._safe_info(self.own_state)

    def __copy__(self) -> FlatEvaluator:
        """A new evaluator of the same tree, in the same episode state (its generated step is its own)."""
        other = FlatEvaluator(self.tree)
        other._m, other.goals, other._s, other._q = self._m, dict(self.goals), self._s, self._q
        other.own_state = self.own_state[:]
        return other

    def __deepcopy__(self, memo: dict[int, Any]) -> FlatEvaluator:
        return self.__copy__()  # the episode state is immutable values and one list of floats, copied

    def _non_finite(self, r: float, terms: dict[str, float]) -> NoReturn:
        bad = {k: v for k, v in terms.items() if not math.isfinite(v)}
        raise EvaluationError(f"non-finite reward {r}: the terms {bad} are not finite")

    def _diagnose(self, action: Any, f: Sequence[float], error: Exception) -> NoReturn:
        """Re-run the user functions one by one to name the one at fault."""
        s2 = self._state_cls._make(f)
        for t in self.tree.distances:
            assert t.fn is not None
            distance_value(t.key, t.fn, s2)
        for t in self.tree.counters if action is not None else ():
            assert t.fn is not None
            try:
                t.fn(s2) if t.on_next_state else t.fn(self._s, action)
            except Exception as e:
                state = f"state {s2}" if t.on_next_state else f"state {self._s}, action {action!r}"
                raise EvaluationError(
                    f"{t.key}: the constraint function raised {type(e).__name__}: {e} ({state})"
                ) from e
        raise EvaluationError(f"evaluating the step failed with {type(error).__name__}: {error}") from error
