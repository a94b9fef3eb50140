"""Files written whole or not at all: the one way specguard writes results, baselines, reports and cache entries.

A reader never sees a half-written file: data goes to a temporary file (or
folder) beside its destination, which replaces the destination in one rename.
The temporary is removed whatever happens, an error included.

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
import shutil
import tempfile
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
    if folder:
        tmp = Path(tempfile.mkdtemp(prefix=".tmp-", dir=destination.parent))
    else:
        fd, name = tempfile.mkstemp(prefix=f".tmp-{destination.name}-", dir=destination.parent)
        os.close(fd)
        tmp = Path(name)
    try:
        yield tmp
    finally:
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()


def write_atomic(path: Path | str, data: str | bytes) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` whole or not at all, and return ``path``.

    Raises:
        OSError: the folder cannot be made or written (nothing is left behind).
    """
    path = Path(path)
    with staged(path) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
        os.replace(tmp, path)
    return path
