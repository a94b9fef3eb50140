"""Automatic weights: ``All(weights="auto")`` adapted to its children's observed success during training.

The paper leaves an AND-node's weights to the user, who tunes them by hand
when one subgoal crowds out another (Pendulum (w): position 0.8,
stabilization 0.2). ``weights="auto"`` does that tuning from what the run
observes, by this rule (our choice, beyond SPEC.md):

    w_i = (1 - p_i + FLOOR) / sum_j (1 - p_j + FLOOR)

where ``p_i`` is the share of the last :data:`WINDOW` finished training
episodes whose last state lies in child ``i``'s goal: the very measure the
gate judges, observed on the training policy. A child the agent already
reaches loses weight to the ones it misses; :data:`FLOOR` keeps a reached
child's weight above zero, so the agent is still paid for keeping it; when
every child is reached (or none is) the weights are equal, ``1/N``.

Why success rather than each component's reward scale: the conflict the
weights resolve is one of *outcomes* (the pendulum hangs still, reaching
stabilization and never the position), which success measures directly
and scales do not; and success is bounded, so the rule needs no tuning of
its own. The weights sum to 1 like the default ``1/N``, so the node's reward
keeps its scale relative to its siblings and to constraints.

Weights change only between episodes (the env applies new ones at its next
``reset``, :meth:`specguard.env.SpecEnv.set_weights`): within an episode
shaping telescopes and enter/exit rewards cancel only under constant
weights (SPEC.md section 6). The env built from the tree alone keeps ``1/N``
and is what evaluation uses; success does not depend on weights, so
evaluation stays a pure function of the spec. The weights in force are
recorded in each learning-curve point and in the run's result.

Example:
    >>> import specguard as sg
    >>> tree = sg.All(sg.Goal("up", x=(0.9, 1)), sg.Goal("still", v=(-0.1, 0.1)), name="p", weights="auto")
    >>> adapter = WeightAdapter.of(tree)
    >>> for _ in range(20):  # it hangs still: "still" reached, "up" not
    ...     adapter.observe({"p": False, "p/up": False, "p/still": True})
    >>> adapter.weights()
    {'p': (0.9166666666666666, 0.08333333333333333)}
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping, Sequence

from specguard.extend import Node
from specguard.validation import PATH_SEPARATOR

__all__ = [
    "FLOOR",
    "MIN_EPISODES",
    "WINDOW",
    "WeightAdapter",
    "adapted_weights",
    "adapting_nodes",
    "per_seed_text",
    "weights_text",
]

WINDOW = 100  # episodes the success shares are measured over
MIN_EPISODES = 10  # fewer finished episodes say too little to move the weights
FLOOR = 0.1  # a reached child keeps FLOOR / (sum) of the weight


def adapted_weights(rates: Sequence[float]) -> tuple[float, ...]:
    """The rule above: weights from the children's success shares ``rates`` (each in ``[0, 1]``).

    Example:
        >>> adapted_weights([0.0, 1.0])
        (0.9166666666666666, 0.08333333333333333)
        >>> adapted_weights([0.5, 0.5])
        (0.5, 0.5)
    """
    raw = [1.0 - p + FLOOR for p in rates]
    total = sum(raw)
    return tuple(r / total for r in raw)


def adapting_nodes(tree: Node) -> dict[str, tuple[str, ...]]:
    """Per path of a node that adapts its weights, its children's paths, in order."""
    return {
        path: tuple(f"{path}{PATH_SEPARATOR}{c.name}" for c in node.children)
        for path, node in tree.walk()
        if node.adapts_weights
    }


def weights_text(weights: Mapping[str, Sequence[float]]) -> str:
    """Adapted weights as read in a report: ``pendulum (0.71, 0.29)``, nodes separated by ``; ``.

    Example:
        >>> weights_text({"pendulum": [0.714285, 0.285714]})
        'pendulum (0.71, 0.29)'
    """
    return "; ".join(f"{path} ({', '.join(f'{w:.2f}' for w in ws)})" for path, ws in weights.items())


def per_seed_text(seeds: Iterable[tuple[int, Mapping[str, Sequence[float]]]]) -> str:
    """Each seed's adapted weights: ``seed 0 pendulum (0.71, 0.29), seed 1 ...`` (seeds without any left out).

    Example:
        >>> per_seed_text([(0, {"p": [0.75, 0.25]}), (1, {})])
        'seed 0 p (0.75, 0.25)'
    """
    return ", ".join(f"seed {seed} {weights_text(weights)}" for seed, weights in seeds if weights)


class WeightAdapter:
    """Success shares of the children of every adapting node, over a window of finished episodes.

    Args:
        nodes: per adapting node's path, its children's paths (:func:`adapting_nodes`).
        window: how many of the latest finished episodes the shares are measured over.
    """

    def __init__(
        self,
        nodes: Mapping[str, Sequence[str]],
        initial: Mapping[str, Sequence[float]],
        window: int = WINDOW,
    ) -> None:
        self.nodes = {path: tuple(children) for path, children in nodes.items()}
        # The weights before any adaptation (the node's own, 1/N for "auto"), and then the latest ones.
        self.in_force: dict[str, tuple[float, ...]] = {path: tuple(initial[path]) for path in self.nodes}
        self._children = tuple(dict.fromkeys(c for cs in self.nodes.values() for c in cs))
        self._episodes: deque[tuple[bool, ...]] = deque(maxlen=window)

    @classmethod
    def of(cls, tree: Node, window: int = WINDOW) -> WeightAdapter | None:
        """The adapter of ``tree``, or ``None`` when no node of it adapts its weights."""
        nodes = adapting_nodes(tree)
        if not nodes:
            return None
        initial = {path: tuple(w.core for w in node.child_weights()) for path, node in tree.walk() if path in nodes}
        return cls(nodes, initial, window)

    def observe(self, goals: Mapping[str, bool]) -> None:
        """Add one finished episode: ``info["goals"]`` of its last step."""
        self._episodes.append(tuple(bool(goals[c]) for c in self._children))

    def rates(self) -> dict[str, float]:
        """Per child path, the share of the window's episodes that ended in its goal."""
        n = len(self._episodes)
        return {c: sum(e[i] for e in self._episodes) / n if n else 0.0 for i, c in enumerate(self._children)}

    def weights(self) -> dict[str, tuple[float, ...]] | None:
        """The adapted weights per node, or ``None`` while fewer than :data:`MIN_EPISODES` episodes finished."""
        if len(self._episodes) < MIN_EPISODES:
            return None
        rates = self.rates()
        return {path: adapted_weights([rates[c] for c in children]) for path, children in self.nodes.items()}

    def in_force_lists(self) -> dict[str, list[float]]:
        """:attr:`in_force` as plain JSON data, as results and curve points record it."""
        return {path: list(w) for path, w in self.in_force.items()}

    def update(self) -> dict[str, tuple[float, ...]] | None:
        """:meth:`weights`, which then become :attr:`in_force`; ``None`` (nothing changes) while too few episodes."""
        weights = self.weights()
        if weights is not None:
            self.in_force = weights
        return weights
