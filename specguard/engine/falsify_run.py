"""Falsifying a spec's trained runs: the cached model as a batched policy, the spec's property and identity.

:func:`falsify_run` loads run ``seed``'s model from the cache (no retraining),
makes it a policy over a batch of observations (its ``VecNormalize``
statistics applied where the run used them, its deterministic action where
the spec evaluates so) and searches a start space with
:func:`specguard.falsify.search.falsify`. The property is the spec's own: the
root goal and every thresholded goal and safety rate at the end of an episode.
Counterexamples are stored in a Hypothesis example database under a key made
of the spec's identity (its fingerprint's ``spec_key``), the seed and the start space.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from specguard.falsify.search import EpisodeRunner, Falsification, falsify
from specguard.spec.spec import Spec
from specguard.starts.space import StartSpace
from specguard.training.policy import one_torch_thread

__all__ = ["batch_policy", "database_key", "falsify_run", "property_keys", "start_space"]


def start_space(spec: Spec, starts: StartSpace | None = None) -> StartSpace:
    """The start space searched: ``starts`` if given, else the spec's own (``Spec.starts``), else the env's.

    Example:
        >>> import specguard as sg
        >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
        >>> spec = sg.Spec(cartpole, sg.Goal("g", x=(0, 1)), budget=sg.Budget(timesteps=8), starts={"x": (-1, 1)})
        >>> start_space(spec).ranges, start_space(spec, sg.StartSpace()).ranges
        ((('x', -1.0, 1.0),), ())
    """
    if starts is not None:
        return starts
    return spec.starts if spec.starts is not None else StartSpace()


def property_keys(spec: Spec) -> list[str]:
    """The keys the falsifier asserts: the root goal, then every thresholded goal and safety rate."""
    return list(dict.fromkeys([spec.tree.name, *spec.thresholds]))


def database_key(spec_key: str, seed: int, space: StartSpace) -> str:
    """The key a counterexample of run ``seed`` over ``space`` is stored under."""
    return hashlib.sha256(f"{spec_key}\n{seed}\n{space.describe()}".encode()).hexdigest()


def batch_policy(model: Any, normalizer: Any, deterministic: bool) -> Callable[[np.ndarray], Any]:
    """``model``'s actions for a batch of observations (rows), its ``VecNormalize`` statistics applied if any."""
    from specguard.training.policy import policy

    return policy(model, normalizer, deterministic=deterministic, batch=True)


def falsify_run(
    spec: Spec,
    model: Any,
    normalizer: Any,
    *,
    seed: int,
    spec_key: str | None,
    starts: StartSpace | None = None,
    examples: int = 200,
    uniform: int = 100,
    search_seed: int = 0,
    database: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> Falsification:
    """Search the start space of run ``seed`` of ``spec`` for a start from which its policy misses the spec.

    Args:
        starts: the start space; ``None``: :func:`start_space`'s (the spec's own, else the env's).
        database: the directory of the Hypothesis example database; ``None``: nothing stored or replayed.
        Others: as :func:`specguard.falsify.search.falsify`.
    """
    from hypothesis.database import DirectoryBasedExampleDatabase

    from specguard.error import SpecError

    if spec.baseline:
        raise SpecError(
            f"Spec {spec.label!r}: falsify needs a spec trained on the constructed env, not a baseline spec",
            hint="falsify the spec itself; a baseline's episodes end as the initial env says",
        )
    space = start_space(spec, starts)
    runner = EpisodeRunner(
        spec.make_env, batch_policy(model, normalizer, spec.deterministic), space, property_keys(spec)
    )
    db = DirectoryBasedExampleDatabase(str(database)) if database is not None and spec_key else None
    key = database_key(spec_key, seed, space) if spec_key else ""
    label = f"{spec.label} seed {seed}"
    with one_torch_thread():
        return falsify(
            runner,
            examples=examples,
            uniform=uniform,
            seed=search_seed,
            database=db,
            key=key,
            confidence=spec.confidence,
            progress=(lambda line: progress(f"{label}: {line}")) if progress is not None else None,
        )
