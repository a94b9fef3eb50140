"""What a spec may spend: training steps, seeds, evaluation episodes, wall-clock time.

Budgets are what make CI affordable. Pick ``timesteps`` from a run you trust
(the smallest budget at which the spec's goals are met on your machine), keep
``min_seeds`` at 2 for a pull-request check (two runs in parallel on a 2-core
machine), and raise ``max_seeds`` where a quorum should be judged over more
runs. ``eval_episodes`` sets how narrow a run's interval gets: with 30
episodes and 30 successes the 95% interval is ``[0.884, 1]``. ``checkpoints``
makes ``timesteps`` a ceiling: a run is judged at every ``checkpoints``-th of
it and stops training once every threshold is met (:mod:`specguard.stats.anytime`).

Example:
    >>> Budget(timesteps=50_000, min_seeds=2, max_seeds=4)  # doctest: +NORMALIZE_WHITESPACE
    Budget(timesteps=50000, min_seeds=2, max_seeds=4, eval_episodes=30, max_eval_episodes=120,
           wall_clock_s=None, checkpoints=10)
    >>> Budget(timesteps=50_000).looks
    12
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from specguard.error import InvalidSpec
from specguard.spec.algorithms import algorithm_name, collect_parameter, collect_steps
from specguard.stats.anytime import DEFAULT_CHECKPOINTS
from specguard.validation import check_count, check_positive

__all__ = ["Budget", "trained_timesteps"]


@dataclass(frozen=True)
class Budget:
    """Training and evaluation budget of a spec.

    Args:
        timesteps: environment steps of training per seed.
        min_seeds: runs always trained.
        max_seeds: runs trained at most, while a quorum is still open
            (default: ``min_seeds``).
        eval_episodes: evaluation episodes per run.
        max_eval_episodes: evaluation episodes an undecided run may get in
            total before it is called (default: 4x ``eval_episodes``).
        wall_clock_s: optional cap in seconds on one run's training.
        checkpoints: evaluation checkpoints of a run (default
            :data:`~specguard.stats.anytime.DEFAULT_CHECKPOINTS`, 10, at every
            door). ``C > 1``: judged after every ``C``-th of the budget, and
            training stops at the first checkpoint where every threshold is
            met (anytime verdicts); the verdicts' confidence is corrected for
            the extra looks (:mod:`specguard.stats.anytime`). 1: judged once,
            after the whole budget.
    """

    timesteps: int
    min_seeds: int = 2
    max_seeds: int | None = None
    eval_episodes: int = 30
    max_eval_episodes: int | None = None
    wall_clock_s: float | None = None
    checkpoints: int = DEFAULT_CHECKPOINTS

    def __post_init__(self) -> None:
        object.__setattr__(self, "timesteps", check_count("Budget", "timesteps", self.timesteps))
        object.__setattr__(self, "min_seeds", check_count("Budget", "min_seeds", self.min_seeds))
        max_seeds = self.min_seeds if self.max_seeds is None else check_count("Budget", "max_seeds", self.max_seeds)
        if max_seeds < self.min_seeds:
            raise InvalidSpec(
                "Budget.max_seeds",
                f"expected max_seeds >= min_seeds, got max_seeds={max_seeds} < min_seeds={self.min_seeds}",
            )
        object.__setattr__(self, "max_seeds", max_seeds)
        object.__setattr__(self, "eval_episodes", check_count("Budget", "eval_episodes", self.eval_episodes))
        max_eval = (
            4 * self.eval_episodes
            if self.max_eval_episodes is None
            else check_count("Budget", "max_eval_episodes", self.max_eval_episodes)
        )
        if max_eval < self.eval_episodes:
            raise InvalidSpec(
                "Budget.max_eval_episodes",
                f"expected max_eval_episodes >= eval_episodes, got {max_eval} < {self.eval_episodes}",
            )
        object.__setattr__(self, "max_eval_episodes", max_eval)
        if self.wall_clock_s is not None:
            wall_clock_s = check_positive("Budget", "wall_clock_s", self.wall_clock_s, "seconds, or None for no cap")
            object.__setattr__(self, "wall_clock_s", wall_clock_s)
        object.__setattr__(self, "checkpoints", check_count("Budget", "checkpoints", self.checkpoints))

    @property
    def evaluation_stages(self) -> list[int]:
        """Episodes evaluated after each stage of a run's final evaluation (:mod:`specguard.stats.anytime`)."""
        from specguard.stats.anytime import evaluation_stages

        assert self.max_eval_episodes is not None
        return evaluation_stages(self.eval_episodes, self.max_eval_episodes)

    @property
    def looks(self) -> int:
        """How many times a run may be judged: interim checkpoints plus final evaluation stages."""
        from specguard.stats.anytime import looks

        return looks(self.checkpoints, len(self.evaluation_stages))

    def scaled(self, factor: float, *, checkpoints: int | None = None) -> Budget:
        """This budget with ``timesteps`` multiplied by ``factor`` (at least 1 step), e.g. 0.25 for a quick check.

        ``checkpoints``, if given, replaces the budget's own.
        """
        check_positive("Budget.scaled", "factor", factor, "the budget scale")
        return Budget(
            timesteps=max(1, round(self.timesteps * factor)),
            min_seeds=self.min_seeds,
            max_seeds=self.max_seeds,
            eval_episodes=self.eval_episodes,
            max_eval_episodes=self.max_eval_episodes,
            wall_clock_s=self.wall_clock_s,
            checkpoints=self.checkpoints if checkpoints is None else checkpoints,
        )


ROUNDING_WARNING = 0.10  # warn when training rounds the budget up by more than this fraction
AGENT_TIMESTEPS = 1
"""The budget of a spec that only judges agents trained elsewhere (docs/guide/agents.md), which trains nothing: never
warned about for its rounding."""


def trained_timesteps(
    budget: Budget | int, algorithm: str | type, hyperparameters: Mapping[str, Any] | None = None, n_envs: int = 1
) -> int:
    """The timesteps a run actually trains: the budget rounded up to whole collections.

    stable-baselines3 stops only between collections: on-policy algorithms collect
    ``n_steps`` per env (PPO's default 2048, A2C's 5, RecurrentPPO's 128), so they train
    ``ceil(timesteps / (n_steps * n_envs)) * n_steps * n_envs``; off-policy
    algorithms collect ``train_freq`` steps per env (DQN and QRDQN 4, SAC, TD3, DDPG, TQC and
    CrossQ 1); the defaults are read from the algorithm's constructor.
    Warns once when that is more than 10% above the budget, unless the budget is :data:`AGENT_TIMESTEPS`, the one
    the docs give a spec that only judges agents trained elsewhere.

    Example:
        >>> trained_timesteps(100_000, "PPO", {"n_steps": 1024}, n_envs=4)
        102400
    """
    timesteps = budget.timesteps if isinstance(budget, Budget) else check_count("trained_timesteps", "budget", budget)
    chunk = collect_steps(algorithm, hyperparameters or {}) * n_envs
    trained = math.ceil(timesteps / chunk) * chunk
    if trained > timesteps * (1 + ROUNDING_WARNING) and timesteps != AGENT_TIMESTEPS:
        warnings.warn(
            f"budget of {timesteps} timesteps trains {trained}: {algorithm_name(algorithm)} collects {chunk} steps "
            "at a time "
            f"({chunk // n_envs} per env x {n_envs} env{'s' if n_envs != 1 else ''}); "
            f"set timesteps to a multiple of {chunk} or lower " + collect_parameter(algorithm),
            stacklevel=2,
        )
    return trained
