"""The goal tree compiled once into a flat evaluator.

Algorithm 1 (see :mod:`specguard.reference`) nests closures; evaluated per
step it made Pendulum training 1.7-2x slower than on the raw env. Because a
leaf reward is ``1[s' in G] - 1[s in G]`` and every operator reward is linear,
the root reward is a plain weighted sum over the tree's atomic components:

* one term per leaf, ``c_leaf * (m'_leaf - m_leaf)`` where ``c_leaf`` is the
  product of the weights on its path (the AND-weights folded in);
* one term per distance, ``c * (fn(s) - fn(s')) / scale``;
* one term per constraint, ``c * (-1 if fn(s, a) else 0)``.

Every node's goal is a box (an ``All`` of boxes is their intersection), so all
of them are two arrays ``lo``/``hi`` of shape ``(nodes, features)``: batches of
states are tested in one vectorised comparison (:meth:`CompiledTree.members`).
For the single state of an env step, numpy's per-call overhead (about 3.5 us
for that comparison) would exceed the whole budget of a Pendulum step, so the
same tables are also turned into a small generated Python function with the
bounds as constants (:attr:`CompiledTree.source`), as dataclasses generate
``__init__``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from specguard.error import EvaluationError, InvalidSpec, UnknownFeature
from specguard.initial_env import state_type
from specguard.nodes import ANNOTATION_SEPARATOR, All, Constraint, Distance, Goal, Node, component_weights

__all__ = ["CompiledTree", "Evaluator", "compile_tree"]


@dataclass(frozen=True)
class _Term:
    key: str  # "path" for a leaf core, "path:name" for an annotation
    kind: str  # "leaf" | "distance" | "constraint"
    coef: float  # product of the weights on the path, times the component weight (and 1/scale)
    node: int = -1  # leaf: index of its node
    fn: Callable[..., Any] | None = None
    budget: int = 0


@dataclass(frozen=True)
class CompiledTree:
    """The flat form of a goal tree over a fixed feature tuple.

    Attributes:
        features: the feature names, the columns of ``lo`` and ``hi``.
        paths: every node's path, parents before children (root first).
        lo, hi: ``(len(paths), len(features))`` inclusive boxes, ``+-inf`` where open.
        terms: the reward components in Algorithm 1's processing order
            (a node's subtree, then its annotations).
        children: per node, the indices of its children in ``paths``.
    """

    features: tuple[str, ...]
    paths: tuple[str, ...]
    lo: np.ndarray
    hi: np.ndarray
    terms: tuple[_Term, ...]
    children: tuple[tuple[int, ...], ...]

    @property
    def term_keys(self) -> tuple[str, ...]:
        return tuple(t.key for t in self.terms)

    @property
    def constraints(self) -> tuple[_Term, ...]:
        return tuple(t for t in self.terms if t.kind == "constraint")

    @property
    def distances(self) -> tuple[_Term, ...]:
        return tuple(t for t in self.terms if t.kind == "distance")

    @property
    def counter_keys(self) -> tuple[str, ...]:
        return tuple(t.key for t in self.constraints)

    @property
    def budgets(self) -> tuple[int, ...]:
        return tuple(t.budget for t in self.constraints)

    # -- batch evaluation (numpy) ------------------------------------------

    def members(self, states: np.ndarray) -> np.ndarray:
        """``(B, nodes)`` membership of every state of ``states`` (shape ``(B, features)``) in every goal."""
        s = np.asarray(states, dtype=np.float64)[:, None, :]
        return ((s >= self.lo) & (s <= self.hi)).all(axis=2)

    def reward_terms(self, states: np.ndarray, actions: Any, next_states: np.ndarray) -> np.ndarray:
        """``(B, terms)`` weighted reward components of the transitions ``(s, a, s')``.

        Constraint terms depend on ``(s, a)`` only; counters are per episode and
        so are not part of a transition batch.
        """
        s = np.asarray(states, dtype=np.float64)
        s2 = np.asarray(next_states, dtype=np.float64)
        m, m2 = self.members(s), self.members(s2)
        out = np.empty((len(s), len(self.terms)))
        for j, t in enumerate(self.terms):
            if t.kind == "leaf":
                out[:, j] = t.coef * (m2[:, t.node].astype(np.float64) - m[:, t.node])
            elif t.kind == "distance":
                out[:, j] = t.coef * (self._apply(t, s) - self._apply(t, s2))
            else:
                out[:, j] = -t.coef * self._apply(t, s, actions)
        return out

    def rewards(self, states: np.ndarray, actions: Any, next_states: np.ndarray) -> np.ndarray:
        """``(B,)`` rewards of the transitions: the sum of :meth:`reward_terms`."""
        return self.reward_terms(states, actions, next_states).sum(axis=1)

    def _apply(self, t: _Term, s: np.ndarray, actions: Any = None) -> np.ndarray:
        # Most user functions are written with numpy and accept column arrays;
        # those that branch in Python (``a and b``) or use ``math`` cannot, and
        # are applied row by row instead.
        assert t.fn is not None
        cls = state_type(self.features)
        args: tuple[Any, ...] = (cls(*s.T),) if t.kind == "distance" else (cls(*s.T), actions)
        try:
            out = np.asarray(t.fn(*args), dtype=np.float64)
            if out.shape == (len(s),):
                return out
        except Exception:
            pass
        rows = [cls._make(row) for row in s.tolist()]
        if t.kind == "distance":
            return np.array([float(t.fn(r)) for r in rows])
        return np.array([1.0 if t.fn(r, a) else 0.0 for r, a in zip(rows, actions)])

    # -- the per-step kernel -------------------------------------------------

    @property
    def source(self) -> str:
        """The generated per-step membership function, for reading and debugging."""
        return _members_source(self)

    def evaluator(self) -> Evaluator:
        """A fresh per-episode evaluator (one per env)."""
        return Evaluator(self)


def _members_source(tree: CompiledTree) -> str:
    names = [f"f{i}" for i in range(len(tree.features))]
    lines = ["def members(f):", f"    ({', '.join(names)},) = f"]
    # Children come after parents in ``paths``: emit in reverse so a parent
    # reuses its children's results (G = intersection of G_i).
    for i in reversed(range(len(tree.paths))):
        if tree.children[i]:
            expr = " and ".join(f"m{c}" for c in tree.children[i])
        else:
            tests = []
            for j, name in enumerate(names):
                lo, hi = float(tree.lo[i, j]), float(tree.hi[i, j])
                if lo == hi:
                    tests.append(f"{name} == {lo!r}")
                elif lo > -math.inf and hi < math.inf:
                    tests.append(f"{lo!r} <= {name} <= {hi!r}")
                elif lo > -math.inf:
                    tests.append(f"{lo!r} <= {name}")
                elif hi < math.inf:
                    tests.append(f"{name} <= {hi!r}")
            expr = " and ".join(tests) or "True"
        lines.append(f"    m{i} = {expr}  # {tree.paths[i]}")
    lines.append(f"    return ({', '.join(f'm{i}' for i in range(len(tree.paths)))},)")
    return "\n".join(lines) + "\n"


def compile_tree(tree: Node, features: Sequence[str]) -> CompiledTree:
    """Validate ``tree`` against ``features`` and flatten it.

    Raises:
        UnknownFeature: a goal names a feature not in ``features``.
        InvalidSpec: the tree holds a node or annotation this evaluator has no
            definition for.
    """
    features = tuple(features)
    index = {f: i for i, f in enumerate(features)}
    paths: list[str] = []
    boxes: list[tuple[np.ndarray, np.ndarray]] = []
    children: list[list[int]] = []
    terms: list[_Term] = []

    def visit(node: Node, path: str, coef: float) -> int:
        me = len(paths)
        paths.append(path)
        children.append([])
        boxes.append((np.full(len(features), -np.inf), np.full(len(features), np.inf)))
        core_w, ann_w = component_weights(node)
        lo, hi = boxes[me]
        if isinstance(node, Goal):
            for f, b_lo, b_hi in node.bounds:
                if f not in index:
                    raise UnknownFeature(
                        path,
                        f"goal names unknown feature {f!r}; known features: {', '.join(features)}",
                        hint="features come from InitialEnv(features=...); compute new ones in state()",
                    )
                lo[index[f]], hi[index[f]] = b_lo, b_hi
            terms.append(_Term(path, "leaf", coef * core_w, node=me))
        elif isinstance(node, All):
            for child, w in zip(node.children, node.child_weights()):
                k = visit(child, f"{path}/{child.name}", coef * core_w * w)
                children[me].append(k)
                np.maximum(lo, boxes[k][0], out=lo)
                np.minimum(hi, boxes[k][1], out=hi)
        else:
            raise InvalidSpec(path, f"the flat evaluator has no definition for {type(node).__name__} nodes")
        for a, w in zip(node.annotations, ann_w):
            key = f"{path}{ANNOTATION_SEPARATOR}{a.name}"
            if isinstance(a, Distance):
                terms.append(_Term(key, "distance", coef * w / a.scale, fn=a.fn))
            elif isinstance(a, Constraint):
                assert isinstance(a.budget, int)
                terms.append(_Term(key, "constraint", coef * w, fn=a.fn, budget=a.budget))
            else:
                raise InvalidSpec(key, f"the flat evaluator has no definition for {type(a).__name__} annotations")
        return me

    visit(tree, tree.name, 1.0)
    lo = np.stack([b[0] for b in boxes])
    hi = np.stack([b[1] for b in boxes])
    lo.setflags(write=False)
    hi.setflags(write=False)
    return CompiledTree(features, tuple(paths), lo, hi, tuple(terms), tuple(tuple(c) for c in children))


class Evaluator:
    """Steps a :class:`CompiledTree` along one episode at a time.

    Holds the episode's state: the previous memberships, distances and
    feature namedtuple, and the constraint counters.
    """

    def __init__(self, tree: CompiledTree) -> None:
        self.tree = tree
        self.paths = tree.paths
        self.counter_keys = tree.counter_keys
        self.budgets = tree.budgets
        namespace: dict[str, Any] = {}
        exec(compile(tree.source, f"<specguard members of {tree.paths[0]!r}>", "exec"), namespace)
        self._members: Callable[[Sequence[float]], tuple[bool, ...]] = namespace["members"]
        self._state_cls = state_type(tree.features)
        self._needs_state = any(t.kind != "leaf" for t in tree.terms)
        # One tuple per term, the fields the step loop reads (kind code, coef, node, fn, counter slot).
        plan = []
        slot = 0
        for t in tree.terms:
            if t.kind == "constraint":
                plan.append((2, t.coef, slot, t.fn, t.key))
                slot += 1
            else:
                plan.append((0 if t.kind == "leaf" else 1, t.coef, t.node, t.fn, t.key))
        self._plan = tuple(plan)
        self._m: tuple[bool, ...] = ()
        self._phi: dict[str, float] = {}
        self._s: Any = None
        self.counters: list[int] = list(self.budgets)

    def reset(self, f: Sequence[float]) -> tuple[bool, ...]:
        """Start an episode in features ``f``; returns every node's membership."""
        self._m = self._members(f)
        self.counters = list(self.budgets)
        if self._needs_state:
            self._s = self._state_cls._make(f)
            self._phi = {t.key: self._distance(t.key, t.fn, self._s) for t in self.tree.distances}
        return self._m

    def step(self, action: Any, f: Sequence[float]) -> tuple[float, bool, tuple[bool, ...], dict[str, float]]:
        """Advance by one transition to features ``f``.

        Returns:
            The reward, whether the spec ends the episode (root goal reached or
            a counter at 0), every node's membership of ``f`` and the weighted
            reward terms by key.
        """
        m2 = self._members(f)
        m = self._m
        s = self._s
        s2 = self._state_cls._make(f) if self._needs_state else None
        phi = self._phi
        counters = self.counters
        terms = {}
        ended = m2[0]
        for kind, coef, i, fn, key in self._plan:
            if kind == 0:
                terms[key] = coef * (m2[i] - m[i])
            elif kind == 1:
                d = self._distance(key, fn, s2)
                terms[key] = coef * (phi[key] - d)
                phi[key] = d
            else:
                if self._violates(key, fn, s, action):
                    terms[key] = -coef
                    counters[i] -= 1
                    if counters[i] == 0:
                        ended = True
                else:
                    terms[key] = 0.0
        self._m = m2
        self._s = s2
        reward = sum(terms.values())
        if not math.isfinite(reward):
            bad = {k: v for k, v in terms.items() if not math.isfinite(v)}
            raise EvaluationError(f"non-finite reward {reward}: the terms {bad} are not finite")
        return reward, ended, m2, terms

    @staticmethod
    def _distance(key: str, fn: Callable[[Any], float], s: Any) -> float:
        try:
            d = fn(s)
        except Exception as e:
            raise EvaluationError(f"{key}: the distance function raised {type(e).__name__}: {e} (state {s})") from e
        if not (d >= 0.0):  # also catches NaN
            raise EvaluationError(f"{key}: expected a distance >= 0, got {d!r} (state {s})")
        return float(d)

    @staticmethod
    def _violates(key: str, fn: Callable[[Any, Any], bool], s: Any, a: Any) -> bool:
        try:
            return bool(fn(s, a))
        except Exception as e:
            raise EvaluationError(
                f"{key}: the constraint function raised {type(e).__name__}: {e} (state {s}, action {a!r})"
            ) from e
