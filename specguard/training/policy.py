"""A trained model as a policy: its action for an observation, with its ``VecNormalize`` statistics applied.

The one assembly of a policy from an SB3 model, used where a run is evaluated
(:mod:`specguard.training.train`), watched (:mod:`specguard.training.rollout`,
GIFs) and falsified (:mod:`specguard.engine.falsification`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["normalizer_of", "policy"]


def normalizer_of(model: Any, normalizer: Any = None) -> Any:
    """The ``VecNormalize`` whose statistics the policy expects: ``normalizer`` if given, else the model's training env
    when it is one, else ``None``."""
    if normalizer is not None:
        return normalizer
    from stable_baselines3.common.vec_env import VecNormalize

    env = model.get_env() if hasattr(model, "get_env") else None
    return env if isinstance(env, VecNormalize) else None


def policy(
    model: Any, normalizer: Any = None, *, deterministic: bool = True, batch: bool = False
) -> Callable[[Any], Any]:
    """``model``'s action for an observation, its ``VecNormalize`` statistics applied where it has them.

    Args:
        normalizer: the statistics of a ``normalize=True`` spec; default: the model's training env when it is one.
        deterministic: the model's deterministic action, or a sampled one.
        batch: the policy takes a batch of observations (rows) and returns their actions as the model gives them;
            otherwise one observation, and a discrete action as a Python ``int``.
    """
    import gymnasium as gym

    norm = normalizer_of(model, normalizer)
    discrete = not batch and isinstance(getattr(model, "action_space", None), gym.spaces.Discrete)

    def act(obs: Any) -> Any:
        action = model.predict(norm.normalize_obs(obs) if norm is not None else obs, deterministic=deterministic)[0]
        return int(action) if discrete else action

    return act
