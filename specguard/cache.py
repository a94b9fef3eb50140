"""The run cache: unchanged specs are not retrained, changed ones are.

A trained run is keyed by a fingerprint of everything that determines it: the
tree's structure and numbers, the source (and captured values) of every user
function (distances, constraints, ``state``, ``execute``, env factories), the
env id and kwargs, algorithm and hyperparameters, budget, thresholds and
confidence (they decide extra evaluation episodes), the seed, and the versions
of specguard, gymnasium, stable-baselines3, torch, numpy and Python.

An entry is a folder ``<root>/<key[:2]>/<key>/`` holding ``result.json``,
``model.zip`` (loadable with SB3's ``load``) and, with ``normalize=True``,
``vecnormalize.pkl``. It is written in a temporary folder and renamed into
place, which is atomic: two processes never corrupt an entry, and a run killed
midway leaves only a temporary folder that is never read. ``result.json``
records the fingerprint and a SHA-256 of the model file; an entry that does not
parse or match is reported corrupt and retrained, never trusted.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import os
import platform
import shutil
import tempfile
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

from specguard.nodes import Node
from specguard.spec import Spec
from specguard.train import RunResult

__all__ = ["Cache", "fingerprint"]

_VERSIONED = ("specguard", "gymnasium", "stable-baselines3", "torch", "numpy")


def _fn_identity(fn: Callable[..., Any] | None) -> Any:
    """Source, defaults and captured values of a user function (what decides its behaviour)."""
    if fn is None:
        return None
    try:
        source = inspect.getsource(fn)
    except (OSError, TypeError):
        code = getattr(fn, "__code__", None)
        source = repr(fn) if code is None else code.co_code.hex() + repr(code.co_consts)
    closure = getattr(fn, "__closure__", None) or ()
    captured = []
    for cell in closure:
        try:
            captured.append(repr(cell.cell_contents))
        except ValueError:  # an empty cell
            captured.append("<empty>")
    return {
        "name": getattr(fn, "__qualname__", repr(fn)),
        "source": source,
        "defaults": repr(getattr(fn, "__defaults__", None)),
        "captured": captured,
    }


def _tree_identity(tree: Node) -> list[Any]:
    out = []
    for path, node in tree.walk():
        entry: dict[str, Any] = {"path": path, "node": node.describe()}
        entry["annotations"] = [{"repr": repr(a), "fn": _fn_identity(getattr(a, "fn", None))} for a in node.annotations]
        out.append(entry)
    return out


def _versions() -> dict[str, str]:
    found = {"python": platform.python_version()}
    for name in _VERSIONED:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "absent"
    return found


def fingerprint(spec: Spec, seed: int) -> str:
    """The SHA-256 key of one run of ``spec`` with ``seed``."""
    env = spec.initial_env
    identity = {
        "tree": _tree_identity(spec.tree),
        "env": env.env if isinstance(env.env, str) else _fn_identity(env.env),
        "features": list(env.features),
        "state": _fn_identity(env.state),
        "execute": _fn_identity(env.execute),
        "bounds": [list(b) for b in env.bounds],
        "action_space": repr(env.action_space),
        "make_kwargs": repr(sorted(env.make_kwargs.items())),
        "algorithm": spec.algorithm,
        "hyperparameters": repr(sorted(spec.hyperparameters.items())),
        "n_envs": spec.n_envs,
        "normalize": spec.normalize,
        "deterministic": spec.deterministic,
        "baseline": spec.baseline,
        "budget": [
            spec.budget.timesteps,
            spec.budget.eval_episodes,
            spec.budget.max_eval_episodes,
            spec.budget.wall_clock_s,
        ],
        "thresholds": sorted(spec.thresholds.items()),
        "confidence": spec.confidence,
        "seed": seed,
        "versions": _versions(),
    }
    text = json.dumps(identity, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class Cache:
    """Trained runs on disk, keyed by :func:`fingerprint`.

    Args:
        root: the cache folder (created on first store).
    """

    def __init__(self, root: Path | str) -> None:
        self.root = Path(root)

    def entry(self, spec: Spec, seed: int) -> Path:
        key = fingerprint(spec, seed)
        return self.root / key[:2] / key

    def model_path(self, spec: Spec, seed: int) -> Path:
        """Where the run's model is (``PPO.load(cache.model_path(spec, seed))``)."""
        return self.entry(spec, seed) / "model.zip"

    def load(self, spec: Spec, seed: int) -> RunResult | None:
        """The cached result of the run, or ``None`` when absent or not trustworthy."""
        folder = self.entry(spec, seed)
        if not folder.exists():
            return None
        try:
            data = json.loads((folder / "result.json").read_text())
            if data["fingerprint"] != folder.name or data["model_sha256"] != _sha256(folder / "model.zip"):
                raise ValueError("fingerprint or model checksum does not match")
            return RunResult(**data["result"])
        except (OSError, ValueError, KeyError, TypeError) as e:
            # Corrupt or partial: move it aside so the retrained run can take its place.
            shutil.rmtree(folder, ignore_errors=True)
            import warnings

            warnings.warn(f"specguard cache: discarded a corrupt entry {folder} ({e}); retraining", stacklevel=2)
            return None

    def store(self, spec: Spec, seed: int, result: RunResult, model: Any) -> Path:
        """Write the run atomically; returns its folder."""
        folder = self.entry(spec, seed)
        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".tmp-", dir=folder.parent))
        try:
            model.save(tmp / "model.zip")
            env = model.get_env()
            if spec.normalize and hasattr(env, "save"):
                env.save(str(tmp / "vecnormalize.pkl"))
            record = {
                "fingerprint": folder.name,
                "model_sha256": _sha256(tmp / "model.zip"),
                "result": result.to_dict(),
            }
            (tmp / "result.json").write_text(json.dumps(record, indent=1))
            try:
                os.rename(tmp, folder)  # atomic; fails if another process stored it first
            except OSError:
                if not folder.exists():
                    raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return folder
