"""The examples the contract checks run on, and how their failures read (for :mod:`specguard.contract.invariants`).

An example (:class:`Example`) is a random goal tree over :data:`FEATURES` that
contains the class under test, a trajectory of float32 states and the actions
taken. :func:`run_property` runs a check's property with Hypothesis
(derandomized, so CI sees the same examples every time) and turns the shrunk
failing example into one readable :class:`AssertionError` (:func:`fail`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple, NoReturn

import numpy as np
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st
from hypothesis.errors import FlakyFailure, HypothesisException

from specguard import strategies as sgst
from specguard.construction.env import SpecEnv
from specguard.construction.initial_env import state_type
from specguard.construction.reference import ExtendedState, Requirements, process
from specguard.contract.replay import ReplayEnv
from specguard.extend import Annotation, Box, Context, Node, until_end
from specguard.tree._draw import values
from specguard.tree.builtin_annotations import Constraint, Distance
from specguard.tree.nodes import All, Goal
from specguard.utils.node_paths import child_path

__all__ = [
    "FEATURES",
    "Broken",
    "Example",
    "cases",
    "fail",
    "refinement_cases",
    "run_property",
    "trees_with",
    "visiting_cases",
]


class Broken(Exception):
    """What breaks an invariant, raised by a contract property; :func:`run_property` adds the rest.

    An internal signal: the kit's checks (:mod:`specguard.contract.invariants`) raise it and
    :func:`run_property` turns it into the check's readable :class:`AssertionError` (:func:`fail`).
    """


FEATURES = ("a", "b", "c")
"""The features of the random trees and trajectories."""
MAX_EXAMPLES = 40
"""Examples per check by default."""
MARKOV_EXAMPLES = 100
"""Examples of ``check_markov`` by default: episode state hidden at module level or on a class shows only in some
trajectories (30 derandomize-free runs of it on a Sequence keeping its stage there: at 40 examples, 10-13 missed it
with random states and 5 with states moved into the tree's goals, :func:`visiting_cases`)."""

Check = Callable[..., None]


class Example(NamedTuple):
    """One example: a tree and, for most checks, a trajectory ``s_0 .. s_T`` with the actions ``a_0 .. a_{T-1}``."""

    tree: Node
    trajectory: list[list[float]] | None = None
    actions: list[int] | None = None
    leaf: Node | None = None  # the refined leaf (check_refinement_preserves_root_goal)
    terminate: bool = False  # the base env ends the trajectory by termination (a fall), not truncation


# -- strategies ----------------------------------------------------------------


def _annotated(draw: st.DrawFn, node: Node, kinds: Sequence[type[Annotation]]) -> Node:
    anns = []
    for i in range(max(0, draw(st.integers(0, 4)) - 2)):  # mostly none, up to 2
        kind = draw(st.sampled_from(kinds))
        anns.append(draw(kind.strategy(FEATURES, f"{kind.__name__.lower()}{i}")))
    return node.annotate(*anns) if anns else node


def _goal(draw: st.DrawFn, name: str) -> Goal:
    """A ``Goal`` on some of :data:`FEATURES` (a lighter :func:`specguard.strategies.goals`), often on grid edges."""
    box: dict[str, tuple[float | None, float | None]] = {}
    for f in FEATURES:
        side = draw(st.integers(0, 4))  # 0: unbounded (what it shrinks to), 1: lo only, 2: hi only, else both
        if side:
            lo, hi = sorted((draw(values), draw(values)))
            box[f] = (None if side == 2 else lo, None if side == 1 else hi)
    if not box:
        box[FEATURES[0]] = (draw(values), None)
    return Goal(name, **box)


def _subtree(
    draw: st.DrawFn, ops: Sequence[type[Node]], kinds: Sequence[type[Annotation]], depth: int, name: str
) -> Node:
    """A ``Goal`` leaf or an operator of ``ops`` (``strategy(children, name)``) over up to 3 children ``n0..n2``."""
    if depth <= 1 or draw(st.integers(0, 2)) == 0:  # shrinks towards a leaf
        node: Node = _goal(draw, name)
    else:
        op = draw(st.sampled_from(ops))
        kids = [_subtree(draw, ops, kinds, depth - 1, f"n{i}") for i in range(draw(st.integers(1, 3)))]
        node = draw(op.strategy(kids, name))
    return _annotated(draw, node, kinds)


@st.composite
def trees_with(draw: st.DrawFn, cls: type) -> Node:
    """Random trees over :data:`FEATURES` that contain ``cls``, with ``Distance`` and ``Constraint`` annotations.

    An operator roots the tree (``cls.strategy(children, "root")``) and may
    recur below it; an annotation class is attached to the root
    (``cls.strategy(FEATURES, "kit")``) and may be drawn on any node; ``Goal``
    (a leaf) is in every tree. Constraints let children end episodes.
    """
    kinds: tuple[type[Annotation], ...] = (Distance, Constraint, Distance)  # constraints end episodes early
    if issubclass(cls, Annotation):
        tree = _subtree(draw, (All,), (cls, Distance, Constraint), 3, "root")
        return tree.annotate(draw(cls.strategy(FEATURES, "kit")))
    if issubclass(cls, Goal) or not issubclass(cls, Node):
        return _subtree(draw, (All,), kinds, 3, "root")
    kids = [_subtree(draw, (All, cls), kinds, 2, f"n{i}") for i in range(draw(st.integers(1, 3)))]
    return _annotated(draw, draw(cls.strategy(kids, "root")), kinds)


def f32(rows: Sequence[Sequence[float]]) -> list[list[float]]:
    """States as observations carry them (float32), so that every evaluator sees the same numbers."""
    out: list[list[float]] = np.asarray(rows, dtype=np.float32).astype(np.float64).tolist()
    return out


@st.composite
def cases(draw: st.DrawFn, cls: type, max_size: int = 10) -> Example:
    """A tree containing ``cls``, a trajectory of 2 to ``max_size`` states and an action (0-2) per step."""
    tree = draw(trees_with(cls))
    trajectory = f32(draw(sgst.trajectories(FEATURES, max_size=max_size)))
    n = len(trajectory) - 1
    actions = draw(st.lists(st.integers(0, 2), min_size=n, max_size=n))
    # Trajectories of odd length end by the base env's termination, the others by truncation: both ends are
    # covered with no draw of their own, which would change every example the checks are tuned to find.
    return Example(tree, trajectory, actions, terminate=n % 2 == 0)


def _goal_boxes(tree: Node) -> list[Box]:
    """The boxes of the tree's nodes that declare one (``Node.box``: a ``Goal``'s, an ``All``'s intersection), the
    empty ones left out, children before their parent."""
    found: list[Box] = []

    def visit(node: Node) -> Box | None:
        kids = [visit(child) for child in node.children]
        try:
            box = node.box(kids)
        except Exception:  # a broken operator's box is other checks' business
            return None
        if box is not None and all(lo <= hi for lo, hi in box.values()):
            found.append(box)
        return box

    visit(tree)
    return found


def _inside(box: Box, state: list[float]) -> list[float]:
    """``state`` moved into ``box``: each bounded feature set to a value inside its range (float32)."""
    moved = list(state)
    for f, (lo, hi) in box.items():
        v = lo if math.isinf(hi) else hi if math.isinf(lo) else (lo + hi) / 2
        moved[FEATURES.index(f)] = float(np.clip(np.float32(v), lo, hi))  # a middle's float32 can fall past a bound
    return moved


@st.composite
def visiting_cases(draw: st.DrawFn, cls: type, max_size: int = 10) -> Example:
    """:func:`cases` whose states often enter the goal of one of the tree's nodes (any, in any order).

    Random states rarely enter a box goal, and more rarely its siblings' in
    their order, so an operator whose episode state is wrong only once its
    children's goals have been reached (a stage kept at module level) would pass
    on them. Each state is moved into the box of a node drawn for it
    (``Node.box``: a ``Goal``'s, an ``All``'s intersection), or kept (what it
    shrinks to).
    """
    case = draw(cases(cls, max_size))
    assert case.trajectory is not None
    boxes = _goal_boxes(case.tree)
    trajectory = []
    for state in case.trajectory:
        k = draw(st.integers(0, len(boxes)))  # 0: the state as drawn
        trajectory.append(state if k == 0 else _inside(boxes[k - 1], state))
    return case._replace(trajectory=f32(trajectory))


@st.composite
def refinement_cases(draw: st.DrawFn, cls: type[Node]) -> Example:
    """A ``Goal`` leaf, a refinement of it by ``cls`` (as the tree) and 1 to 8 states (as the trajectory)."""
    leaf = _goal(draw, "leaf")
    refinements = cls.refinements(leaf)
    assume(refinements is not None)
    assert refinements is not None
    states = f32(draw(st.lists(sgst.states(FEATURES), min_size=1, max_size=8)))
    return Example(draw(refinements), states, None, leaf)


# -- running a property and reporting its counterexample --------------------------


def value_text(v: float) -> str:
    """A float32 state value as its shortest exact text."""
    return str(np.float32(v)) if float(np.float32(v)) == v else repr(v)


def _example(case: Example) -> list[str]:
    lines = ["tree:", *(f"    {line}" for line in case.tree.pretty().splitlines())]
    if case.leaf is not None:
        lines[1:1] = [f"    (a refinement of the leaf {case.leaf.describe()})"]
    if case.trajectory is not None:
        what = "states" if case.actions is None else "trajectory (state s_t, then the action a_t taken in it)"
        lines += ["", f"{what}, features ({', '.join(FEATURES)}):"]
        for t, s in enumerate(case.trajectory):
            act = f"   a{t} = {case.actions[t]}" if case.actions is not None and t < len(case.actions) else ""
            lines.append(f"    s{t} = ({', '.join(value_text(v) for v in s)}){act}")
        if case.terminate:  # else it truncates there, its horizon
            lines.append(f"    (the base env terminates at s{len(case.trajectory) - 1}: a fall before its horizon)")
    return lines


def fail(check: Check, cls: type, case: Example, detail: str) -> NoReturn:
    """Raise the :class:`AssertionError` of ``check`` on ``cls``: the invariant, the example, what breaks it."""
    invariant = (check.__doc__ or check.__name__).strip().splitlines()[0]
    lines = [f"{check.__name__} failed for {cls.__name__}.", f"Invariant: {invariant}", "", *_example(case)]
    raise AssertionError("\n".join([*lines, "", f"What breaks it: {detail}"]))


def run_property(
    check: Check, cls: type, max_examples: int, body: Callable[[Example], None], examples: Any = None
) -> None:
    """Run ``body`` on examples (default: :func:`cases`); a :class:`Broken` or any error fails ``check`` readably.

    Hypothesis shrinks the failing example and re-raises the failure of the
    smallest one, so the message describes that one.
    """
    health = [HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large]

    @settings(
        max_examples=max_examples,
        deadline=None,
        derandomize=True,
        database=None,
        report_multiple_bugs=False,
        suppress_health_check=[*health, HealthCheck.large_base_example],
        phases=(Phase.explicit, Phase.reuse, Phase.generate, Phase.target, Phase.shrink),  # no explain: slow
    )
    @given(cases(cls) if examples is None else examples)
    def prop(case: Example) -> None:
        try:
            body(case)
        except Broken as e:
            fail(check, cls, case, str(e))
        except (AssertionError, HypothesisException):
            raise
        except Exception as e:
            fail(check, cls, case, f"evaluating the example raised {type(e).__name__}: {e}")

    try:
        prop()
    except FlakyFailure as e:
        # A failure that did not repeat on the same example: the operator's results depend on more than
        # the tree and the states (state kept on its class or at module level, across examples too).
        first = next((x for x in e.exceptions if isinstance(x, AssertionError)), None)
        if first is None:
            raise
        raise AssertionError(
            f"{first}\n(It did not repeat when the same example ran again: {cls.__name__}'s results depend on "
            "something outside the tree and the states, such as state kept on its class or at module level.)"
        ) from None


def step_name(t: int) -> str:
    """``after reset`` or ``after step t (...)``, as messages name a moment of the episode."""
    return "after reset (s0)" if t == 0 else f"after step {t} (s{t - 1} -> s{t}, action a{t - 1})"


# -- driving the env and the reference requirements ---------------------------------


def replay_env(tree: Node, trajectory: list[list[float]], evaluator: str = "flat", terminate: bool = False) -> SpecEnv:
    """The constructed env of ``tree`` over a :class:`~specguard.contract.replay.ReplayEnv` of ``trajectory``.

    Built as :func:`specguard.make_env` builds it, without its static checks:
    a goal no state can be in (an ``All`` of disjoint boxes) is a fine example here. ``terminate``: the
    replay ends by termination (:class:`~specguard.contract.replay.ReplayEnv`).
    """
    replay = ReplayEnv(trajectory, terminate=terminate)
    return SpecEnv(replay, tree=tree, features=FEATURES, evaluator=evaluator)  # type: ignore[arg-type]


class Step(NamedTuple):
    """What the env returned after reset (``reward`` None) or a step."""

    obs: np.ndarray
    reward: Any
    terminated: bool
    info: dict[str, Any]
    truncated: bool = False


def play(env: SpecEnv, actions: Sequence[int]) -> list[Step]:
    """Reset, then step until the episode ends: ``[reset, step 1, ...]``."""
    obs, info = env.reset(seed=0)
    steps = [Step(obs, None, False, info)]
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        steps.append(Step(obs, reward, terminated, info, truncated))
        if terminated or truncated:
            break
    return steps


def extended_states(
    tree: Node, trajectory: list[list[float]], actions: list[int], terminate: bool = False
) -> tuple[Requirements, list[Any]]:
    """The reference requirements and the extended states (true own states) along the trajectory.

    ``terminate``: the base env terminates at the trajectory's last state (:class:`Example`), a fall
    before the horizon where the root goal holds until the end.
    """
    req = process(tree)
    make = state_type(FEATURES)._make
    s = make(trajectory[0])
    xs = [ExtendedState(s, req.initial(s))]
    fall = terminate and until_end(tree)
    for t, (a, f) in enumerate(zip(actions, trajectory[1:]), 1):
        s2 = make(f)
        xs.append(ExtendedState(s2, req.transition(xs[-1], a, s2, fall and t == len(trajectory) - 1)))
    return req, xs


def context(req: Requirements, path: str, node: Node, x: Any) -> Context:
    """The node's :class:`Context` in the extended state ``x``: its own state and its children's memberships."""
    inside = tuple(req.goals[child_path(path, c.name)](x) for c in node.children)
    return Context(x.s, tuple(x.states.get(path, ())), inside)
