"""A result's trained runs, reached again: their SB3 models, ``VecNormalize`` statistics and rollouts.

A :class:`~specguard.engine.spec_result.SpecResult` is plain data; the runs it
judged stay in the cache it was trained with. These functions load run
``seed``'s model from there (after the cache's checksums are verified) and let
it act; nothing retrains.

Example:
    >>> import specguard as sg
    >>> result = sg.run_spec(spec)  # doctest: +SKIP
    >>> model = sg.load_model(result, 0)  # doctest: +SKIP
    >>> last = sg.rollout(result, 0, episodes=1)[0][-1]  # doctest: +SKIP
    >>> assert last["info"]["goals"]["pendulum/stabilization"]  # doctest: +SKIP
"""

from __future__ import annotations

from typing import Any

from specguard.cache.models import load_cached
from specguard.engine.spec_result import SpecResult
from specguard.error import SpecError
from specguard.evaluation.rollout import rollout_model
from specguard.spec.spec import Spec

__all__ = ["load_model", "load_normalizer", "load_run", "rollout"]


def load_run(result: SpecResult, seed: int) -> tuple[Spec, Any, Any]:
    """Run ``seed`` of ``result``: the spec as run, its SB3 model and its ``VecNormalize`` statistics (or ``None``).

    Raises:
        SpecError: the result is an agent's (:func:`~specguard.engine.check_agent.check_agent`: nothing was
            trained, the agent is its own model), the runs were not cached (``cache_dir=None``, or a result read
            back without its ``trained`` spec and ``cache_dir``), or the run's cache entry is gone.
    """
    if result.agent is not None:
        raise SpecError(
            f"Spec {result.spec!r}: no model for seed {seed}: this result judged agent {result.agent!r}, trained "
            "elsewhere; specguard trained nothing",
            hint="the agent is its own model: sg.load_agent(source) loads it, and sg.falsify_agent(spec, agent) "
            "plays and searches its episodes",
        )
    if result.trained is None or result.cache_dir is None:
        raise SpecError(
            f"Spec {result.spec!r}: no model kept for seed {seed}: the runs were not cached",
            hint="run with a cache (the default) to reach trained models; "
            "a result read back needs SpecResult.from_dict(data, trained=spec, cache_dir=...)",
        )
    try:
        model, normalizer = load_cached(result.trained, seed, result.cache_dir)
    except FileNotFoundError as e:
        raise SpecError(f"Spec {result.spec!r}: {e}", hint="train it again: its cache entry is gone") from None
    return result.trained, model, normalizer


def load_model(result: SpecResult, seed: int) -> Any:
    """The trained SB3 model of run ``seed`` of ``result``, loaded from the cache after its checksums are verified.

    Raises:
        SpecError: the run was not cached, or is gone (:func:`load_run`).
    """
    return load_run(result, seed)[1]


def load_normalizer(result: SpecResult, seed: int) -> Any:
    """Run ``seed``'s ``VecNormalize`` statistics (``None`` where the run did not normalise observations).

    A policy outside specguard must normalise observations with these before asking the model.

    Raises:
        SpecError: the run was not cached, or is gone (:func:`load_run`).
    """
    return load_run(result, seed)[2]


def rollout(
    result: SpecResult, seed: int, episodes: int = 1, *, deterministic: bool = True
) -> list[list[dict[str, Any]]]:
    """Episodes of run ``seed``'s policy on its env, seeded as evaluation episodes are.

    Returns:
        One list of steps per episode: ``{"obs", "action", "reward",
        "terminated", "truncated", "info"}`` with ``info["goals"]``.

    Raises:
        SpecError: the run was not cached, or is gone (:func:`load_run`).
    """
    spec, model, normalizer = load_run(result, seed)
    return rollout_model(model, spec, episodes=episodes, deterministic=deterministic, normalizer=normalizer)
