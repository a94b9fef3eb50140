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
``__init__``. Only two kinds of values reach that source: finite floats as
their exact ``repr`` (:func:`_number`) and names as ``str`` literals
(:func:`_text`); user text never becomes code.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, NoReturn

import numpy as np

from specguard.error import EvaluationError, InvalidSpec, UnknownFeature
from specguard.initial_env import state_type
from specguard.nodes import ANNOTATION_SEPARATOR, All, Constraint, Distance, Goal, Node, component_weights
from specguard.reference import FLOAT_MAX, check_distance, distance_value

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
        return np.asarray(((s >= self.lo) & (s <= self.hi)).all(axis=2))

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
        return np.asarray(self.reward_terms(states, actions, next_states).sum(axis=1))

    def _apply(self, t: _Term, s: np.ndarray, actions: Any = None) -> np.ndarray:
        # Most user functions are written with numpy and accept column arrays;
        # those that branch in Python (``a and b``) or use ``math`` cannot, and
        # are applied row by row instead.
        assert t.fn is not None
        cls = state_type(self.features)
        args: tuple[Any, ...] = (cls(*s.T),) if t.kind == "distance" else (cls(*s.T), actions)
        try:
            out = np.asarray(t.fn(*args), dtype=np.float64)
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
        return np.array([1.0 if t.fn(r, a) else 0.0 for r, a in zip(rows, actions)], dtype=np.float64)

    # -- the per-step kernel -------------------------------------------------

    @property
    def source(self) -> str:
        """The generated per-step code (``members`` and ``step``), for reading and debugging."""
        return _members_source(self) + "\n" + _step_source(self)

    def evaluator(self) -> Evaluator:
        """A fresh per-episode evaluator (one per env)."""
        return Evaluator(self)


def _number(x: float) -> str:
    """A finite float as exact Python source (``repr`` round-trips); never the names ``inf`` or ``nan``."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot emit the non-finite number {x!r} into generated code")
    return repr(x)


def _text(text: str) -> str:
    """A name as a Python ``str`` literal (``str.__repr__``: no subclass may change it)."""
    return str.__repr__(text)


def _unpack(tree: CompiledTree) -> str:
    return f"    ({', '.join(f'f{i}' for i in range(len(tree.features)))},) = f"


def _members_lines(tree: CompiledTree) -> list[str]:
    lines = [_unpack(tree)]
    # Children come after parents in ``paths``: emit in reverse so a parent
    # reuses its children's results (G = intersection of G_i).
    for i in reversed(range(len(tree.paths))):
        if tree.children[i]:
            expr = " and ".join(f"m{c}" for c in tree.children[i])
        else:
            tests = []
            for j in range(len(tree.features)):
                lo, hi = float(tree.lo[i, j]), float(tree.hi[i, j])
                if lo == hi:
                    tests.append(f"f{j} == {_number(lo)}")
                elif lo > -math.inf and hi < math.inf:
                    tests.append(f"{_number(lo)} <= f{j} <= {_number(hi)}")
                elif lo > -math.inf:
                    tests.append(f"{_number(lo)} <= f{j}")
                elif hi < math.inf:
                    tests.append(f"f{j} <= {_number(hi)}")
            expr = " and ".join(tests) or "True"
        lines.append(f"    m{i} = {expr}  # {_text(tree.paths[i])}")
    return lines


def _members_tuple(tree: CompiledTree) -> str:
    return f"({', '.join(f'm{i}' for i in range(len(tree.paths)))},)"


def _members_source(tree: CompiledTree) -> str:
    return "\n".join(["def members(f):", *_members_lines(tree), f"    return {_members_tuple(tree)}"]) + "\n"


def _step_source(tree: CompiledTree) -> str:
    """``step(f, m, s, q, c, a)``: features of s', memberships, state and distances of s, counters, action.

    Straight-line code: one line per goal and per reward term, the weights
    folded into constants. User functions are globals ``_fn<k>``.
    """
    lines = ["def step(f, m, s, q, c, a):", *_members_lines(tree)]
    lines.append("    s2 = _make(f)" if tree.distances or tree.constraints else "    s2 = None")
    names: list[str] = []
    distances: list[str] = []
    slot = 0
    for k, t in enumerate(tree.terms):
        if t.kind == "leaf":
            term = f"{_number(t.coef)} * (m{t.node} - m[{t.node}])"
        elif t.kind == "distance":
            d = f"d{len(distances)}"
            lines.append(f"    {d} = _float(_fn{k}(s2))  # {_text(t.key)}")
            term = f"{_number(t.coef)} * (q[{len(distances)}] - {d})"
            distances.append(d)
        else:
            lines.append(f"    v{slot} = _fn{k}(s, a)  # {_text(t.key)}")
            lines.append(f"    if v{slot}:")
            lines.append(f"        c[{slot}] -= 1")
            term = f"{_number(-t.coef)} if v{slot} else 0.0"
            slot += 1
        names.append(f"t{k}")
        lines.append(f"    t{k} = {term}")
    if distances:
        # One comparison chain per distance: finite and >= 0 (NaN fails it too).
        checks = " and ".join(f"0.0 <= {d} <= {_number(FLOAT_MAX)}" for d in distances)
        lines.append(f"    if not ({checks}):")
        lines.append("        raise ValueError('invalid distance')")
    lines.append(f"    r = {' + '.join(names)}")
    pairs = ", ".join(f"{_text(t.key)}: t{k}" for k, t in enumerate(tree.terms))
    ended = " or ".join(["m0", *(f"c[{i}] == 0" for i in range(slot))])
    distance_tuple = f"({', '.join(distances)},)" if distances else "()"
    lines.append(f"    return r, {ended}, {_members_tuple(tree)}, s2, {distance_tuple}, {{{pairs}}}")
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
    for t in terms:
        if not math.isfinite(t.coef):
            raise InvalidSpec(
                t.key,
                f"the component's coefficient (the weights on its path times its own weight"
                f"{', divided by scale' if t.kind == 'distance' else ''}) is {t.coef!r}",
                hint="use weights and scales of moderate size; only their ratios matter",
            )
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
        self._state_cls = state_type(tree.features)
        namespace: dict[str, Any] = {"_make": self._state_cls._make, "_float": float}
        namespace.update({f"_fn{k}": t.fn for k, t in enumerate(tree.terms) if t.fn is not None})
        exec(compile(tree.source, f"<specguard evaluator of {_text(tree.paths[0])}>", "exec"), namespace)
        self.members: Callable[[Sequence[float]], tuple[bool, ...]] = namespace["members"]
        """Every node's membership of one feature vector (no episode state)."""
        self._step: Callable[..., Any] = namespace["step"]
        self._needs_state = bool(tree.distances or tree.constraints)
        self._m: tuple[bool, ...] = ()
        self._q: tuple[float, ...] = ()
        self._s: Any = None
        self.counters: list[int] = list(self.budgets)

    def reset(self, f: Sequence[float]) -> tuple[bool, ...]:
        """Start an episode in features ``f``; returns every node's membership."""
        self._m = self.members(f)
        self.counters = list(self.budgets)
        if self._needs_state:
            self._s = self._state_cls._make(f)
            self._q = tuple(self._distance(t, self._s) for t in self.tree.distances)
        return self._m

    def step(self, action: Any, f: Sequence[float]) -> tuple[float, bool, tuple[bool, ...], dict[str, float]]:
        """Advance by one transition to features ``f``.

        Returns:
            The reward, whether the spec ends the episode (root goal reached or
            a counter at 0), every node's membership of ``f`` and the weighted
            reward terms by key (Algorithm 1's processing order).
        """
        counters = list(self.counters)  # the episode state changes only once the step succeeded
        try:
            r, ended, m2, s2, q2, terms = self._step(f, self._m, self._s, self._q, counters, action)
        except Exception as e:
            self._diagnose(action, f, e)
        if not math.isfinite(r):
            bad = {k: v for k, v in terms.items() if not math.isfinite(v)}
            raise EvaluationError(f"non-finite reward {r}: the terms {bad} are not finite")
        self._m, self._s, self._q, self.counters = m2, s2, q2, counters
        return float(r), ended, m2, terms

    def _diagnose(self, action: Any, f: Sequence[float], error: Exception) -> NoReturn:
        """Re-run the user functions one by one to name the one at fault."""
        s2 = self._state_cls._make(f)
        for t in self.tree.distances:
            self._distance(t, s2)
        for t in self.tree.constraints:
            assert t.fn is not None
            try:
                t.fn(self._s, action)
            except Exception as e:
                raise EvaluationError(
                    f"{t.key}: the constraint function raised {type(e).__name__}: {e} "
                    f"(state {self._s}, action {action!r})"
                ) from e
        raise EvaluationError(f"evaluating the step failed with {type(error).__name__}: {error}") from error

    @staticmethod
    def _distance(t: _Term, s: Any) -> float:
        assert t.fn is not None
        return distance_value(t.key, t.fn, s)
