"""The SB3 callback of a training run: the learning curve's body stepped, auto weights switched between rollouts.

Stable-baselines3 is imported with this module; :mod:`specguard.training.train`
imports it only when a run trains.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from stable_baselines3.common.callbacks import BaseCallback

if TYPE_CHECKING:
    from specguard.training.auto_weights import WeightAdapter
    from specguard.training.curve import GoalCurve

__all__ = ["GoalCurveCallback"]


class GoalCurveCallback(BaseCallback):  # type: ignore[misc]
    """Feeds every step to ``curve`` (which may stop training), and switches auto weights after each rollout.

    Args:
        curve: the run's learning curve, checkpoints and caps.
        adapter: the run's weight adapter (``weights="auto"``), or ``None``.
    """

    def __init__(self, curve: GoalCurve, adapter: WeightAdapter | None = None) -> None:
        super().__init__()
        self.curve = curve
        self.adapter = adapter

    def _on_step(self) -> bool:
        return self.curve.on_step(self.num_timesteps, self.locals["dones"], self.locals["infos"])

    def _on_rollout_end(self) -> None:
        # Between rollouts, so every env switches at its next reset (specguard.training.auto_weights).
        if self.adapter is not None and self.adapter.update() is not None:
            self.training_env.env_method("set_weights", self.adapter.in_force)
