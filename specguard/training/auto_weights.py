"""Automatic weights: ``All(weights="auto")`` adapted to its outcomes' observed success during training.

The paper leaves an AND-node's weights to the user, who tunes them by hand
when one subgoal crowds out another (Pendulum (w): position 0.8,
stabilization 0.2). ``weights="auto"`` does that tuning from what the run
observes, by this rule (our choice, beyond the paper; docs/semantics.md, "Automatic weights"):

    w_i = (1 - p_i + FLOOR) / sum_j (1 - p_j + FLOOR)

over the node's *outcomes*: each child, with ``p_i`` the share of the last
:data:`WINDOW` finished training episodes whose last state lies in its goal,
and each safety annotation of the node itself left at its default weight
(``Constraint(fn)`` on the ``All``, not ``Constraint(fn, weight=...)``),
with ``p_i`` the share of those episodes without a violation: the very
measures the gate judges, observed on the training policy. An outcome the
agent already reaches loses weight to the ones it misses; :data:`FLOOR` keeps
a reached outcome's weight above zero, so the agent is still paid for keeping
it; when every outcome is reached (or none is) the weights are equal.

Why constraints take part: a penalty of fixed weight 1 beside goals whose
weights sum to 1 can outweigh them all, and an agent that learns to be safe
first (LunarLander: hovering is never a crash) then never risks the goal.
Letting a constraint kept in nearly every episode hand its weight to the
goals still missed is the Lagrangian idea of constrained RL (the penalty
grows while the constraint is violated, shrinks while it holds), on the same
bounded shares as the children. A constraint's budget still ends the episode
at 0 whatever its weight.

Why success rather than each component's reward scale: the conflict the
weights resolve is one of *outcomes* (the pendulum hangs still, reaching
stabilization and never the position), which success measures directly
and scales do not; and success is bounded, so the rule needs no tuning of
its own. The weights sum to 1, so the node's reward keeps its scale relative
to its siblings. Until :data:`MIN_EPISODES` episodes have finished, the
node's own weights hold: ``1/N`` per child, 1 per constraint.

Weights change only between episodes (the env applies new ones at its next
``reset``, :meth:`specguard.construction.env.SpecEnv.set_weights`): within an episode
shaping telescopes and enter/exit rewards cancel only under constant
weights (docs/semantics.md, "Potential-based shaping"). The env built from the tree alone keeps ``1/N``
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
from collections.abc import Mapping, Sequence

from specguard.extend import Node, adapted_annotations, annotation_key, component_weights
from specguard.utils.node_paths import child_path

__all__ = [
    "FLOOR",
    "MIN_EPISODES",
    "WINDOW",
    "WeightAdapter",
    "adapted_weights",
    "adapting_nodes",
    "initial_weights",
]

WINDOW = 100  # episodes the success shares are measured over
MIN_EPISODES = 10  # fewer finished episodes say too little to move the weights
FLOOR = 0.1  # a reached outcome keeps FLOOR / (sum) of the weight


def adapted_weights(rates: Sequence[float]) -> tuple[float, ...]:
    """The rule above: weights from the outcomes' success shares ``rates`` (each in ``[0, 1]``).

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
    """Per path of a node that adapts its weights, its outcomes' keys, in order.

    Its children's paths, then the keys (``path:name``) of its adapted safety
    annotations (:func:`adapted_annotations`): the order of the weights.
    """
    return {
        path: tuple(child_path(path, c.name) for c in node.children)
        + tuple(annotation_key(path, node.annotations[i]) for i in adapted_annotations(node))
        for path, node in tree.walk()
        if node.adapts_weights
    }


def initial_weights(node: Node) -> tuple[float, ...]:
    """A node's own weights in :func:`adapting_nodes`'s order: its children's, then its adapted annotations'."""
    annotation_weights = component_weights(node)[1]
    return tuple(w.core for w in node.child_weights()) + tuple(annotation_weights[i] for i in adapted_annotations(node))


class WeightAdapter:
    """Success shares of the outcomes of every adapting node, over a window of finished episodes.

    Args:
        nodes: per adapting node's path, its outcomes' keys (:func:`adapting_nodes`).
        initial: per adapting node's path, its weights before any adaptation (:func:`initial_weights`).
        window: how many of the latest finished episodes the shares are measured over.
    """

    def __init__(
        self,
        nodes: Mapping[str, Sequence[str]],
        initial: Mapping[str, Sequence[float]],
        window: int = WINDOW,
    ) -> None:
        self.nodes = {path: tuple(outcomes) for path, outcomes in nodes.items()}
        # The weights before any adaptation (the node's own, 1/N for "auto"), and then the latest ones.
        self.in_force: dict[str, tuple[float, ...]] = {path: tuple(initial[path]) for path in self.nodes}
        self._outcomes = tuple(dict.fromkeys(c for cs in self.nodes.values() for c in cs))
        self._episodes: deque[tuple[bool, ...]] = deque(maxlen=window)

    @classmethod
    def of(cls, tree: Node, window: int = WINDOW) -> WeightAdapter | None:
        """The adapter of ``tree``, or ``None`` when no node of it adapts its weights."""
        nodes = adapting_nodes(tree)
        if not nodes:
            return None
        initial = {path: initial_weights(node) for path, node in tree.walk() if path in nodes}
        return cls(nodes, initial, window)

    def observe(self, goals: Mapping[str, bool], safe: Mapping[str, bool] | None = None) -> None:
        """Add one finished episode: ``info["goals"]`` and ``info["safe"]`` of its last step."""
        outcomes = {**goals, **(safe or {})}
        self._episodes.append(tuple(bool(outcomes[c]) for c in self._outcomes))

    def rates(self) -> dict[str, float]:
        """Per outcome key, the share of the window's episodes that ended in its goal (or without a violation)."""
        n = len(self._episodes)
        return {c: sum(e[i] for e in self._episodes) / n if n else 0.0 for i, c in enumerate(self._outcomes)}

    def weights(self) -> dict[str, tuple[float, ...]] | None:
        """The adapted weights per node, or ``None`` while fewer than :data:`MIN_EPISODES` episodes finished."""
        if len(self._episodes) < MIN_EPISODES:
            return None
        rates = self.rates()
        return {path: adapted_weights([rates[c] for c in outcomes]) for path, outcomes in self.nodes.items()}

    def in_force_lists(self) -> dict[str, list[float]]:
        """:attr:`in_force` as plain JSON data, as results and curve points record it."""
        return {path: list(w) for path, w in self.in_force.items()}

    def update(self) -> dict[str, tuple[float, ...]] | None:
        """:meth:`weights`, which then become :attr:`in_force`; ``None`` (nothing changes) while too few episodes."""
        weights = self.weights()
        if weights is not None:
            self.in_force = weights
        return weights
