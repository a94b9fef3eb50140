"""Watching a trained policy: trajectories of evaluation episodes on the env its run trained on.

:func:`rollout` runs the policy on the env a run trained on (the constructed
env, or the initial env for a baseline spec) and returns every step. GIFs of
an episode are :mod:`specguard.report.gifs`; loading a cached model is
:mod:`specguard.cache.models`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from specguard.spec.spec import Spec
from specguard.training.train import EVAL_SEED_BASE

__all__ = ["episode", "policy", "rollout", "spec_env"]


def spec_env(spec: Spec, **make_kwargs: Any) -> Any:
    """The env ``spec`` trains on, built afresh: the constructed env, or the initial env for a baseline spec."""
    from specguard.construction.env import make_baseline_env, make_env

    if spec.baseline:
        return make_baseline_env(spec.initial_env, spec.tree, **make_kwargs)
    return make_env(spec.initial_env, spec.tree, **make_kwargs)


def _normalizer(model: Any, normalizer: Any) -> Any:
    """The ``VecNormalize`` whose statistics the policy expects: given, or the model's training env."""
    if normalizer is not None:
        return normalizer
    from stable_baselines3.common.vec_env import VecNormalize

    env = model.get_env() if hasattr(model, "get_env") else None
    return env if isinstance(env, VecNormalize) else None


def policy(model: Any, normalizer: Any, deterministic: bool) -> Callable[[Any], Any]:
    """``model``'s action for an observation, with its ``VecNormalize`` statistics applied where it has them."""
    import gymnasium as gym

    norm = _normalizer(model, normalizer)
    discrete = isinstance(getattr(model, "action_space", None), gym.spaces.Discrete)

    def act(obs: Any) -> Any:
        action = model.predict(norm.normalize_obs(obs) if norm is not None else obs, deterministic=deterministic)[0]
        return int(action) if discrete else action

    return act


def episode(
    env: Any,
    act: Callable[[Any], Any],
    seed: int,
    on_step: Callable[[int], None] | None = None,
    options: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """One episode of ``act`` on ``env`` from ``reset(seed=seed, options=options)``; ``on_step(n)`` after each of
    its ``n`` steps."""
    obs, info = env.reset(seed=seed, options=options)
    if on_step is not None:
        on_step(0)
    steps: list[dict[str, Any]] = []
    done = False
    while not done:
        action = act(obs)
        next_obs, reward, terminated, truncated, info = env.step(action)
        steps.append(
            {
                "obs": obs,
                "action": action,
                "reward": float(reward),
                "terminated": bool(terminated),
                "truncated": bool(truncated),
                "info": info,
            }
        )
        obs = next_obs
        done = bool(terminated or truncated)
        if on_step is not None:
            on_step(len(steps))
    return steps


def rollout(
    model: Any,
    spec: Spec,
    *,
    episodes: int = 1,
    seed: int = EVAL_SEED_BASE,
    deterministic: bool = True,
    normalizer: Any = None,
) -> list[list[dict[str, Any]]]:
    """Run ``model`` for ``episodes`` episodes on the env ``spec`` trains on (episode ``i`` seeded ``seed + i``).

    Args:
        model: a trained SB3 model (``train_run``'s second value, or :func:`load_model`).
        normalizer: the ``VecNormalize`` statistics of a ``normalize=True`` spec;
            default: the model's own training env when it is one.

    Returns:
        One list per episode of its steps: ``{"obs", "action", "reward",
        "terminated", "truncated", "info"}``, where ``obs`` is the observation
        the action was chosen on and ``info["goals"]`` says which goals the
        state reached by the step lies in.
    """
    act = policy(model, normalizer, deterministic)
    env = spec_env(spec)
    try:
        return [episode(env, act, seed + i) for i in range(episodes)]
    finally:
        env.close()
