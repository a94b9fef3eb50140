"""Files written whole or not at all: the one way specguard writes results, baselines, reports and cache entries.

A reader never sees a half-written file: data goes to a temporary file (or
folder) beside its destination, which replaces the destination in one rename.
The temporary is removed whatever happens, an error included.

A written file has the mode any other program's would: a new one follows the
umask (``0644`` under the usual ``022``), and one overwritten keeps its own, so
a baseline or a CI report stays readable to whoever could read it before.

Example:
    >>> import tempfile
    >>> from pathlib import Path
    >>> folder = Path(tempfile.mkdtemp())
    >>> write_atomic(folder / "out" / "result.json", '{"passed": true}')
    PosixPath('...result.json')
    >>> sorted(p.name for p in (folder / "out").iterdir())
    ['result.json']
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import stat
from collections.abc import Iterator
from pathlib import Path

__all__ = ["DEFAULT_CACHE_DIR", "staged", "write_atomic"]

DEFAULT_CACHE_DIR = ".specguard/cache"
"""Where every door caches trained runs unless told otherwise (relative to the working directory)."""


@contextlib.contextmanager
def staged(destination: Path, *, folder: bool = False) -> Iterator[Path]:
    """A temporary file (or, with ``folder``, a folder) beside ``destination``, removed when the block ends.

    Move it into place inside the block (``os.replace`` / ``os.rename``); what is
    left of it afterwards, after an error too, is deleted. The parent folder is
    created if needed.
    """
    destination.parent.mkdir(parents=True, exist_ok=True)
    tmp = _fresh(destination.parent, ".tmp-" if folder else f".tmp-{destination.name}-", folder=folder)
    try:
        yield tmp
    finally:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()


def _fresh(parent: Path, prefix: str, *, folder: bool) -> Path:
    """A new, empty file (or folder) in ``parent`` under an unused name, its mode from the umask.

    ``tempfile.mkstemp`` and ``mkdtemp`` make ``0600``/``0700`` whatever the umask
    says; a file or folder moved into place must read as one written directly.
    """
    for _ in range(100):
        path = parent / f"{prefix}{secrets.token_hex(6)}"
        try:
            if folder:
                os.mkdir(path, 0o777)
            else:
                os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"no unused temporary name in {str(parent)!r} after 100 tries")


def _keep_mode(tmp: Path, path: Path) -> None:
    """Give ``tmp`` the mode of the file it replaces, if there is one (a new file keeps the umask's)."""
    try:
        existing = os.stat(path)
    except FileNotFoundError:
        return
    os.chmod(tmp, stat.S_IMODE(existing.st_mode))


def write_atomic(path: Path | str, data: str | bytes) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` whole or not at all, and return ``path``.

    A new file's mode follows the umask; a file overwritten keeps its mode.

    Raises:
        OSError: the folder cannot be made or written (nothing is left behind).
    """
    path = Path(path)
    with staged(path) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
        _keep_mode(tmp, path)
        os.replace(tmp, path)
    return path
