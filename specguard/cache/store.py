"""The run cache: unchanged specs are not retrained, changed ones are, and stored results are never trusted blindly.

A trained run is keyed by :meth:`specguard.cache.fingerprint.SpecFingerprint.run_key`:
an exact digest of everything that decides the run (see
:mod:`specguard.cache.fingerprint` for what it covers and what it cannot see).

An entry is a folder ``<root>/<key[:2]>/<key>/`` holding ``result.json``,
``model.zip`` (loadable with SB3's ``load``) and, with ``normalize=True``,
``vecnormalize.pkl``; a run of a trainer of the user's (``Spec(trainer=...)``) holds its last agent as
``agent.pkl`` (cloudpickle) in place of the zip. It is written in a temporary folder and renamed into
place, which is atomic: a run killed midway leaves only a temporary folder that
is never read. ``result.json`` holds the result, the versions it was made
with, a SHA-256 of every file, and a checksum over all of that; with a secret
(:data:`SECRET_ENV`), also an HMAC-SHA256 signature. On load an entry must pass
every check of :func:`validate_record`; one that does not is discarded with a
warning and retrained, never trusted and never a traceback.

Trust boundary: a cache folder is trusted input. The checksum catches damage,
not intent (anyone who can write the folder can recompute it), and SB3's
``load`` unpickles (and ``agent.pkl`` is a pickle), so a model file from an untrusted source can run code.
For a cache shared between machines or branches, set the same secret in
:data:`SECRET_ENV` everywhere: entries are then signed, and an entry whose
signature does not verify with the key is discarded.

Two processes asking for the same run at once (two ``specguard run``, xdist
workers) take a file lock per key (:meth:`Cache.lock`): one trains, the other
waits and then reads its entry.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import shutil
import tempfile
import warnings
from collections.abc import Collection
from pathlib import Path
from typing import Any

from specguard.cache.fingerprint import fingerprint_spec
from specguard.cache.versions import versions
from specguard.error import CacheLockTimeout
from specguard.spec.spec import Spec
from specguard.spec.trainers import SB3
from specguard.training.result import RunResult
from specguard.tree.keys import result_keys
from specguard.utils.atomic import staged

__all__ = [
    "SECRET_ENV",
    "Cache",
    "CacheLockTimeout",
    "file_sha256",
    "model_files",
    "run_files",
    "try_acquire",
    "validate_record",
    "wait_for",
]

SECRET_ENV = "SPECGUARD_CACHE_KEY"
FORMAT = 5  # 3: runs record met_early (anytime verdicts); 4: adapted weights; 5: stopped_early is hit_wall_clock
MODEL = "model.zip"
AGENT = "agent.pkl"  # a trainer's agent (Spec(trainer=...)), in place of MODEL
NORMALIZER = "vecnormalize.pkl"
RESULT = "result.json"


def file_sha256(path: Path) -> str:
    """The SHA-256 of the file ``path``'s bytes, read a megabyte at a time (a model's zip, its statistics)."""
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _checksum(record: dict[str, Any]) -> str:
    body = {k: v for k, v in record.items() if k not in ("checksum", "signature")}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _sign(secret: bytes, checksum: str) -> str:
    return hmac.new(secret, checksum.encode(), hashlib.sha256).hexdigest()


# -- the checks a stored record must pass, one invariant each ------------------------


def _check_envelope(record: Any, key: str) -> None:
    if not isinstance(record, dict):
        raise ValueError(f"expected a JSON object, got {type(record).__name__}")
    if record.get("format") != FORMAT:
        raise ValueError(f"format {record.get('format')!r}, expected {FORMAT}")
    if record.get("fingerprint") != key:
        raise ValueError("the recorded fingerprint is not the entry's key")


def _check_checksum(record: dict[str, Any]) -> None:
    if record.get("checksum") != _checksum(record):
        raise ValueError("checksum does not match the contents (edited or damaged)")


def _check_signature(record: dict[str, Any], secret: bytes | None) -> None:
    if secret is None:
        return
    signature = record.get("signature")
    if not isinstance(signature, str) or not hmac.compare_digest(signature, _sign(secret, str(record["checksum"]))):
        raise ValueError(f"no valid signature for the key in {SECRET_ENV}")


def _check_files(record: dict[str, Any], folder: Path, *, model: bool = True) -> None:
    files = record.get("files")
    if not isinstance(files, dict) or (MODEL in files or AGENT in files) != model:
        raise ValueError("no file checksums recorded" if model else "a model recorded in an evaluation's entry")
    for name, expected in files.items():
        if name not in (MODEL, AGENT, NORMALIZER):
            raise ValueError(f"unexpected file {name!r} recorded")
        if not (folder / name).is_file() or file_sha256(folder / name) != expected:
            raise ValueError(f"{name} is missing or does not match its checksum")


def _check_versions(record: dict[str, Any]) -> None:
    if record.get("versions") != versions():
        raise ValueError("made with other versions of specguard or its dependencies")


def validate_record(
    record: Any,
    folder: Path,
    *,
    key: str,
    seed: int,
    paths: Collection[str],
    secret: bytes | None,
    model: bool = True,
) -> RunResult:
    """The run stored in ``record`` (parsed ``result.json`` of ``folder``), after every check.

    ``paths`` are the keys the run must have measured, exactly: the tree's node
    paths and its safety keys (:func:`specguard.tree.keys.result_keys`). ``model``: the entry holds the run's
    model (a trained run), or no file at all (an evaluation of an agent trained elsewhere).

    Raises:
        ValueError: the first check that failed, in words.
    """
    _check_envelope(record, key)
    _check_checksum(record)
    _check_signature(record, secret)
    _check_files(record, folder, model=model)
    _check_versions(record)
    return RunResult.from_dict(record.get("result"), seed=seed, paths=paths)


def _secret_from_env() -> bytes | None:
    value = os.environ.get(SECRET_ENV)
    return value.encode() if value else None


class Cache:
    """Trained runs on disk, keyed by the spec's fingerprint and the seed.

    Args:
        root: the cache folder (created on first store).
        secret: the HMAC key for signed entries; default: the environment
            variable :data:`SECRET_ENV`, if set.
    """

    def __init__(self, root: Path | str, *, secret: bytes | None = None) -> None:
        self.root = Path(root)
        self.secret = secret if secret is not None else _secret_from_env()

    def folder(self, key: str) -> Path:
        """Where the entry of run key ``key`` lives."""
        return self.root / key[:2] / key

    def entry(self, spec: Spec, seed: int) -> Path:
        return self.folder(fingerprint_spec(spec).run_key(seed))

    def model_path(self, spec: Spec, seed: int) -> Path:
        """Where the run's model is (``PPO.load(cache.model_path(spec, seed))``)."""
        return self.entry(spec, seed) / MODEL

    def load(self, spec: Spec, seed: int) -> RunResult | None:
        """The cached result of the run, or ``None`` when absent or not trustworthy."""
        return self.load_key(fingerprint_spec(spec).run_key(seed), seed=seed, paths=_paths(spec))

    def load_key(self, key: str, *, seed: int, paths: Collection[str], model: bool = True) -> RunResult | None:
        """The run stored under ``key`` if it passes :func:`validate_record`; a failing entry is discarded.

        ``model=False``: an evaluation's entry (:meth:`store_evaluation`), which holds no file.
        """
        folder = self.folder(key)
        if not folder.exists():
            return None
        try:
            record = json.loads((folder / RESULT).read_text())
            return validate_record(record, folder, key=key, seed=seed, paths=paths, secret=self.secret, model=model)
        except (OSError, ValueError, KeyError, TypeError, RecursionError) as e:  # RecursionError: JSON nested deep
            # Damaged, edited, unsigned or stale: remove it so the retrained run can take its place.
            shutil.rmtree(folder, ignore_errors=True)
            again = "retraining" if model else "evaluating again"
            warnings.warn(f"specguard cache: discarded entry {folder} ({e}); {again}", stacklevel=2)
            return None

    def store(self, spec: Spec, seed: int, result: RunResult, model: Any) -> Path:
        """Write the run atomically; returns its folder."""
        files, _ = run_files(spec, model)  # a training loop's agent that cannot be pickled: the result alone
        return self.store_files(fingerprint_spec(spec).run_key(seed), result, files)

    def store_key(self, key: str, result: RunResult, model: Any, *, normalize: bool) -> Path:
        """Write a run under ``key`` atomically (see :meth:`store_files`)."""
        return self.store_files(key, result, model_files(model, normalize=normalize))

    def store_files(self, key: str, result: RunResult, files: dict[str, bytes]) -> Path:
        """Write a run's result and files (:func:`model_files`) under ``key``: a temporary folder renamed into place.

        The driver stores what a worker sent back, so workers need no shared filesystem.
        """
        unknown = sorted(set(files) - {MODEL, AGENT, NORMALIZER})
        if (MODEL in files) == (AGENT in files) or unknown:
            raise ValueError(f"expected {MODEL} (and optionally {NORMALIZER}) or {AGENT}, got files {sorted(files)}")
        return self._write(key, result, files)

    def store_evaluation(self, key: str, result: RunResult) -> Path:
        """Write an evaluation of an agent trained elsewhere (:func:`specguard.engine.check_agent.check_agent`):
        the result alone, no file (the agent is the user's, not the cache's); read back with
        ``load_key(key, model=False)``."""
        return self._write(key, result, {})

    def _write(self, key: str, result: RunResult, files: dict[str, bytes]) -> Path:
        folder = self.folder(key)
        with staged(folder, folder=True) as tmp:
            for name, data in sorted(files.items()):
                (tmp / name).write_bytes(data)
            record: dict[str, Any] = {
                "format": FORMAT,
                "fingerprint": key,
                "versions": versions(),
                "files": {name: hashlib.sha256(data).hexdigest() for name, data in sorted(files.items())},
                "result": result.to_dict(),
            }
            record["checksum"] = _checksum(record)
            if self.secret is not None:
                record["signature"] = _sign(self.secret, record["checksum"])
            (tmp / RESULT).write_text(json.dumps(record, indent=1))
            try:
                os.rename(tmp, folder)  # atomic; fails if another process stored it first
            except OSError:
                if not folder.exists():
                    raise
        return folder

    def lock(self, key: str, timeout: float) -> Any:
        """A file lock for run ``key`` (``filelock.FileLock``); the OS releases it if its holder dies."""
        from filelock import FileLock

        path = self.folder(key).parent / f"{key}.lock"
        path.parent.mkdir(parents=True, exist_ok=True)
        return FileLock(str(path), timeout=timeout, thread_local=False)


def model_files(model: Any, *, normalize: bool) -> dict[str, bytes]:
    """A trained SB3 model (and its ``VecNormalize`` statistics) as the bytes of the entry's files."""
    with tempfile.TemporaryDirectory(prefix="specguard-model-") as tmp:
        model.save(Path(tmp) / MODEL)
        env = model.get_env()
        if normalize and hasattr(env, "save"):
            env.save(str(Path(tmp) / NORMALIZER))
        return {p.name: p.read_bytes() for p in sorted(Path(tmp).iterdir())}


def run_files(spec: Spec, model: Any) -> tuple[dict[str, bytes], str | None]:
    """A trained run's entry files, and why they are none: an SB3 trainer's model (:func:`model_files`), or a training
    loop's last agent pickled (cloudpickle, as the spec reaches a worker), or ``({}, why)`` when it cannot be
    pickled."""
    if isinstance(spec.trainer, SB3):
        return model_files(model, normalize=spec.trainer.normalize), None
    import cloudpickle

    try:
        return {AGENT: cloudpickle.dumps(model)}, None
    except Exception as e:  # a lock, a file, a generator in it: the run is kept and judged all the same
        return {}, f"its agent {type(model).__name__} cannot be pickled ({type(e).__name__}: {e})"


def _paths(spec: Spec) -> list[str]:
    return result_keys(spec.tree)


def try_acquire(lock: Any) -> bool:
    """Take ``lock`` if it is free right now."""
    from filelock import Timeout

    try:
        lock.acquire(timeout=0)
    except Timeout:
        return False
    return True


def wait_for(lock: Any, what: str, timeout: float) -> None:
    """Acquire ``lock``, raising :class:`CacheLockTimeout` with a clear message after ``timeout`` seconds."""
    from filelock import Timeout

    try:
        lock.acquire(timeout=timeout)
    except Timeout:
        raise CacheLockTimeout(
            f"{what}: another process has been training this run for over {timeout:g} s (lock {lock.lock_file}); "
            "wait for it, or raise the lock timeout. A lock is released by the OS when its process ends, so a "
            "stale lock means that process still runs"
        ) from None
