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
