"""Related, less robust agents made from the agent judged: the same policy with ``epsilon``-random actions.

Their failures are frequent where the agent's are rare, and fall where the
agent is closest to failing, so their episodes train the failure predictor
(:mod:`specguard.falsify.predictor`) for any agent, one trained elsewhere
included. At each step, with probability ``epsilon`` independently per env,
the action is drawn uniformly from the env's action space instead of the
agent's: it works alike for discrete and continuous actions, and for a
policy that carries a state per env (an :class:`EpisodePolicy`, told as
episodes start, as the agent itself is). Action noise (a Gaussian added to
continuous actions) was the other candidate; it has no discrete form.

Example:
    >>> import gymnasium as gym
    >>> import numpy as np
    >>> noisy = EpsilonRandom(lambda obs: np.zeros(len(obs), dtype=np.int64), gym.spaces.Discrete(2), 1.0,
    ...                       np.random.default_rng(0))
    >>> sorted(set(noisy(np.zeros((64, 4))).tolist()))  # every action random: both actions drawn
    [0, 1]
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from specguard.construction.episode_policy import EpisodePolicy
from specguard.falsify.predictor import FailureData

__all__ = ["EPSILONS", "EpsilonRandom", "perturbed"]

EPSILONS = (0.1, 0.3, 0.5)
"""The related agents' shares of random actions: a few levels, from a little weaker than the agent to much weaker."""


class EpsilonRandom:
    """``act`` with each row's action replaced, with probability ``epsilon``, by a uniform draw from ``space``.

    Args:
        act: the agent: ``act(observations) -> actions``, or an :class:`EpisodePolicy`.
        space: the env's action space.
        epsilon: the share of random actions, in [0, 1].
        rng: where the coin flips and random actions come from.
    """

    def __init__(
        self, act: Callable[..., Any], space: gym.Space[Any], epsilon: float, rng: np.random.Generator
    ) -> None:
        if not 0.0 <= epsilon <= 1.0:
            raise ValueError(f"expected epsilon in [0, 1], got {epsilon!r}")
        self.act, self.space, self.epsilon, self.rng = act, space, float(epsilon), rng
        self.space.seed(int(rng.integers(2**31)))

    def start(self, envs: Sequence[Any]) -> None:
        if isinstance(self.act, EpisodePolicy):
            self.act.start(envs)

    def __call__(self, observations: Any, rows: Sequence[int] | None = None) -> Any:
        actions = self.act(observations, rows) if isinstance(self.act, EpisodePolicy) else self.act(observations)
        actions = np.array(actions, copy=True)
        for i in np.flatnonzero(self.rng.random(len(actions)) < self.epsilon):
            actions[i] = self.space.sample()
        return actions


def perturbed(runner: Any, points: np.ndarray, epsilon: float, rng: np.random.Generator) -> FailureData:
    """One episode from each start (rows of ``points``, in the start space) of the runner's agent with
    ``epsilon``-random actions, as failure data of weakness ``epsilon``, weight 1. The runner's own agent is put back
    after."""
    with runner.acting(EpsilonRandom(runner.act, runner.action_space, epsilon, rng)):
        outcomes = runner.run(points)
    return FailureData(
        np.array([o.first for o in outcomes], dtype=np.float64),
        np.full(len(outcomes), float(epsilon)),
        np.array([o.failed for o in outcomes]),
        np.ones(len(outcomes)),
    )
