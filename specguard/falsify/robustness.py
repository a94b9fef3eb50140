"""How robustly an episode met its spec: a signed margin per goal and safety annotation, from the goal tree.

The falsifier's property is the spec's own: the root goal, each asserted goal
and each asserted safety annotation at the end of an episode. Its search is
steered by a *robustness score*, the smallest margin over those keys:

* a goal that is a box (:meth:`Node.box`) has the box's margin: per feature,
  the distance to the box's nearer side in units of the feature's scale
  (half its observation range where finite, else 1); the smallest inside
  (``>= 0``), minus the largest violation outside (``< 0``);
* any other node says its own (:meth:`specguard.extend.Node.margin`), given
  its children's; the default signs the children's smallest margin by
  membership, so a new operator has one without writing anything;
* a safety annotation says its own (:meth:`specguard.extend.Annotation.margin`),
  by default ``1`` without a violation and minus the violations with;
* the root goal, where reaching it ended the episode, has how early it was
  reached instead (:func:`reached_early`): every such episode ends just inside
  it, so its margin there says nothing, while an episode that needed most of
  its steps was close to running out of them.

Example:
    >>> import specguard as sg
    >>> from specguard.construction.initial_env import state_type
    >>> tree = sg.Goal("upright", theta=(-0.1, 0.1))
    >>> s = state_type(("x", "theta"))(0.0, 0.05)
    >>> margins(tree, s, {}, {"upright": True}, {"theta": 0.5})["upright"]
    0.1
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from specguard.extend import SAFETY, Box, Context, Node, annotation_key
from specguard.utils.node_paths import child_path

__all__ = ["Judgement", "box_margin", "feature_scales", "judge_end", "margins", "own_states", "reached_early"]

SCORE_LIMIT = 1e6
"""Margins are clipped to ``+-SCORE_LIMIT`` (an open box is infinitely far inside)."""


def feature_scales(features: Sequence[str], low: np.ndarray, high: np.ndarray) -> dict[str, float]:
    """Per feature, half its range where both bounds are finite (and apart), else 1."""
    out = {}
    for f, lo, hi in zip(features, low, high, strict=True):
        width = float(hi) - float(lo)
        out[f] = width / 2.0 if math.isfinite(width) and width > 0 else 1.0
    return out


def box_margin(box: Box, s: Any, scales: Mapping[str, float]) -> float:
    """The signed margin of features ``s`` in ``box``: ``>= 0`` inside (its nearest side), ``< 0`` outside."""
    worst = -math.inf  # per feature max(lo - v, v - hi): <= 0 inside (minus the distance to the nearer side)
    for f, (lo, hi) in box.items():
        v = float(getattr(s, f))
        worst = max(worst, max(lo - v, v - hi) / scales.get(f, 1.0))
    return float(np.clip(-worst, -SCORE_LIMIT, SCORE_LIMIT))


def margins(
    tree: Node,
    s: Any,
    own: Mapping[str, tuple[float, ...]],
    goals: Mapping[str, bool],
    scales: Mapping[str, float],
) -> dict[str, float]:
    """Every node's margin (by path) and every safety annotation's (by ``path:name``) in the last state.

    Args:
        tree: the goal tree.
        s: the last state's features.
        own: the own states by key (node path or annotation key), as the env kept them.
        goals: every node's membership of the last state (``info["goals"]``).
        scales: per feature, the unit of its margins.
    """
    out: dict[str, float] = {}

    def visit(node: Node, path: str) -> Box | None:
        kids = [(c, child_path(path, c.name)) for c in node.children]
        boxes = [visit(c, p) for c, p in kids]
        box = node.box(boxes)
        if box is not None:
            m = box_margin(box, s, scales)
        else:
            ctx = Context(s, own.get(path, ()), tuple(bool(goals[p]) for _, p in kids))
            m = float(np.clip(node.margin(ctx, tuple(out[p] for _, p in kids)), -SCORE_LIMIT, SCORE_LIMIT))
        out[path] = m
        for a in node.annotations:
            if a.role == SAFETY:
                key = annotation_key(path, a)
                out[key] = float(np.clip(a.margin(s, own.get(key, ())), -SCORE_LIMIT, SCORE_LIMIT))
        return box

    visit(tree, tree.name)
    return out


def own_states(slots: Iterable[tuple[str, Any]], values: Sequence[float]) -> dict[str, tuple[float, ...]]:
    """An evaluator's own-state slots grouped by key (node path or annotation key)."""
    grouped: dict[str, list[float]] = {}
    for (key, _), v in zip(slots, values, strict=True):
        grouped.setdefault(key, []).append(float(v))
    return {k: tuple(v) for k, v in grouped.items()}


@dataclass(frozen=True)
class Judgement:
    """One episode's end, judged by the spec's property.

    Attributes:
        missed: the asserted keys the episode missed (empty: it met the spec).
        score: the smallest margin over the asserted keys (the search minimises it).
        margins: every asserted key's margin.
    """

    missed: tuple[str, ...]
    score: float
    margins: Mapping[str, float]


def judge_end(
    tree: Node,
    keys: Sequence[str],
    s: Any,
    own: Mapping[str, tuple[float, ...]],
    goals: Mapping[str, bool],
    safe: Mapping[str, bool],
    scales: Mapping[str, float],
) -> Judgement:
    """The property at an episode's end: each of ``keys`` (goal paths, safety keys) met, with margins."""
    every = margins(tree, s, own, goals, scales)
    missed = tuple(k for k in keys if not (goals[k] if k in goals else safe[k]))
    asserted = {k: every[k] for k in keys}
    return Judgement(missed, min(asserted.values()), asserted)


def reached_early(judgement: Judgement, root: str, steps: int, limit: int) -> Judgement:
    """``judgement`` with the root goal's margin replaced by how early it was reached: ``1 - steps / limit``.

    For an episode that ended because it reached the root goal (it ends just
    inside it, whatever the start): a time robustness, in the spirit of signal
    temporal logic's. Unchanged where the root is not asserted or was missed.

    Example:
        >>> j = Judgement((), 0.01, {"home": 0.01, "home:safe": 1.0})
        >>> reached_early(j, "home", 150, 200).margins["home"]
        0.25
        >>> reached_early(j, "home", 150, 200).score
        0.25
    """
    if root not in judgement.margins or root in judgement.missed:
        return judgement
    margins = {**judgement.margins, root: max(0.0, 1.0 - steps / limit)}
    return Judgement(judgement.missed, min(margins.values()), margins)
