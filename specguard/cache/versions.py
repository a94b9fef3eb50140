"""Which code a run is made by: specguard's source digest, installed libraries' versions, and the check workers make.

Library code (the standard library, installed distributions, specguard) enters
a cache key by name and version, not content (:mod:`specguard.cache.canonical`);
specguard by its version and a digest of every source file of the package.
"""

from __future__ import annotations

import functools
import hashlib
import sys
import sysconfig
from collections.abc import Mapping
from importlib import metadata
from pathlib import Path

from specguard.error import VersionMismatch
from specguard.version import __version__

__all__ = ["check_versions", "library_module", "source_digest", "torch_capability", "versions"]

_VERSIONED = ("gymnasium", "stable-baselines3", "torch", "numpy", "scipy", "cloudpickle")


# -- where code comes from --------------------------------------------------------


@functools.cache
def _library_roots() -> tuple[str, ...]:
    paths = sysconfig.get_paths()
    roots = {str(Path(paths[k]).resolve()) for k in ("stdlib", "platstdlib", "purelib", "platlib") if k in paths}
    return tuple(sorted(roots))


@functools.cache
def _distribution_versions() -> dict[str, str]:
    """Top-level import name -> "dist==version" of the installed distributions."""
    out: dict[str, str] = {}
    for top, dists in metadata.packages_distributions().items():
        found = []
        for d in sorted(set(dists)):
            try:
                found.append(f"{d}=={metadata.version(d)}")
            except metadata.PackageNotFoundError:
                continue
        out[top] = ",".join(found)
    return out


@functools.cache
def _specguard_digest() -> str:
    """specguard's version and a digest of its own source: a change to the engine misses the cache too."""
    return f"{__version__}+{source_digest(Path(__file__).resolve().parents[1])}"


def source_digest(package: Path) -> str:
    """A digest of every Python source file under ``package``, subpackages included, and of where each lies.

    A file's path relative to ``package`` is part of the digest, so moving a
    module changes it as much as editing one.
    """
    h = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        relative = path.relative_to(package).as_posix()
        if "__pycache__" in relative:
            continue
        h.update(relative.encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


@functools.cache
def library_module(name: str) -> str | None:
    """The version tag of ``name`` if it is library code (stdlib, an installed package or specguard), else None."""
    top = name.split(".", 1)[0]
    if top == "specguard":
        return _specguard_digest()
    if top in sys.stdlib_module_names or top in sys.builtin_module_names:
        return f"python=={sys.version.split()[0]}"
    module = sys.modules.get(name) or sys.modules.get(top)
    file = getattr(module, "__file__", None)
    if module is None or file is None:
        return None
    resolved = str(Path(file).resolve())
    if not any(resolved.startswith(root + "/") for root in _library_roots()):
        return None  # the user's own code (also an editable install): followed by content
    return _distribution_versions().get(top, "unversioned")


def _loaded_versions() -> dict[str, str]:
    """The versions of the libraries of :data:`_VERSIONED` this process has imported, as the modules state them."""
    loaded = {}
    for name in _VERSIONED:
        module = sys.modules.get(name.replace("-", "_"))
        version = getattr(module, "__version__", None)
        if isinstance(version, str):
            loaded[name] = version
    return loaded


def _public(version: str) -> str:
    """A version without its local label (PEP 440's ``+...``): PyPI's torch wheel is ``2.13.0`` installed and
    ``2.13.0+cu130`` as ``torch.__version__`` says it, the same code; an upgrade changes the public part."""
    return version.split("+", 1)[0]


def versions() -> dict[str, str]:
    """The versions that decide a run's outcome beside the spec: Python, specguard and the RL stack."""
    found = {"python": sys.version.split()[0], "specguard": _specguard_digest()}
    for name in _VERSIONED:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = "absent"
    return found


def check_versions(expected: Mapping[str, str], where: str) -> None:
    """Refuse to go on in a process whose :func:`versions` differ from ``expected`` (the ones a key was made with).

    The libraries this process has imported must also be the installed ones: a process forked from a server
    that imported them before an upgrade (:mod:`specguard.parallel.workers`) runs the old code, while
    :func:`versions` reads the installed one.

    Raises:
        VersionMismatch: naming each version that differs, expected and found, or loaded and installed.
    """
    found = versions()
    stale = [
        f"{name} {loaded} (loaded) != {found[name]} (installed)"
        for name, loaded in _loaded_versions().items()
        if _public(loaded) != _public(found.get(name, ""))
    ]
    if stale:  # a process forked from a server that imported them before an upgrade (specguard.parallel.workers)
        named = "; ".join(stale)
        raise VersionMismatch(f"{where}: this process runs libraries other than the installed ones: {named}")
    differing = [
        f"{name} {expected.get(name, 'absent')!s} (keyed) != {found.get(name, 'absent')!s} (here)"
        for name in sorted(set(expected) | set(found))
        if expected.get(name) != found.get(name)
    ]
    if differing:
        named = "; ".join(differing)
        raise VersionMismatch(f"{where}: this process runs other code than the run's cache key names: {named}")


def torch_capability() -> str:
    """The vector kernels torch computes with in this process (``DEFAULT``, ``AVX2``, ``AVX512``): chosen once, when
    torch first computes (:mod:`specguard.utils.numerics`)."""
    import torch

    return str(torch.backends.cpu.get_cpu_capability())
