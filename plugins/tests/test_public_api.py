"""The plugin is written against specguard's public extension API only, and is found through its entry points."""

from __future__ import annotations

import ast
import doctest
import importlib
import pkgutil
import subprocess
import sys
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import pytest
import specguard_plugins
from specguard_plugins import AnyOf, Avoid, Sequence, anyof, avoid, sequence

import specguard as sg
from specguard import registry

PACKAGE = Path(specguard_plugins.__file__).parent
ALLOWED = frozenset(
    {
        "specguard",
        "specguard.extend",
        "specguard.validation",
        "specguard.error",
        "specguard.testing",
        "specguard.strategies",
        "specguard.registry",
    }
)
SUBMODULES = frozenset(f"specguard.{m.name}" for m in pkgutil.iter_modules(sg.__path__))
IMPORTERS = frozenset({"import_module", "__import__"})


def _is_specguard(module: str) -> bool:
    return module == "specguard" or module.startswith("specguard.")


def private_uses(source: str, filename: str = "<source>") -> list[str]:
    """Every use of specguard beyond its public extension API in ``source``, as ``"line: what"``.

    Flags: importing a specguard module other than those in ``ALLOWED`` (by
    ``import``, ``from ... import``, ``from specguard import <submodule>``,
    ``importlib.import_module`` or ``__import__``), a star import from
    specguard, any name starting with ``_`` imported from or read off a
    specguard module, and reaching a non-public submodule as an attribute
    (``sg.tree.nodes.Goal``).
    """
    tree = ast.parse(source, filename)
    found: list[str] = []
    modules: dict[str, str] = {}  # local name -> the specguard module it is bound to

    def flag(node: ast.AST, what: str) -> None:
        found.append(f"{filename}:{getattr(node, 'lineno', '?')}: {what}")

    def check_module(node: ast.AST, module: str) -> None:
        if any(part.startswith("_") for part in module.split(".")):
            flag(node, f"private module {module}")
        elif module not in ALLOWED:
            flag(node, f"non-public module {module}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if _is_specguard(alias.name):
                    check_module(node, alias.name)
                    if alias.asname is not None:
                        modules[alias.asname] = alias.name
                    else:
                        modules["specguard"] = "specguard"  # `import specguard.x` binds `specguard`
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and _is_specguard(node.module):
            check_module(node, node.module)
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                if alias.name == "*":
                    flag(node, f"star import from {node.module}")
                elif alias.name.startswith("_"):
                    flag(node, f"private name {full}")
                elif full in SUBMODULES:
                    check_module(node, full)
                    modules[alias.asname or alias.name] = full
        elif isinstance(node, ast.Call):
            fn = node.func
            name = fn.attr if isinstance(fn, ast.Attribute) else fn.id if isinstance(fn, ast.Name) else ""
            if name in IMPORTERS and node.args:
                arg = node.args[0]
                if isinstance(arg, ast.Constant) and isinstance(arg.value, str) and _is_specguard(arg.value):
                    check_module(node, arg.value)
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules:
            owner = modules[node.value.id]
            if node.attr.startswith("_"):
                flag(node, f"private name {owner}.{node.attr}")
            elif f"{owner}.{node.attr}" in SUBMODULES:
                check_module(node, f"{owner}.{node.attr}")
    return found


def plugin_sources() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_the_plugin_has_sources_to_check():
    names = {p.name for p in plugin_sources()}
    assert {"__init__.py", "anyof.py", "sequence.py", "avoid.py"} <= names


@pytest.mark.parametrize("path", plugin_sources(), ids=lambda p: p.name)
def test_plugin_sources_import_only_the_public_extension_api(path):
    assert private_uses(path.read_text(encoding="utf-8"), path.name) == []


@pytest.mark.parametrize(
    "source",
    [
        "from specguard.tree.nodes import Goal",
        "from specguard.construction.reference import process",
        "import specguard.construction.compiled",
        "import specguard.construction.codegen as cg",
        "from specguard.extend import _private",
        "from specguard.extend import annotation_key, _call",
        "from specguard import _EXPORTS",
        "from specguard import tree",
        "from specguard import engine",
        "from specguard import *",
        "from specguard._vendored import x",
        "import specguard as sg\nsg.tree.nodes.Goal",
        "import specguard as sg\nsg._EXPORTS",
        "from specguard import strategies as st\nst._values",
        "import importlib\nimportlib.import_module('specguard.construction.compiled')",
        "__import__('specguard.construction.reference')",
        "def f():\n    from specguard.construction.initial_env import state_type",
    ],
)
def test_the_checker_flags_private_uses(source):
    assert private_uses(source) != []


@pytest.mark.parametrize(
    "source",
    [
        "import specguard as sg\nsg.Goal('g', x=1)",
        "import specguard\nimport specguard.extend",
        "from specguard import Goal, strategies",
        "from specguard.extend import SHAPING, Node, check_children, goal_test",
        "from specguard.validation import check_name, number_text",
        "from specguard.error import InvalidSpec",
        "from specguard.testing import ReplayEnv",
        "from specguard.strategies import goals, weights",
        "from specguard.registry import lookup",
        "from . import anyof\nfrom ._checks import check_weights",
        "import hypothesis._internal",
        "import importlib\nimportlib.import_module('specguard.extend')",
    ],
)
def test_the_checker_passes_public_uses(source):
    assert private_uses(source) == []


def imported_names(source: str) -> list[tuple[str, str]]:
    """``(module, name)`` for each ``from specguard... import name`` in ``source`` (module level or not)."""
    return [
        (node.module, alias.name)
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and _is_specguard(node.module)
        for alias in node.names
    ]


def test_every_name_the_plugin_imports_is_listed_in_its_module_all():
    """What a plugin imports is the API specguard keeps: a name in the public module's ``__all__`` (or a submodule)."""
    used = sorted({pair for path in plugin_sources() for pair in imported_names(path.read_text(encoding="utf-8"))})
    assert ("specguard.validation", "number_text") in used  # the reader reads them
    unlisted = [
        f"{module}.{name}"
        for module, name in used
        if f"{module}.{name}" not in SUBMODULES and name not in importlib.import_module(module).__all__
    ]
    assert unlisted == []


# -- names --------------------------------------------------------------------


def test_curated_all():
    assert specguard_plugins.__all__ == ["AnyOf", "Avoid", "Sequence"]
    assert (anyof.__all__, sequence.__all__, avoid.__all__) == (["AnyOf"], ["Sequence"], ["Avoid"])
    for module in (specguard_plugins, anyof, sequence, avoid):
        for name in module.__all__:
            assert getattr(module, name).__module__.startswith("specguard_plugins")
    submodules_and_future = ["annotations", "anyof", "avoid", "sequence"]
    public = [n for n in dir(specguard_plugins) if not n.startswith("_")]
    assert sorted(public) == sorted(specguard_plugins.__all__ + submodules_and_future)


def test_classes_subclass_the_extension_api():
    assert issubclass(AnyOf, sg.Node) and issubclass(Sequence, sg.Node) and issubclass(Avoid, sg.extend.Annotation)
    assert (AnyOf.kind, Sequence.kind) == ("AnyOf", "Sequence")


# -- entry points -------------------------------------------------------------


def test_entry_points_are_declared_by_the_distribution():
    eps = {
        ep.name: ep
        for ep in metadata.entry_points(group=registry.GROUP)
        if ep.dist and ep.dist.name == "specguard-plugins"
    }
    assert {name: ep.value for name, ep in eps.items()} == {
        "AnyOf": "specguard_plugins.anyof:AnyOf",
        "Sequence": "specguard_plugins.sequence:Sequence",
        "Avoid": "specguard_plugins.avoid:Avoid",
    }
    assert metadata.version("specguard-plugins") == specguard_plugins.__version__ == "0.1.0"


def test_registry_finds_the_operators_by_name():
    assert registry.lookup("AnyOf") is AnyOf
    assert registry.lookup("Sequence") is Sequence
    assert registry.lookup("Avoid") is Avoid
    assert {"AnyOf", "Sequence", "Avoid"} <= set(registry.registered())


def test_specguard_exposes_them_as_top_level_names():
    assert (sg.AnyOf, sg.Sequence, sg.Avoid) == (AnyOf, Sequence, Avoid)


@pytest.mark.slow
def test_loading_the_plugins_in_a_fresh_process_warns_nothing():
    code = (
        "import warnings\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        "    import specguard as sg\n"
        "    print(sg.AnyOf.__module__, sg.Sequence.__module__, sg.Avoid.__module__)\n"
        "print([str(w.message) for w in caught if 'plugin' in str(w.message)])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "specguard_plugins.anyof specguard_plugins.sequence specguard_plugins.avoid"
    assert out[1] == "[]"


# -- docstring examples ---------------------------------------------------------


@pytest.mark.parametrize(
    "name", ["specguard_plugins", "specguard_plugins.anyof", "specguard_plugins.sequence", "specguard_plugins.avoid"]
)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0
    assert result.failed == 0


# -- fingerprints (the run cache's key) ------------------------------------------


@dataclass(frozen=True, init=False, repr=False)
class _UserOperator(sg.Node):
    """A frozen-dataclass operator defined in user code, as specguard_plugins' are under an editable install."""

    kind = "UserOperator"
    name: str
    annotations: tuple

    def __init__(self, name):
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "annotations", ())

    def contains(self, ctx):
        return True

    def describe(self):
        return f"UserOperator {self.name!r}"


def _tree(budget):
    edge = AnyOf(sg.Goal("l", x=(None, -1.0)), sg.Goal("r", x=(1.0, None)), name="edge")
    return Sequence(edge, sg.Goal("home", x=(-0.1, 0.1)), name="seq").annotate(
        Avoid({"omega": (2.0, None)}, budget=budget)
    )


def test_trees_of_plugin_operators_have_exact_fingerprints():
    # Under an editable install the plugin is user code, whose dataclass bodies the fingerprint follows
    # (it failed on Field.metadata, a mappingproxy, until specguard's encoder learnt it).
    from specguard.cache.canonical import digest

    assert digest(_UserOperator("o")) == digest(_UserOperator("o"))
    assert digest(_tree(2)) == digest(_tree(2))
    assert digest(_tree(2)) != digest(_tree(3))
