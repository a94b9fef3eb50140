"""The env wrappers an agent was trained with, as its rl-zoo3 ``config.yml`` names them: :class:`FrameStack` (what
SB3's ``VecFrameStack`` does, for one env) and :func:`zoo_wrappers`, ``frame_stack`` and ``env_wrapper`` read from
the config and put around the env the agent is judged in.

rl-zoo3 wraps each env in ``env_wrapper`` (classes named ``module.Class``, with their keyword arguments), then the
vectorized envs in ``VecFrameStack(n_stack=frame_stack)``; :class:`ZooWrappers` does the same for one env. A class
named by the config is imported only for a trusted agent (importing runs the module's code); otherwise loading the
agent is refused, naming it.

Example:
    >>> import gymnasium as gym
    >>> env = FrameStack(gym.make("CartPole-v1"), 4)
    >>> obs, _ = env.reset(seed=0)
    >>> obs.shape, obs[:12].tolist() == [0.0] * 12, env.observation_space.shape
    ((16,), True, (16,))
    >>> zoo_wrappers({"frame_stack": 4}, "config.yml", trust=False).text
    'frame_stack: 4'
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from specguard.error import AgentError, SpecWarning
from specguard.utils.text import shown

__all__ = ["FrameStack", "Normalized", "ZooWrappers", "zoo_wrappers"]


class FrameStack(gym.Wrapper):
    """The last ``n_stack`` observations of ``env``, stacked as SB3's ``VecFrameStack`` stacks them for one env: on
    the last axis (an image's channel axis, first or last, as SB3 detects it; a ``Dict``'s key by key), zeros before
    the first observation of an episode.

    It is SB3's own ``StackedObservations``, so an agent trained with ``VecFrameStack(venv, n_stack)`` sees here what
    it saw in training (``gymnasium.wrappers.FrameStackObservation`` stacks on a new first axis instead, and repeats
    the first observation by default).
    """

    def __init__(self, env: gym.Env, n_stack: int) -> None:
        from stable_baselines3.common.vec_env.stacked_observations import StackedObservations

        super().__init__(env)
        self.n_stack = n_stack
        self._stack = StackedObservations(1, n_stack, env.observation_space)  # type: ignore[arg-type]
        self.observation_space = self._stack.stacked_observation_space

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return _row(self._stack.reset(_batch(obs))), info

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        # never "done" here: the next reset zeroes the stack, as VecFrameStack does on an episode's end
        stacked, _ = self._stack.update(_batch(obs), np.zeros(1, dtype=bool), [{}])
        return _row(stacked), reward, terminated, truncated, info


class Normalized(gym.ObservationWrapper):
    """Each observation of ``env`` normalized by ``VecNormalize`` statistics (``normalizer.normalize_obs``, its
    clipping included), as ``VecNormalize`` hands them on; its space is the env's (what a network reads of it: the
    kind and shape)."""

    def __init__(self, env: gym.Env, normalizer: Any) -> None:
        super().__init__(env)
        self.normalizer = normalizer

    def observation(self, observation: Any) -> Any:
        return self.normalizer.normalize_obs(observation)


def _batch(obs: Any) -> Any:
    if isinstance(obs, Mapping):
        return {key: np.asarray(value)[None] for key, value in obs.items()}
    return np.asarray(obs)[None]


def _row(stacked: Any) -> Any:
    if isinstance(stacked, Mapping):
        return {key: value[0].copy() for key, value in stacked.items()}
    return stacked[0].copy()


class ZooWrappers:
    """``env_wrapper`` then ``frame_stack`` around an env, as rl-zoo3 trains: ``wrappers(env) -> env``.

    Attributes:
        frame_stack: the ``n_stack`` of ``VecFrameStack``, or ``None``.
        env_wrapper: the classes (imported) and their keyword arguments, in order.
        text: what the config said, for notes (``"frame_stack: 4"``).
    """

    def __init__(
        self,
        frame_stack: int | None,
        env_wrapper: list[tuple[type, dict[str, Any]]],
        text: str,
        normalizer: Any = None,
    ) -> None:
        self.frame_stack = frame_stack
        self.env_wrapper = env_wrapper
        self.text = text
        self.normalizer = normalizer
        self.__qualname__ = f"config.yml's {text}"  # how function_text names it in notes and errors

    def normalized(self, normalizer: Any, source: str) -> ZooWrappers:
        """These wrappers with ``VecNormalize`` statistics applied to each frame before it is stacked, as rl-zoo3
        trains (``VecNormalize`` around the envs, ``VecFrameStack`` around it): its statistics are of one frame."""
        return ZooWrappers(
            self.frame_stack, self.env_wrapper, f"{self.text}, each frame normalized first by {source}", normalizer
        )

    def __call__(self, env: gym.Env) -> gym.Env:
        for cls, kwargs in self.env_wrapper:
            env = cls(env, **kwargs)
        if self.normalizer is not None:
            env = Normalized(env, self.normalizer)
        return env if self.frame_stack is None else FrameStack(env, self.frame_stack)

    def stacked_space(self, space: gym.Space[Any]) -> gym.Space[Any]:
        """What the agent reads of observations ``space`` (one frame's) through the frame stack."""
        from stable_baselines3.common.vec_env.stacked_observations import StackedObservations

        if self.frame_stack is None:
            return space
        return StackedObservations(1, self.frame_stack, space).stacked_observation_space  # type: ignore[arg-type]

    def identity(self) -> list[Any]:
        """What the wrappers are, for the agent's identity: the config's words."""
        names = [f"{cls.__module__}.{cls.__qualname__}" for cls, _ in self.env_wrapper]
        return [self.frame_stack, names, [sorted(map(str, kwargs.items())) for _, kwargs in self.env_wrapper]]


def zoo_wrappers(config: Mapping[str, Any], where: str, *, trust: bool) -> ZooWrappers | None:
    """The wrappers ``config`` (an rl-zoo3 ``config.yml``'s hyperparameters, at ``where``) says the agent was
    trained with; ``None``: none.

    Raises:
        AgentError: ``frame_stack`` is not a count; ``env_wrapper`` names a class and the agent is not trusted
            (importing it runs code from the config), or it cannot be imported.
    """
    stack = config.get("frame_stack")
    if stack is not None and (isinstance(stack, bool) or not isinstance(stack, int) or stack < 1):
        raise AgentError(f"{where}: frame_stack: expected a count of frames >= 1, got {shown(stack)}", hint=None)
    said = config.get("env_wrapper")
    entries = [] if said is None else said if isinstance(said, list) else [said]
    named: list[tuple[str, dict[str, Any]]] = []
    for entry in entries:
        if isinstance(entry, str):
            named.append((entry, {}))
        elif isinstance(entry, Mapping) and len(entry) == 1:
            ((name, kwargs),) = entry.items()
            named.append((str(name), dict(kwargs or {})))
        else:
            raise AgentError(
                f"{where}: env_wrapper: expected a class name or a mapping of one to its kwargs, got {shown(entry)}",
                hint=None,
            )
    if named and not trust:
        names = ", ".join(name for name, _ in named)
        raise AgentError(
            f"{where}: the agent was trained with env_wrapper {names}, which specguard applies only to a trusted "
            "agent: importing it runs the code it names",
            hint="if you trust it, trust=True or --trust-agent applies it; or take env_wrapper out of the config and "
            "give the wrappers yourself (check_agent(..., wrap=...))",
        )
    classes = [(_imported(where, name), kwargs) for name, kwargs in named]
    if config.get("vec_env_wrapper") is not None:  # around the vectorized envs: no one env's wrapper to put on
        warnings.warn(
            f"{where}: the agent was trained with vec_env_wrapper {shown(config['vec_env_wrapper'])}, which specguard "
            "does not apply (it judges one env): what the agent sees may differ from its training; give "
            "check_agent(..., wrap=...) a wrapper that does the same for one env",
            SpecWarning,
            stacklevel=4,
        )
    if stack is None and not classes:
        return None
    parts = [f"env_wrapper: {', '.join(name for name, _ in named)}"] if named else []
    parts += [f"frame_stack: {stack}"] if stack is not None else []
    return ZooWrappers(stack, classes, "; ".join(parts))


def _imported(where: str, name: str) -> type:
    """The class ``module.Class`` (rl-zoo3's form) or ``module:Class``."""
    module, _, attr = name.partition(":") if ":" in name else name.rpartition(".")
    try:
        found = getattr(importlib.import_module(module), attr) if module and attr else None
    except Exception as e:
        raise AgentError(f"{where}: env_wrapper {name} cannot be imported: {type(e).__name__}: {e}", hint=None) from e
    if not isinstance(found, type):
        raise AgentError(f"{where}: env_wrapper {name} names no class", hint="name it module.Class, as rl-zoo3 does")
    return found
