"""Schedules of SB3 hyperparameters that a spec (and rl-zoo3's files) write as values: :class:`LinearSchedule`.

Example:
    >>> LinearSchedule(3e-4)(0.5)
    0.00015
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SCHEDULED", "LinearSchedule"]

SCHEDULED = ("learning_rate", "clip_range", "clip_range_vf", "delta_std")
"""The hyperparameters whose ``"lin_<x>"`` values rl-zoo3 turns into linear schedules (as it does, and no others)."""


@dataclass(frozen=True)
class LinearSchedule:
    """rl-zoo3's ``lin_<x>``: ``initial_value`` times the progress remaining (1 at the start, 0 at the end).

    stable-baselines3 takes it wherever it takes a schedule (``learning_rate``, ``clip_range``, ...). The same numbers
    as rl-zoo3's ``SimpleLinearSchedule``; a frozen dataclass, so it pickles to worker processes and enters a run's key
    by its value.
    """

    initial_value: float

    def __call__(self, progress_remaining: float) -> float:
        return progress_remaining * self.initial_value
