"""Trained models: a cached run's SB3 model and its ``VecNormalize`` statistics, loaded after the cache's checks;
a trainer's run (``Spec(trainer=...)``), its last agent."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from specguard.spec import algorithms as sb3
from specguard.spec.spec import Spec
from specguard.spec.trainers import SB3

__all__ = ["load_cached"]


def load_cached(spec: Spec, seed: int, cache_dir: Path | str) -> tuple[Any, Any]:
    """The cached model of run ``seed`` of ``spec`` and its ``VecNormalize`` statistics (or ``None``); for a spec
    with a trainer, the agent its last checkpoint yielded (unpickled) and ``None``. A result's run is
    :func:`specguard.load_model` (``sg.load_model(result, seed)``), which reads it here.

    Raises:
        FileNotFoundError: the run is not (or no longer validly) cached.
    """
    import pickle

    from specguard.cache.store import AGENT, NORMALIZER, Cache

    cache = Cache(cache_dir)
    if cache.load(spec, seed) is None:  # validates the entry's checksums before anything is unpickled
        raise FileNotFoundError(f"run seed {seed} of spec {spec.label!r} is not in the cache {str(cache_dir)!r}")
    path = cache.model_path(spec, seed)
    if not isinstance(spec.trainer, SB3):  # a training loop's agent, as run_files stored it
        with (path.parent / AGENT).open("rb") as f:
            return pickle.load(f), None  # cloudpickle's output is read by pickle
    model = sb3.load_saved(spec.trainer.algorithm, path)
    stats = path.parent / NORMALIZER
    normalizer = None
    if stats.exists():
        with stats.open("rb") as f:
            normalizer = pickle.load(f)  # VecNormalize.save pickles itself; only its statistics are used
    return model, normalizer
