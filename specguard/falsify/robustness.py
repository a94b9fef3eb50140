"""How robustly an episode met its spec: a signed margin per goal and safety annotation, from the goal tree.

The falsifier's property is the spec's own: the root goal, each asserted goal
and each asserted safety annotation, judged as the env judges them. Its search
is steered by a *robustness score*, the smallest margin over those keys:

* a goal that is a box (:meth:`Node.box`) has the box's margin: per feature,
  the distance to the box's nearer side in units of the feature's scale
  (half its observation range where finite, else 1); the smallest inside
  (``>= 0``), minus the largest violation outside (``< 0``);
* any other node says its own (:meth:`specguard.extend.Node.margin`), given
  its children's; the default signs the children's smallest margin by
  membership, so a new operator has one without writing anything;
* a safety annotation says its own (:meth:`specguard.extend.Annotation.margin`),
  by default ``1`` without a violation and minus the violations with.

That is the default score, ``score="last"`` (:data:`SCORES`): each key's margin
in the episode's last state. ``score="episode"`` opts in to the score over the
whole episode, as signal temporal logic (STL) computes its quantitative
semantics (measured in docs/guide/falsify.md: not better on held-out agents,
and dearer per episode, hence not the default); it changes two things:

* a safety annotation that avoids a region of states
  (:meth:`specguard.extend.Annotation.avoids`, as ``Avoid``) has, without a
  violation, the state's distance from the region (the region's margin,
  negated; 0 inside it, where no step entered it);
* a key whose meaning is *throughout the episode* (:func:`over_episode`: a node
  that holds until the end, as ``Always``, and every safety annotation) has the
  **minimum of its margin over the episode's states** (:class:`EpisodeMinimum`,
  kept per row by the falsifier's runner): STL's robustness of "always phi" is
  the minimum over time of phi's, ``rho(G phi, w, 0) = min_t rho(phi, w, t)``.
  Taken from rtamt's discrete-time offline semantics (``AlwaysSemantics``: a
  minimum carried over the samples, whose value at time 0 is the whole trace's;
  a predicate ``x <= c`` scores ``c - x``, which a box's margin is per side). A
  kept ``Avoid`` is scored by its closest approach to its region, a balanced
  pole by its deepest dip, not by where the episode happened to end. Where an
  operator's goal at the end does not imply its goal at every state before (a
  union of an ``Always`` and a reach goal, met by the reach goal at the end), a
  met key keeps its last state's margin. FalStar (Ernst, Sedwards, Zhang, Hasuo)
  steers its adaptive search by the robustness of the trace so far.

With either score, the root goal, where reaching it ended the episode, has how
early it was reached instead (:func:`reached_early`): every such episode ends
just inside it, so its margin there says nothing, while an episode that needed
most of its steps was close to running out of them (STL's time robustness,
Donzé and Maler 2010); a reach goal otherwise keeps its last state's margin
(``F phi`` judged where the episode ends). The verdict is never the score's: a
key is missed exactly as the env reports it (``info["goals"]``,
``info["safe"]``), and the score only steers the search (the portfolio,
:mod:`~specguard.falsify.portfolio`). They agree in sign: a missed key's margin
is ``< 0`` and a met key's ``>= 0``.

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

from specguard.extend import SAFETY, Annotation, Box, Context, Node, annotation_key, until_end
from specguard.utils.node_paths import child_path

__all__ = [
    "SCORES",
    "EpisodeMinimum",
    "Judgement",
    "box_margin",
    "feature_scales",
    "judge_end",
    "margins",
    "over_episode",
    "own_states",
    "reached_early",
    "region_margin",
    "safety_margin",
]

SCORE_LIMIT = 1e6
"""Margins are clipped to ``+-SCORE_LIMIT`` (an open box is infinitely far inside)."""

SCORES = ("last", "episode")
"""The falsifier's scores (its ``score`` argument): ``"last"``, each key's margin in the episode's last state (the
default); ``"episode"``, over the whole episode (:class:`EpisodeMinimum`)."""


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
    *,
    regions: bool = False,
) -> dict[str, float]:
    """Every node's margin (by path) and every safety annotation's (by ``path:name``) in one state.

    Args:
        tree: the goal tree.
        s: the state's features.
        own: the own states by key (node path or annotation key), as the env kept them.
        goals: every node's membership of the state (``info["goals"]``).
        scales: per feature, the unit of its margins.
        regions: a safety annotation without a violation by its distance from the region it avoids
            (:func:`safety_margin`, ``score="episode"``); ``False``: by its own margin alone.
    """
    out: dict[str, float] = {}
    _visit(tree, tree.name, s, own, goals, scales, out, regions)
    return out


def _visit(
    node: Node,
    path: str,
    s: Any,
    own: Mapping[str, tuple[float, ...]],
    goals: Mapping[str, bool] | None,
    scales: Mapping[str, float],
    out: dict[str, float],
    regions: bool,
) -> tuple[Box | None, bool]:
    """``node``'s subtree's margins into ``out``; its box and membership (``goals``: as the env reported them;
    ``None``: from :meth:`Node.contains`, for a region without own state); ``regions``: as :func:`margins`."""
    kids = [(c, child_path(path, c.name)) for c in node.children]
    visited = [_visit(c, p, s, own, goals, scales, out, regions) for c, p in kids]
    inside = tuple(bool(goals[p]) for _, p in kids) if goals is not None else tuple(v[1] for v in visited)
    ctx = Context(s, own.get(path, ()), inside)
    box = node.box([v[0] for v in visited])
    out[path] = (
        box_margin(box, s, scales) if box is not None else _clipped(node.margin(ctx, tuple(out[p] for _, p in kids)))
    )
    for a in node.annotations:
        if a.role == SAFETY:
            key = annotation_key(path, a)
            q = own.get(key, ())
            out[key] = safety_margin(a, s, q, scales) if regions else _clipped(a.margin(s, q))
    return box, (bool(goals[path]) if goals is not None else bool(node.contains(ctx)))


def _clipped(margin: float) -> float:
    return float(np.clip(margin, -SCORE_LIMIT, SCORE_LIMIT))


def region_margin(region: Node, s: Any, scales: Mapping[str, float]) -> float:
    """The margin of state ``s`` in a region (a node without own state): ``>= 0`` inside, ``< 0`` outside.

    Example:
        >>> import specguard as sg
        >>> from specguard.construction.initial_env import state_type
        >>> edge = sg.Goal("edge", x=(2.0, None))
        >>> region_margin(edge, state_type(("x",))(1.5), {"x": 1.0})
        -0.5
    """
    out: dict[str, float] = {}
    _visit(region, region.name, s, {}, None, scales, out, True)
    return out[region.name]


def safety_margin(annotation: Annotation, s: Any, q: tuple[float, ...], scales: Mapping[str, float]) -> float:
    """A safety annotation's margin in ``(s, q)``: its own (:meth:`Annotation.margin`); where it has no violation
    and avoids a region (:meth:`Annotation.avoids`), how far ``s`` lies from that region (0 inside it).
    """
    m = _clipped(annotation.margin(s, q))
    region = annotation.avoids()
    if region is None or m < 0:
        return m
    return max(0.0, -region_margin(region, s, scales))


def over_episode(tree: Node, keys: Sequence[str]) -> tuple[str, ...]:
    """The keys among ``keys`` whose meaning is *throughout the episode*: every safety annotation, and every node
    that holds until the end (:func:`~specguard.extend.until_end`, as ``Always``).

    Example:
        >>> import specguard as sg
        >>> balance = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")
        >>> over_episode(balance, ["balance", "balance/upright"])
        ('balance',)
    """
    throughout = {p for p, n in tree.walk() if until_end(n)}
    throughout |= {annotation_key(p, a) for p, n in tree.walk() for a in n.annotations if a.role == SAFETY}
    return tuple(k for k in keys if k in throughout)


class EpisodeMinimum:
    """Per row of a batch of episodes, the running minimum of the margins of the keys judged over the whole
    episode (:func:`over_episode`), over the states after each step: ``min_t rho(phi, s_t)``.

    Only those keys' subtrees are walked at each step (a safety annotation: its own margin alone).

    Args:
        tree: the goal tree.
        keys: the asserted keys (those judged throughout are kept).
        scales: per feature, the unit of the margins.

    Example:
        >>> import specguard as sg
        >>> from specguard.construction.initial_env import state_type
        >>> tree = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")
        >>> low = EpisodeMinimum(tree, ["balance"], {"theta": 1.0})
        >>> low.start(1)
        >>> goals = {"balance": True, "balance/upright": True}
        >>> for theta in (0.0, 0.15, 0.05):  # the pole dips to 0.15, then recovers
        ...     low.update(0, state_type(("theta",))(theta), {"balance": (1.0,)}, goals)
        >>> round(low.rows[0]["balance"], 3)
        0.05
    """

    def __init__(self, tree: Node, keys: Sequence[str], scales: Mapping[str, float]) -> None:
        self.keys = over_episode(tree, keys)
        self.scales = scales
        nodes = dict(tree.walk())
        annotations = {annotation_key(p, a): a for p, n in tree.walk() for a in n.annotations if a.role == SAFETY}
        self._nodes = [(k, nodes[k]) for k in self.keys if k in nodes]
        self._annotations = [(k, annotations[k]) for k in self.keys if k in annotations]
        self.rows: list[dict[str, float]] = []
        """Per row, each key's lowest margin so far."""

    def start(self, n: int) -> None:
        """``n`` new episodes: nothing seen yet."""
        self.rows = [dict.fromkeys(self.keys, math.inf) for _ in range(n)]

    def update(self, row: int, s: Any, own: Mapping[str, tuple[float, ...]], goals: Mapping[str, bool]) -> None:
        """Row ``row``'s state after a step: each key's margin there lowers its minimum."""
        low = self.rows[row]
        out: dict[str, float] = {}
        for key, node in self._nodes:
            _visit(node, key, s, own, goals, self.scales, out, True)
            low[key] = min(low[key], out[key])
        for key, a in self._annotations:
            low[key] = min(low[key], safety_margin(a, s, own.get(key, ()), self.scales))


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
    lowest: Mapping[str, float] | None = None,
) -> Judgement:
    """The property at an episode's end: each of ``keys`` (goal paths, safety keys) met, with margins.

    ``lowest``: ``None`` (``score="last"``, the default), each key's margin in the last state; else
    (``score="episode"``) the keys judged over the whole episode and their lowest margins over its states
    (:class:`EpisodeMinimum`): each such key's margin is the lower of that and its last state's, unless the key
    was met and that is negative (a goal met at the end that did not hold before: its last state's margin), and a
    kept safety annotation that avoids a region is graded by its distance from it (:func:`safety_margin`).
    """
    every = margins(tree, s, own, goals, scales, regions=lowest is not None)
    missed = tuple(k for k in keys if not (goals[k] if k in goals else safe[k]))
    asserted = {k: every[k] for k in keys}
    for k, low in (lowest or {}).items():
        if k in asserted:
            over = min(asserted[k], low)
            asserted[k] = over if over >= 0 or k in missed else asserted[k]
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
