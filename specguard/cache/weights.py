"""A digest of what a policy computes, read from its weights: one source for a trained run's
(:attr:`RunResult.weights_digest <specguard.training.result.RunResult>`) and an agent's in memory
(:attr:`Agent.identity <specguard.agents.agent.Agent.identity>`), so the two agree on the same model.

A torch module (an SB3 model's policy) is read through its ``state_dict()``, in key order: each tensor as
``key:dtype:shape``, then its raw bytes; anything else by its canonical form (:func:`specguard.cache.canonical.digest`:
a function's code, as a spec's functions are fingerprinted). ``VecNormalize`` statistics the policy reads enter
beside it. Two machines holding the same weights compute the same hex digest without sharing any file.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from typing import Any

from specguard.cache.canonical import digest

__all__ = ["normalizer_digest", "parameters_digest", "parts_digest", "weights_digest"]


def parameters_digest(obj: Any, name: str) -> str:
    """A digest of what ``obj`` computes: a torch module's code and parameters (an SB3 model's policy's), else its
    canonical form (a function's code, as a spec's functions are fingerprinted).

    Raises:
        FingerprintError: ``obj`` is no torch module, and holds something that cannot be fingerprinted exactly.
    """
    import torch

    module = getattr(obj, "policy", obj)
    if not isinstance(module, torch.nn.Module):
        return digest(obj, f"agent {name!r}")
    h = hashlib.sha256(digest(type(obj), f"agent {name!r}").encode())
    for key, tensor in module.state_dict().items():
        flat = tensor.detach().cpu().reshape(-1)
        h.update(f"{key}:{flat.dtype}:{tuple(tensor.shape)}".encode())
        h.update(flat.view(torch.uint8).numpy().tobytes())
    return h.hexdigest()


def normalizer_digest(norm: Any) -> str | None:
    """A digest of ``VecNormalize`` statistics as a policy reads them (``None`` for none)."""
    if norm is None:
        return None
    rms = norm.obs_rms
    parts = rms.items() if isinstance(rms, Mapping) else [("", rms)]
    stats = [(key, part.mean, part.var, float(part.count)) for key, part in parts]
    return digest([stats, norm.norm_obs, float(norm.clip_obs), float(norm.epsilon)], "the agent's VecNormalize")


def parts_digest(parts: Iterable[tuple[str, Any]]) -> str:
    """The SHA-256 of named parts (each JSON-able), in order."""
    return hashlib.sha256(json.dumps(list(parts)).encode()).hexdigest()


def weights_digest(obj: Any, normalizer: Any = None, *, name: str, kind: str = "model") -> str:
    """The digest of a policy: ``obj``'s (:func:`parameters_digest`) and its ``VecNormalize`` statistics'
    (:func:`normalizer_digest`); ``kind`` is ``"model"`` for an object with SB3's ``predict``, ``"callable"`` for a
    callable ``obs -> action``.

    Raises:
        FingerprintError: as :func:`parameters_digest`.
    """
    return parts_digest([(kind, parameters_digest(obj, name)), ("normalizer", normalizer_digest(normalizer))])
