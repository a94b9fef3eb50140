"""Every episode ends: specguard's step cap for an initial env that declares no episode limit.

An env without a ``TimeLimit`` (``Pendulum-v1``'s ``.unwrapped``, a hand-written env) ends its episodes only
where it terminates or truncates them itself. Most do (highway ends each at its ``duration``, MiniGrid at its
``max_steps``); one that never does would hang training and evaluation, most of all under a root goal that
holds until the end, which ends nothing itself. So such an env runs under :data:`EPISODE_CAP` steps: a cap that
an env ending its own episodes never reaches, and that a verdict states where it cut an evaluation episode
(``info[CAPPED]``, counted in :attr:`specguard.training.result.RunResult.capped`). An env with a limit of its
own keeps it untouched.

Example:
    >>> import gymnasium as gym
    >>> env = capped(gym.make("Pendulum-v1").unwrapped)
    >>> type(env).__name__, env.get_wrapper_attr("_max_episode_steps")
    ('EpisodeCap', 10000)
    >>> capped(gym.make("Pendulum-v1")).spec.max_episode_steps  # its own TimeLimit, kept
    200
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym

from specguard.construction.preflight import episode_limit

__all__ = ["CAPPED", "EPISODE_CAP", "EpisodeCap", "capped"]

EPISODE_CAP = 10_000
"""The step limit of an episode whose initial env declares none: seconds of a policy's steps."""

CAPPED = "episode_cap"
"""The ``info`` key of a step the cap truncated: the cap, in steps."""


class EpisodeCap(gym.wrappers.TimeLimit):
    """A ``TimeLimit`` of :data:`EPISODE_CAP` steps whose truncation says it in ``info[CAPPED]``.

    A step the env ends itself (terminated or truncated) is the env's own end, reported as it is.
    """

    def __init__(self, env: gym.Env, max_episode_steps: int | None = None) -> None:
        super().__init__(env, EPISODE_CAP if max_episode_steps is None else max_episode_steps)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        steps = (self._elapsed_steps or 0) + 1
        self._elapsed_steps = steps  # type: ignore[assignment]  # Gymnasium types it None until a reset
        if steps >= self._max_episode_steps and not (terminated or truncated):
            truncated = True
            info[CAPPED] = self._max_episode_steps
        return obs, reward, terminated, truncated, info


def capped(env: gym.Env) -> gym.Env:
    """``env`` itself where a ``TimeLimit`` among its wrappers enforces an episode limit, else ``env`` under an
    :class:`EpisodeCap`. A limit that is only declared (a ``_max_episode_steps`` attribute of the env's own, a
    spec's ``max_episode_steps``) ends nothing by itself, so it does not spare the env the cap."""
    return env if _time_limited(env) else EpisodeCap(env)


def _time_limited(env: gym.Env) -> bool:
    """Whether a ``TimeLimit`` with a limit lies among ``env``'s wrappers (:func:`episode_limit` reads its limit)."""
    inner: Any = env
    while inner is not None:
        if isinstance(inner, gym.wrappers.TimeLimit) and episode_limit(inner) is not None:
            return True
        inner = getattr(inner, "env", None)
    return False
