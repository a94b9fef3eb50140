"""The curated public namespace, imported lazily."""

from __future__ import annotations

import subprocess
import sys

import specguard as sg


def test_every_public_name_resolves():
    for name in sg.__all__:
        assert getattr(sg, name) is not None
    assert set(dir(sg)) >= set(sg.__all__)


def test_unknown_attribute():
    import pytest

    with pytest.raises(AttributeError, match="has no attribute 'Nope'"):
        sg.Nope  # noqa: B018


def test_import_is_light():
    heavy = "{'torch', 'scipy', 'gymnasium', 'stable_baselines3'}"
    code = f"import sys, specguard, specguard.pytest_plugin.plugin; print(sorted({heavy} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_the_type_checking_imports_are_the_public_names_from_their_modules():
    # Type checkers read the TYPE_CHECKING block; the runtime reads _EXPORTS: one must say what the other does.
    import ast
    from pathlib import Path

    tree = ast.parse(Path(sg.__file__).read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If) and getattr(n.test, "id", None) == "TYPE_CHECKING")
    imported = {
        alias.name: node.module for node in block.body if isinstance(node, ast.ImportFrom) for alias in node.names
    }
    assert imported == {
        name: module for name, module in sg._EXPORTS.items() if name not in ("GoalEnv", "GoalInfo")
    }  # deprecated: untyped


def test_the_public_paths_import():
    import importlib

    for module in [
        "specguard.extend",
        "specguard.testing",
        "specguard.strategies",
        "specguard.registry",
        "specguard.validation",
        "specguard.error",
        "specguard.__main__",
    ]:
        importlib.import_module(module) if module != "specguard.__main__" else importlib.util.find_spec(module)
    from importlib import metadata

    entry = {e.name: e.value for e in metadata.entry_points(group="pytest11")}["specguard"]
    assert importlib.import_module(entry).pytest_addoption  # the plugin's hooks, by the entry point's own path
    script = {e.name: e for e in metadata.entry_points(group="console_scripts")}["specguard"]
    assert callable(script.load())
