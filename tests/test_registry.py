"""Operators by name: built-ins, entry-point plugins (broken ones reported once), explicit registrations."""

from __future__ import annotations

import warnings
from importlib import metadata

import pytest

import specguard as sg
from specguard import registry


class _FakeDist:
    def __init__(self, name: str) -> None:
        self.name = name


class _FakeEntryPoint:
    def __init__(self, name: str, value: object, dist: str, error: Exception | None = None) -> None:
        self.name, self.value, self.dist = name, f"fake_module:{name}", _FakeDist(dist)
        self._loaded, self._error = value, error

    def load(self) -> object:
        if self._error is not None:
            raise self._error
        return self._loaded


class Shiny(sg.Goal):
    kind = "Shiny"


@pytest.fixture
def plugins(monkeypatch):
    """Install fake entry points; the registry forgets what it loaded before and after."""

    def install(*entry_points: _FakeEntryPoint) -> None:
        def fake(group: str) -> list[_FakeEntryPoint]:
            return list(entry_points) if group == registry.GROUP else []

        monkeypatch.setattr(metadata, "entry_points", fake)
        monkeypatch.setattr(registry, "_plugins", None)

    monkeypatch.setattr(registry, "_explicit", {})
    yield install
    monkeypatch.setattr(registry, "_plugins", None)


def test_builtins_are_registered():
    assert {"Goal", "All", "Distance", "Constraint"} <= set(registry.registered())
    assert registry.lookup("Constraint") is sg.Constraint


def test_a_plugin_is_found_by_entry_point_and_as_an_attribute(plugins):
    plugins(_FakeEntryPoint("Shiny", Shiny, "shiny-ops"))
    assert registry.lookup("Shiny") is Shiny
    assert sg.Shiny is Shiny  # type: ignore[attr-defined]


def test_broken_plugins_are_reported_once_naming_the_distribution_and_skipped(plugins):
    plugins(
        _FakeEntryPoint("Broken", None, "broken-ops", error=ImportError("No module named 'nowhere'")),
        _FakeEntryPoint("NotAClass", 42, "odd-ops"),
        _FakeEntryPoint("All", Shiny, "greedy-ops"),
        _FakeEntryPoint("Shiny", Shiny, "shiny-ops"),
        _FakeEntryPoint("Shiny", sg.Goal, "copycat-ops"),
    )
    with pytest.warns(registry.PluginWarning) as caught:
        classes = registry.registered()
    messages = [str(w.message) for w in caught]
    assert len(messages) == 4
    assert "plugin 'broken-ops', entry point Broken" in messages[0]
    assert "failed to load (ImportError: No module named 'nowhere'); skipped" in messages[0]
    assert "plugin 'odd-ops'" in messages[1] and "got 42" in messages[1]
    assert "the name 'All' is already taken by specguard itself" in messages[2]
    assert "the name 'Shiny' is already taken by plugin 'shiny-ops'" in messages[3]
    assert classes["Shiny"] is Shiny and classes["All"] is sg.All  # the good plugin and the built-ins still work
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        registry.registered()  # once: no second report


def test_a_broken_plugin_does_not_break_specs(plugins):
    plugins(_FakeEntryPoint("Broken", None, "broken-ops", error=RuntimeError("boom")))
    with pytest.warns(registry.PluginWarning), pytest.raises(AttributeError, match="no attribute 'Missing'"):
        sg.Missing  # type: ignore[attr-defined]  # noqa: B018
    tree = sg.All(sg.Goal("g", x=(0, 1)), name="r")
    assert sg.formula(tree) == "R = R[g]"


def test_explicit_registration_and_its_errors(plugins):
    plugins()
    assert registry.register(Shiny) is Shiny
    assert registry.lookup("Shiny") is Shiny
    with pytest.raises(
        sg.error.InvalidSpec, match=r"register\('Goal'\): the name 'Goal' is already taken by specguard"
    ):
        registry.register(Shiny, name="Goal")
    with pytest.raises(
        sg.error.InvalidSpec, match=r"expected a subclass of specguard.extend.Node or Annotation, got 3"
    ):
        registry.register(3)  # type: ignore[arg-type]
    with pytest.raises(KeyError, match=r"no specguard operator or annotation named 'Nope'; known: .*Shiny"):
        registry.lookup("Nope")
