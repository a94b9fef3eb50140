"""The ``paper`` marker: the paper's negative results (full budgets) run only when ``-m`` asks for them."""

from __future__ import annotations

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "paper: a spec the main job leaves out (it trains its whole budget); opt in with -m paper"
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if "paper" in (config.getoption("markexpr") or ""):
        return  # -m names the marker: pytest's own selection decides
    left_out = [item for item in items if item.get_closest_marker("paper")]
    if left_out:
        config.hook.pytest_deselected(items=left_out)
        items[:] = [item for item in items if not item.get_closest_marker("paper")]
