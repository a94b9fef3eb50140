"""Files written whole: the mode a written file gets (the umask for a new one, its own for one overwritten)."""

from __future__ import annotations

import os
import stat
import sys

import pytest

from specguard.utils.atomic import staged, write_atomic

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX file modes")


def mode(path):
    return stat.S_IMODE(path.stat().st_mode)


@pytest.fixture
def umask():
    """Set the process umask for one test, and restore it after."""
    old = os.umask(0o022)
    os.umask(old)

    def set_to(mask):
        os.umask(mask)

    yield set_to
    os.umask(old)


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o077])
def test_a_new_file_follows_the_umask(tmp_path, umask, mask):
    umask(mask)
    path = write_atomic(tmp_path / "new" / "result.json", "{}")
    assert mode(path) == 0o666 & ~mask
    assert path.read_text() == "{}"


@pytest.mark.parametrize("existing", [0o644, 0o664, 0o600, 0o640])
def test_an_overwritten_file_keeps_its_mode(tmp_path, umask, existing):
    umask(0o077)  # a umask stricter than the file: the file's own mode wins
    path = tmp_path / "baseline.json"
    path.write_text("old")
    path.chmod(existing)
    write_atomic(path, b"new")
    assert mode(path) == existing and path.read_bytes() == b"new"


def test_a_staged_folder_follows_the_umask_and_nothing_is_left_behind(tmp_path, umask):
    umask(0o022)
    with staged(tmp_path / "entry", folder=True) as tmp:
        assert mode(tmp) == 0o755
        os.rename(tmp, tmp_path / "entry")
    assert mode(tmp_path / "entry") == 0o755
    with pytest.raises(RuntimeError), staged(tmp_path / "x.json") as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["entry"]
