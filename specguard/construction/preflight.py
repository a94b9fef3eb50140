"""Static checks of a goal tree against its initial env, run before anything trains.

Like Gymnasium's ``env_checker``: each ``check_*`` function states one
invariant, raises (or warns) with the node path when it does not hold, and
returns nothing otherwise. :func:`check_goals` runs them all on a compiled
tree; ``make_env`` and ``make_baseline_env`` call it (their preflight,
:class:`specguard.construction.env.EnvFactory`), so ``run_spec`` refuses an
impossible spec before training.

One check is dynamic: :func:`check_starts` judges the root goal on
:data:`START_SAMPLES` seeded resets of the env. A reach goal met at them is met
before the agent acts (:func:`check_root_goal_not_met_at_start`, the mirror of an
unreachable goal); a goal that must hold until the end and holds at none of them
fails before the agent acts (:func:`check_root_goal_holds_at_start`).

Nodes whose goal is a box (a ``Goal``; an ``All``'s is the intersection of
its children's) are checked; a node whose goal is not a box (an ``AnyOf``, a
``Sequence``) is unbounded here. Every feature has bounds, finite where they are known
(:meth:`specguard.InitialEnv.feature_bounds`). Boxes are compared at float32
precision, the precision of the observations: CartPole's bound of ``x`` is
``float32(4.8)``, and a goal ``x=(4.8, None)`` meets it exactly.

Example:
    >>> import specguard as sg
    >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    >>> sg.make_env(cartpole, sg.Goal("far", x=(10, None)))
    Traceback (most recent call last):
    ...
    specguard.error.UnreachableGoal: far: goal box x in [10, inf] lies outside the bounds of x, [-4.8, 4.8]: ...
    Hint: ...
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from specguard.construction.compiled import CompiledTree, compile_tree
from specguard.error import GoalMetAtStart, SpecWarning, UnreachableGoal, user_stacklevel
from specguard.tree.nodes import Node
from specguard.utils.text import bounds_text

__all__ = [
    "START_SAMPLES",
    "check_goals",
    "check_goals_off_the_edge",
    "check_goals_reachable",
    "check_root_goal_holds_at_start",
    "check_root_goal_not_met_at_start",
    "check_starts",
    "episode_limit",
    "unreachable_reason",
]


def _f32(values: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore"):
        return np.asarray(values, dtype=np.float64).astype(np.float32)


def _within(compiled: CompiledTree, low: ArrayLike, high: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Every node's box intersected with the bounds, at float32 precision: ``(nodes, features)`` each."""
    lo = np.maximum(_f32(compiled.lo), _f32(np.asarray(low))[None, :])
    hi = np.minimum(_f32(compiled.hi), _f32(np.asarray(high))[None, :])
    return lo, hi


def _innermost(compiled: CompiledTree, flagged: np.ndarray) -> list[int]:
    """The flagged nodes none of whose children is flagged (the one to blame, not its ancestors)."""
    return [i for i in range(len(compiled.paths)) if flagged[i] and not any(flagged[k] for k in compiled.children[i])]


def _unreachable(compiled: CompiledTree, low: ArrayLike, high: ArrayLike, node: int) -> tuple[str, str] | None:
    """``(message, hint)`` when node ``node``'s box misses the bounds on some feature, else None."""
    lo, hi = _within(compiled, low, high)
    empty = np.flatnonzero(lo[node] > hi[node])
    if not len(empty):
        return None
    j = int(empty[0])
    f = compiled.features[j]
    box_lo, box_hi = float(compiled.lo[node, j]), float(compiled.hi[node, j])
    bounds = bounds_text(float(_f32(np.asarray(low))[j]), float(_f32(np.asarray(high))[j]))
    if box_lo > box_hi:
        message = (
            f"its children's boxes do not overlap on {f}: their intersection {bounds_text(box_lo, box_hi)} is empty "
            f"(the bounds of {f} are {bounds}), so no state can be in this goal"
        )
        hint = "an All's goal is the intersection of its children's goals; widen them so they overlap on " + repr(f)
    else:
        message = (
            f"goal box {f} in {bounds_text(box_lo, box_hi)} lies outside the bounds of {f}, {bounds}: "
            "no state can be in it, so training would be for nothing"
        )
        hint = (
            f"move the box of {f!r} inside {bounds}; if a state() feature can go further, "
            "declare its range with InitialEnv(bounds=...)"
        )
    return message, hint


def check_goals_reachable(compiled: CompiledTree, low: ArrayLike, high: ArrayLike) -> None:
    """Every node's box (an ``All``'s: the intersection) meets the feature bounds on every feature.

    A node below an operator whose goal is not a box (an OR, a sequence) only
    warns: the operator may hold without it.

    Raises:
        UnreachableGoal: for the innermost node whose box lies outside the bounds
            when every ancestor's goal is a box within it (so the root can never hold).
    """
    lo, hi = _within(compiled, low, high)
    parent = {k: i for i, kids in enumerate(compiled.children) for k in kids}
    for node in _innermost(compiled, np.asarray((lo > hi).any(axis=1))):
        found = _unreachable(compiled, low, high, node)
        assert found is not None
        escape = _first_ancestor_without_a_box(compiled, parent, node)
        if escape is None:  # every ancestor is a box inside this one's: the root can never hold either
            raise UnreachableGoal(compiled.paths[node], *found)
        warnings.warn(
            f"{compiled.paths[node]}: {found[0]}; {compiled.paths[escape]} is not a box and may still hold "
            "without it (e.g. through another alternative of an OR)",
            SpecWarning,
            stacklevel=user_stacklevel(),  # the caller of make_env
        )


def _first_ancestor_without_a_box(compiled: CompiledTree, parent: dict[int, int], node: int) -> int | None:
    """The nearest ancestor whose goal is not a box (an ``AnyOf``, a ``Sequence``), or None."""
    while node in parent:
        node = parent[node]
        if not compiled.boxed[node]:
            return node
    return None


def check_goals_off_the_edge(compiled: CompiledTree, low: ArrayLike, high: ArrayLike) -> None:
    """No node's box meets the feature bounds only at their edge (zero width exactly at a bound).

    Such a goal is reachable only where the observation is clipped or the
    episode ends (CartPole's ``x`` at 4.8); it warns once, naming every such
    node. An exact value (``leg=1`` on a 0/1 contact flag) is deliberate and passes.
    """
    lo, hi = _within(compiled, low, high)
    b_lo, b_hi = _f32(np.asarray(low))[None, :], _f32(np.asarray(high))[None, :]
    # An exact value (leg=1 on a 0/1 contact) is asked for on purpose: only a box of positive width
    # that the bounds clip to one point is suspicious.
    wide = _f32(compiled.lo) < _f32(compiled.hi)
    edge = (lo == hi) & ((lo == b_lo) | (hi == b_hi)) & (b_lo < b_hi) & wide
    names = []
    for node in _innermost(compiled, np.asarray(edge.any(axis=1))):
        for j in np.flatnonzero(edge[node]):
            f = compiled.features[j]
            box = bounds_text(float(compiled.lo[node, j]), float(compiled.hi[node, j]))
            names.append(
                f"{compiled.paths[node]} ({f} in {box} meets the bounds {bounds_text(b_lo[0, j], b_hi[0, j])} "
                f"only at {float(lo[node, j]):g})"
            )
    if names:
        warnings.warn(
            "goals reachable only at the edge of the feature bounds: "
            + "; ".join(names)
            + ". Widen the box into the bounds unless the edge is the point",
            SpecWarning,
            stacklevel=user_stacklevel(),  # the caller of make_env
        )


def check_goals(compiled: CompiledTree, low: ArrayLike, high: ArrayLike) -> None:
    """Every static check of a compiled tree over features with bounds ``low``/``high``.

    Raises:
        UnreachableGoal: a goal no state can be in.
    """
    check_goals_reachable(compiled, low, high)
    check_goals_off_the_edge(compiled, low, high)


START_SAMPLES = 32
"""Seeded resets (seeds ``0 .. START_SAMPLES - 1``) on which the root goal is judged before training.

A few milliseconds for most envs; enough that a goal met at every one of them is met at (nearly) every start.
"""

_START_HINT = (
    "reaching the root goal ends an episode, so it must be reached from outside it: widen the env's starts "
    "(reset options, or a factory that starts elsewhere), or state a goal the starts do not meet. A goal that "
    "must hold until the episode ends is sg.Always(goal, name=...): it ends nothing and is judged at the last state"
)
_HOLD_HINT = (
    "a goal that must hold until the end (sg.Always) holds at every state of the episode, the first included: "
    "widen it to take in the env's starts, or state a reach goal (the goal alone, without Always) if it is to be "
    "reached rather than kept"
)


def check_starts(compiled: CompiledTree, inside: int, samples: int) -> None:
    """The root goal judged at the sampled starts (``inside`` of ``samples`` seeded resets were in it).

    A reach goal by :func:`check_root_goal_not_met_at_start`, a goal that holds until the end
    by :func:`check_root_goal_holds_at_start`.
    """
    if compiled.reach:
        check_root_goal_not_met_at_start(compiled, inside, samples)
    else:
        check_root_goal_holds_at_start(compiled, inside, samples)


def check_root_goal_not_met_at_start(compiled: CompiledTree, inside: int, samples: int) -> None:
    """The root goal holds at no sampled start (``inside`` of ``samples`` seeded resets were in it).

    Reaching the root goal ends an episode: an env that starts inside it gives
    one-step episodes whose success owes nothing to the policy.

    Raises:
        GoalMetAtStart: the root goal holds at every sampled start.

    Warns:
        SpecWarning: it holds at some of them, with their share.
    """
    root = compiled.paths[0]
    if samples and inside == samples:
        raise GoalMetAtStart(
            root,
            f"the root goal holds at all {inside} of {samples} sampled starts (seeded resets), so every episode "
            "would end at its first step and the spec would pass without the agent learning anything",
            _START_HINT,
        )
    if inside:
        warnings.warn(
            f"{root} holds at {inside} of {samples} sampled starts ({inside / samples:.0%}): the episodes that "
            "start there end at their first step and count as successes whatever the policy does. "
            f"Hint: {_START_HINT}",
            SpecWarning,
            stacklevel=user_stacklevel(),  # the caller of make_env
        )


def check_root_goal_holds_at_start(compiled: CompiledTree, inside: int, samples: int) -> None:
    """A root goal that must hold until the end holds at some sampled start (``inside`` of ``samples``).

    It must hold at every state, the first included: an episode that starts
    outside it has failed before the policy acts.

    Raises:
        UnreachableGoal: it holds at no sampled start, so every episode fails whatever the policy does.

    Warns:
        SpecWarning: it fails at some of them, with their share.
    """
    root, outside = compiled.paths[0], samples - inside
    if samples and outside == samples:
        raise UnreachableGoal(
            root,
            f"the root goal must hold until the end (from the first state on), and it holds at none of {samples} "
            "sampled starts (seeded resets), so every episode would fail before the agent acts",
            _HOLD_HINT,
        )
    if samples and outside:
        warnings.warn(
            f"{root} must hold until the end and fails at {outside} of {samples} sampled starts "
            f"({outside / samples:.0%}): the episodes that start there fail whatever the policy does. "
            f"Hint: {_HOLD_HINT}",
            SpecWarning,
            stacklevel=user_stacklevel(),  # the caller of make_env
        )


def episode_limit(env: Any) -> int | None:
    """The env's episode step limit: the outermost ``TimeLimit``'s among its wrappers, else its spec's, else None."""
    inner = env
    while inner is not None:
        limit = getattr(inner, "_max_episode_steps", None)
        if isinstance(limit, int) and not isinstance(limit, bool) and limit > 0:
            return limit
        inner = getattr(inner, "env", None)
    spec = getattr(env, "spec", None)
    limit = getattr(spec, "max_episode_steps", None)
    return limit if isinstance(limit, int) and not isinstance(limit, bool) and limit > 0 else None


def unreachable_reason(initial_env: Any, tree: Node, path: str) -> str | None:
    """Why goal ``path`` of ``tree`` can never be reached in ``initial_env``, or None when it can be.

    Builds the base env for its observation space; None too when that fails.
    """
    try:
        base = initial_env.make()
        try:
            low, high = initial_env.feature_bounds(base.observation_space)
        finally:
            base.close()
        compiled = compile_tree(tree, initial_env.features)
    except Exception:  # a hint, not a verdict: no hint rather than a second error
        return None
    if path not in compiled.paths:
        return None
    found = _unreachable(compiled, low, high, compiled.paths.index(path))
    return None if found is None else found[0]
