"""The curated public namespace, imported lazily."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

import specguard as sg


def test_every_public_name_resolves():
    for name in sg.__all__:
        assert getattr(sg, name) is not None
    assert set(dir(sg)) >= set(sg.__all__)


def test_unknown_attribute():
    import pytest

    with pytest.raises(AttributeError, match="has no attribute 'Nope'"):
        sg.Nope  # noqa: B018


@pytest.mark.slow
def test_import_is_light():
    heavy = "{'torch', 'scipy', 'gymnasium', 'stable_baselines3'}"
    code = f"import sys, specguard, specguard.pytest_plugin.plugin; print(sorted({heavy} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


@pytest.mark.slow
def test_star_import_is_silent_under_warnings_as_errors():
    # A fresh interpreter: every public name is imported for the first time, and any warning fails the import.
    code = "from specguard import *; print(len([n for n in dir() if not n.startswith('_')]))"
    run = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert int(run.stdout) == len(sg.__all__) - 1  # every name but __version__


def test_the_names_no_release_had_are_gone():
    for name in ("GoalEnv", "GoalInfo"):
        assert name not in sg.__all__
        assert not hasattr(sg, name)
        assert not hasattr(importlib.import_module("specguard.construction.env"), name)


def test_the_type_checking_imports_are_the_public_names_from_their_modules():
    # Type checkers read the TYPE_CHECKING block; the runtime reads _EXPORTS: one must say what the other does.
    import ast
    from pathlib import Path

    tree = ast.parse(Path(sg.__file__).read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If) and getattr(n.test, "id", None) == "TYPE_CHECKING")
    imported = {
        alias.name: node.module for node in block.body if isinstance(node, ast.ImportFrom) for alias in node.names
    }
    assert imported == sg._EXPORTS


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


def test_every_error_a_user_may_catch_is_under_sg_error_and_its_root_at_the_top():
    from specguard import error

    assert sg.error is error and sg.SpecError is error.SpecError
    assert issubclass(sg.error.InvalidSpec, sg.SpecError)
    assert all(getattr(sg, name) is importlib.import_module(f"specguard.{name}") for name in sg._SUBMODULES)


@pytest.mark.parametrize("name", ["InvalidSpec", "SpecWarning", "Cache", "check_spec", "load_normalizer", "Annotation"])
def test_a_name_the_face_gave_up_still_resolves_with_a_warning_naming_its_home(name):
    home = sg._MOVED[name]
    with pytest.warns(DeprecationWarning, match=rf"specguard\.{name} moved to {home}\.{name}"):
        value = getattr(sg, name)
    assert value is getattr(importlib.import_module(home), name)
    assert name not in sg.__all__ and name not in dir(sg)
