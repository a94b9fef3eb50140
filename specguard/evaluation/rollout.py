"""Watching a trained policy: trajectories of evaluation episodes on the env its run trained on.

:func:`rollout_model` runs a model's policy (:func:`specguard.evaluation.policy.policy`) on the env a
run trained on (:meth:`Spec.make_env <specguard.spec.spec.Spec.make_env>`: the constructed
env, or the initial env for a baseline spec) and returns every step; a result's run is rolled out by
:func:`specguard.rollout` (``sg.rollout(result, seed)``), which loads its model and calls it. GIFs of
an episode are :mod:`specguard.report.gifs`; loading a cached model is :mod:`specguard.cache.models`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from specguard.construction.episode_policy import EpisodePolicy
from specguard.evaluation.episodes import EVAL_SEED_BASE
from specguard.evaluation.policy import one_torch_thread, policy
from specguard.spec.spec import Spec

__all__ = ["episode", "rollout_model"]


def episode(
    env: Any,
    act: Callable[[Any], Any],
    seed: int,
    on_step: Callable[[int], None] | None = None,
    options: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """One episode of ``act`` on ``env`` from ``reset(seed=seed, options=options)``; ``on_step(n)`` after each of
    its ``n`` steps. An :class:`~specguard.construction.episode_policy.EpisodePolicy` is told as the episode starts."""
    obs, info = env.reset(seed=seed, options=options)
    if isinstance(act, EpisodePolicy):
        act.start([env])
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


def rollout_model(
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
        model: a trained SB3 model (``train_run``'s second value, or :func:`specguard.load_model`).
        normalizer: the ``VecNormalize`` statistics of a ``normalize=True`` spec;
            default: the model's own training env when it is one.

    Returns:
        One list per episode of its steps: ``{"obs", "action", "reward",
        "terminated", "truncated", "info"}``, where ``obs`` is the observation
        the action was chosen on and ``info["goals"]`` says which goals the
        state reached by the step lies in.
    """
    act = policy(model, normalizer, deterministic=deterministic)
    env = spec.make_env()
    try:
        with one_torch_thread():
            return [episode(env, act, seed + i) for i in range(episodes)]
    finally:
        env.close()
