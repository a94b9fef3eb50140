"""A simulator-free test double: an env that replays a fixed trajectory (public as ``specguard.testing.ReplayEnv``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["ReplayEnv"]


class ReplayEnv(gym.Env[np.ndarray, int]):
    """Replays a fixed trajectory of observations, whatever the actions.

    ``reset`` returns ``trajectory[0]``; step ``t`` returns ``trajectory[t]``
    and truncates at the last one (its horizon). Rewards are 0.

    Args:
        trajectory: the observations ``s_0 .. s_T``, at least two.
        n_actions: the size of the ``Discrete`` action space.
        terminate: end at the last one by termination instead, as an env ends a fall or a crash
            before its horizon.
    """

    metadata = {"render_modes": []}  # noqa: RUF012  # Gymnasium declares it per instance

    def __init__(self, trajectory: Sequence[Sequence[float]], n_actions: int = 3, terminate: bool = False) -> None:
        self.trajectory = np.asarray(trajectory, dtype=np.float32)
        if self.trajectory.ndim != 2 or len(self.trajectory) < 2:
            raise ValueError(f"expected at least two observations of equal length, got shape {self.trajectory.shape}")
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, shape=self.trajectory.shape[1:], dtype=np.float32)
        self.action_space = gym.spaces.Discrete(n_actions)  # type: ignore[assignment]
        self.terminate = terminate
        self._t = 0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start the replay: the first observation, and an empty info."""
        super().reset(seed=seed)
        self._t = 0
        return self.trajectory[0].copy(), {}

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """The next observation of the trajectory, reward 0; truncated (or terminated) at the last one."""
        self._t += 1
        end = self._t >= len(self.trajectory) - 1
        return self.trajectory[self._t].copy(), 0.0, end and self.terminate, end and not self.terminate, {}
