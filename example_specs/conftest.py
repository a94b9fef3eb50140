"""Opt-in markers: ``paper`` (the paper's negative results, full budgets), ``long`` (passing specs that train for
many minutes) and ``highway`` (highway-env, slow).

Their specs run only when ``-m`` names the marker. ``highway.py`` needs the ``highway`` extra, which
README's first command does not install: without it, the main job collects neither it nor
``test_highway.py`` (with ``-m highway``, the latter is skipped, saying why).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

OPT_IN = {
    "paper": "a spec the main job leaves out (it trains its whole budget); opt in with -m paper",
    "long": "a passing spec the main job leaves out (many minutes per seed on 2 cores); opt in with -m long",
    "highway": "a highway-env spec the main job leaves out (minutes per seed); opt in with -m highway",
}


def named(config: pytest.Config, marker: str) -> bool:
    """``-m`` names ``marker``: pytest's own selection decides."""
    return marker in (config.getoption("markexpr") or "")


def pytest_configure(config: pytest.Config) -> None:
    for marker, description in OPT_IN.items():
        config.addinivalue_line("markers", f"{marker}: {description}")


def pytest_ignore_collect(collection_path: Path, config: pytest.Config) -> bool | None:
    """Without the highway extra, ``highway.py`` (its doctests import it) is not collected, nor is
    ``test_highway.py`` unless ``-m`` names ``highway``, where it is skipped with the reason."""
    if collection_path.name not in ("highway.py", "test_highway.py") or importlib.util.find_spec("highway_env"):
        return None
    return collection_path.name == "highway.py" or not named(config, "highway")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for marker in OPT_IN:
        if named(config, marker):
            continue
        left_out = [item for item in items if item.get_closest_marker(marker)]
        if left_out:
            config.hook.pytest_deselected(items=left_out)
            items[:] = [item for item in items if not item.get_closest_marker(marker)]
