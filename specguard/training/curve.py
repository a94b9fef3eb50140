"""A run's learning curve: success per goal over finished training episodes, its checkpoints, and its caps.

Plain logic, stepped by the SB3 callback (:mod:`specguard.training.callback`) and
tested without it.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

from specguard.parallel.protocol import Report
from specguard.training.auto_weights import WeightAdapter
from specguard.training.progress import encode_update

__all__ = ["TICKS", "GoalCurve", "Look", "count_episode"]


def count_episode(counts: dict[str, int], info: Mapping[str, Any]) -> None:
    """Add one finished episode's last ``info``: its goals (by path), then its safety (by ``path:name``)."""
    for key, ok in info["goals"].items():
        counts[key] = counts.get(key, 0) + int(ok)
    for key, ok in info.get("safe", {}).items():
        counts[key] = counts.get(key, 0) + int(ok)


TICKS = 100  # step reports per run (cheap; they tell where a run was when it died)
HEARTBEAT_S = 30.0  # at a tick, a progress line once this long passed since the last (a long tenth is not silent)


Look = Callable[[int], bool]
"""An interim checkpoint: evaluates the policy at a training step; True when every threshold is met."""


class GoalCurve:
    """An SB3 callback body: success per goal over finished training episodes, checkpoints, and the cap.

    A curve point is made at every tenth of the budget and at every interim
    checkpoint (:mod:`specguard.stats.anytime`); a checkpoint's evaluation is stored
    in its point under ``"evaluation"``, and a met one stops training. An
    ``adapter`` (``weights="auto"``) sees every finished training episode, and
    each point records the weights in force (:mod:`specguard.training.auto_weights`).
    """

    def __init__(
        self,
        every: int,
        wall_clock_s: float | None,
        total: int,
        report: Report | None,
        checkpoints: list[int] | None = None,
        look: Look | None = None,
        adapter: WeightAdapter | None = None,
    ) -> None:
        self.every = max(1, every)
        self.total = total
        self.report = report
        self.checkpoints = list(checkpoints or [])
        self.look = look
        self.adapter = adapter
        self._tick = max(1, total // TICKS)
        self._next_tick = self._tick
        self.start = time.perf_counter()
        self.deadline = None if wall_clock_s is None else time.perf_counter() + wall_clock_s
        self.points: list[dict[str, Any]] = []
        self._counts: dict[str, int] = {}
        self._episodes = 0
        self._next = self.every
        self._said = self.start  # when the last progress line was sent
        self.hit_wall_clock = False
        self.met_early = False

    def on_step(self, num_timesteps: int, dones: Any, infos: list[dict[str, Any]]) -> bool:
        for done, info in zip(dones, infos):
            if done and "goals" in info:
                self._episodes += 1
                count_episode(self._counts, info)
                if self.adapter is not None:
                    self.adapter.observe(info["goals"], info.get("safe"))
        if self.report is not None and num_timesteps >= self._next_tick:
            self._next_tick = num_timesteps + self._tick
            if time.perf_counter() - self._said >= HEARTBEAT_S:
                self._say(num_timesteps)  # the tenth's episodes so far: a line, the counts kept
            else:
                self.report("train", num_timesteps, None)
        looking = bool(self.checkpoints) and num_timesteps >= self.checkpoints[0]
        if num_timesteps >= self._next or looking:
            while self._next <= num_timesteps:
                self._next += self.every
            self._point(num_timesteps)
        if looking:
            while self.checkpoints and self.checkpoints[0] <= num_timesteps:
                self.checkpoints.pop(0)
            assert self.look is not None
            if self.look(num_timesteps):
                self.met_early = True
                return False
        if self.deadline is not None and time.perf_counter() > self.deadline:
            self.hit_wall_clock = True
            return False
        return True

    def _point(self, num_timesteps: int) -> None:
        rates = {p: c / self._episodes for p, c in self._counts.items()} if self._episodes else {}
        self._append(num_timesteps, self._episodes, rates)
        self._say(num_timesteps)
        self._counts, self._episodes = {}, 0

    def _say(self, num_timesteps: int) -> None:
        """The progress line of the episodes since the last point: numbers, as JSON (the parent makes the event,
        :mod:`specguard.training.progress`)."""
        if self.report is None:
            return
        counts, episodes = self._counts, self._episodes
        root = next(iter(counts.values())) / episodes if episodes and counts else None  # the root's goal first
        self._said = now = time.perf_counter()
        self.report("train", num_timesteps, encode_update(num_timesteps, self.total, now - self.start, root, episodes))

    def _append(self, num_timesteps: int, episodes: int, rates: dict[str, float]) -> None:
        point: dict[str, Any] = {"timesteps": num_timesteps, "episodes": episodes, "success": rates}
        if self.adapter is not None:
            point["weights"] = self.adapter.in_force_lists()
        self.points.append(point)

    def evaluated(self, num_timesteps: int, counts: Mapping[str, int], episodes: int) -> None:
        """Record an evaluation at ``num_timesteps`` in the curve (a point of its own if none is there)."""
        if not self.points or self.points[-1]["timesteps"] != num_timesteps:
            self._append(num_timesteps, 0, {})
        self.points[-1]["evaluation"] = {p: c / episodes for p, c in counts.items()}
        self.points[-1]["evaluation_episodes"] = episodes
