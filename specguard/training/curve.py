"""A run's learning curve: success per goal over finished training episodes, a point at a time.

Plain data, filled by the SB3 callbacks of a training run
(:mod:`specguard.training.callback`) and tested without them: finished
episodes are counted into the open period, and a point closes it.

Example:
    >>> curve = GoalCurve()
    >>> curve.count({"goals": {"root": True}})
    >>> curve.count({"goals": {"root": False}, "safe": {"root:cool": True}})
    >>> curve.point(100)
    >>> curve.points
    [{'timesteps': 100, 'episodes': 2, 'success': {'root': 0.5, 'root:cool': 0.5}}]
    >>> curve.evaluated(100, {"root": 27}, episodes=30)
    >>> curve.points[-1]["evaluation"], curve.points[-1]["evaluation_episodes"]
    ({'root': 0.9}, 30)
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from specguard.evaluation.episodes import count_episode

if TYPE_CHECKING:
    from specguard.training.auto_weights import WeightAdapter

__all__ = ["GoalCurve", "root_success"]


def root_success(success: Mapping[str, float]) -> float | None:
    """The root goal's success in a point's ``success`` (the root's goal comes first), or ``None`` when empty."""
    return next(iter(success.values()), None)


class GoalCurve:
    """Success per goal over finished training episodes: one point per period of training.

    A point (``{"timesteps", "episodes", "success"}``) holds the rates over the
    episodes finished since the previous point, goals by path, then safety by
    ``path:name``; with an ``adapter`` (``weights="auto"``) it also records the
    weights in force (:mod:`specguard.training.auto_weights`) under
    ``"weights"``. An evaluation at a step is stored in that step's point
    under ``"evaluation"`` (:meth:`evaluated`).

    Args:
        adapter: the run's weight adapter, read for the weights in force, or ``None``.
    """

    def __init__(self, adapter: WeightAdapter | None = None) -> None:
        self.adapter = adapter
        self.points: list[dict[str, Any]] = []
        self.counts: dict[str, int] = {}  # the open period's: since the last point
        self.episodes = 0

    def count(self, info: Mapping[str, Any]) -> None:
        """Count one finished episode (its last ``info``) into the open period."""
        self.episodes += 1
        count_episode(self.counts, info)

    def success(self) -> dict[str, float]:
        """The open period's rates per goal and safety key (empty before its first episode)."""
        return {key: c / self.episodes for key, c in self.counts.items()} if self.episodes else {}

    def point(self, num_timesteps: int) -> None:
        """Close the open period with a point at ``num_timesteps``."""
        self._append(num_timesteps, self.episodes, self.success())
        self.counts, self.episodes = {}, 0

    def evaluated(self, num_timesteps: int, counts: Mapping[str, int], episodes: int) -> None:
        """Record an evaluation at ``num_timesteps`` in the curve (a point of its own if none is there)."""
        if not self.points or self.points[-1]["timesteps"] != num_timesteps:
            self._append(num_timesteps, 0, {})
        self.points[-1]["evaluation"] = {p: c / episodes for p, c in counts.items()}
        self.points[-1]["evaluation_episodes"] = episodes

    def _append(self, num_timesteps: int, episodes: int, rates: dict[str, float]) -> None:
        point: dict[str, Any] = {"timesteps": num_timesteps, "episodes": episodes, "success": rates}
        if self.adapter is not None:
            point["weights"] = self.adapter.in_force_lists()
        self.points.append(point)
