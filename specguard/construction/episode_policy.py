"""What acts in the constructed env's episodes: the :class:`EpisodePolicy` protocol.

A policy is any callable from observations to actions. One that carries
something per env from step to step (a recurrent policy's state, the env's
action masks) is an :class:`EpisodePolicy`: told as episodes start, then
asked once per step. Training's evaluation and rollouts
(:mod:`specguard.training.train`, :mod:`specguard.evaluation.rollout`) and the
falsifier's runner (:class:`specguard.falsify.search.EpisodeRunner`, several
envs in lockstep) all tell it, and
:class:`specguard.evaluation.policy.Policy` is one.

Example:
    >>> import numpy as np
    >>> class Masked:
    ...     def start(self, envs):
    ...         self.masks = [np.ones(2, dtype=bool) for _ in envs]
    ...     def __call__(self, observations, rows=None):
    ...         return np.zeros(len(observations), dtype=np.int64)
    >>> isinstance(Masked(), EpisodePolicy), isinstance(lambda observations: observations, EpisodePolicy)
    (True, False)
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

__all__ = ["EpisodePolicy"]


@runtime_checkable
class EpisodePolicy(Protocol):
    """A policy that carries something per env from step to step (a recurrent policy's state, the env's action masks).

    :meth:`start` is called as the episodes of ``envs`` start (after their ``reset``; one env per row), then the
    policy once per step, with the rows still running (``None``: every env started).
    :class:`specguard.evaluation.policy.Policy` is one.
    """

    def start(self, envs: Sequence[Any]) -> None: ...

    def __call__(self, observations: Any, rows: Sequence[int] | None = None) -> Any: ...
