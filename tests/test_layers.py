"""The package's architecture, kept by a test: which part may import which, and no import cycles.

Every import counts, wherever it is written: at module level, inside a
function (a lazy import is still a dependency) or under ``TYPE_CHECKING`` (a
design dependency). Parts, lowest first:

- base: ``error``, ``validation``, ``version``, ``utils/``;
- ``extend`` (the operator API), then ``tree/`` (the built-in nodes), then ``construction/`` (the constructed env);
- ``stats/`` (intervals, anytime looks, comparisons: numbers only);
- ``falsify/`` (start spaces, robustness margins, the guided search for failing starts: over any policy callable);
- ``parallel/`` (tasks in processes or on a cluster: generic, it knows nothing of specs);
- the public tools over the core: ``strategies``, ``registry``, ``contract/``, ``testing``;
- ``spec/`` (the spec, its budget, the algorithms, spec files), then ``training/`` (one seed), then ``cache/``
  (run identity and the store), then ``engine/`` (``run_spec``, its runs and verdicts), then ``gate/`` (the baseline
  gate);
- ``report/`` (session reports, figures, GIFs, spec rendering);
- the doors: ``pytest_plugin/`` and ``cli/``; and the facade ``specguard`` (``__init__``) and ``__main__``.

Only the pytest door (and ``testing``, the kit's pytest parametrisation) imports pytest: the CLI shows a pytest
goal-spec file by running pytest in a child process.
"""

from __future__ import annotations

import ast
import builtins
import re
import subprocess
import sys
import textwrap
from collections.abc import Iterable, Mapping
from pathlib import Path

import pytest

import specguard

PACKAGE = Path(specguard.__file__).parent

BASE = frozenset({"error", "validation", "version", "utils"})
CORE = BASE | {"extend", "tree", "construction"}
TOOLS = CORE | {"strategies", "registry", "contract", "testing"}
RUNNING = TOOLS | {"stats", "parallel", "falsify", "spec", "training", "cache"}
# Per part, the parts its modules may import (its own included).
ALLOWED: Mapping[str, frozenset[str]] = {
    "error": frozenset({"error"}),
    "version": frozenset({"version"}),
    "validation": frozenset({"validation", "error"}),
    "utils": BASE,
    "extend": BASE | {"extend"},
    "tree": BASE | {"extend", "tree"},
    "construction": CORE,
    "stats": BASE | {"stats"},
    "strategies": BASE | {"extend", "tree", "strategies"},
    "registry": BASE | {"extend", "tree", "registry"},
    "contract": CORE | {"strategies", "contract"},
    "testing": CORE | {"contract", "testing"},
    "falsify": CORE | {"stats", "falsify"},
    "parallel": BASE | {"parallel"},
    "spec": CORE | {"stats", "falsify", "spec"},
    "training": CORE | {"stats", "falsify", "parallel", "spec", "training"},
    "cache": CORE | {"stats", "falsify", "parallel", "spec", "training", "cache"},
    "engine": RUNNING | {"engine"},
    "gate": RUNNING | {"engine", "gate"},
    "report": RUNNING | {"engine", "gate", "report"},
    "pytest_plugin": RUNNING | {"engine", "gate", "report", "pytest_plugin"},
    "cli": RUNNING | {"engine", "gate", "report", "cli"},
    "__main__": frozenset({"cli", "__main__"}),
}
NO_DEEP_LEARNING = (
    "extend",
    "tree",
    "construction",
    "stats",
    "falsify",
    "parallel",
    "contract",
    "strategies",
    "registry",
    "testing",
    *BASE,
)
DEEP_LEARNING = ("torch", "stable_baselines3")
# The parts that may import pytest: the pytest door, and the contract kit's pytest parametrisation. The CLI is the
# other door, beside the plugin: it neither imports pytest nor runs pytest in its process (a lazy door is a door).
PYTEST_PARTS = ("pytest_plugin", "testing")
PYTEST = ("pytest", "_pytest", "pluggy", "xdist")


def module_name(path: Path, package: Path) -> str:
    """``specguard/engine/run_spec.py`` -> ``specguard.engine.run_spec``; a package's ``__init__`` is the package."""
    parts = path.relative_to(package.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules_of(package: Path) -> dict[str, Path]:
    """Every module of ``package``, subpackages included, by dotted name."""
    return {module_name(p, package): p for p in sorted(package.rglob("*.py")) if "__pycache__" not in p.parts}


def imports_of(path: Path, name: str, known: Iterable[str]) -> set[str]:
    """Every module ``path`` (module ``name``) imports, anywhere in its body, resolved to the most specific known one.

    ``from a.b import c`` is ``a.b.c`` when that is a module, else ``a.b``;
    relative imports are resolved against ``name``.
    """
    known = set(known)
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = name.split(".") if is_package else name.split(".")[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join([*anchor, *([base] if base else [])])
            for alias in node.names:
                full = f"{base}.{alias.name}"
                found.add(full if full in known else base)
    return found


def import_graph(package: Path) -> dict[str, set[str]]:
    """Per module of ``package``, the modules of ``package`` it imports (itself left out)."""
    modules = modules_of(package)
    top = package.name
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        deps = set()
        for imported in imports_of(path, name, modules):
            while imported and imported not in modules and imported.startswith(top):
                imported = imported.rpartition(".")[0]  # a name inside a module: the module
            if imported in modules and imported != name:
                deps.add(imported)
        graph[name] = deps
    return graph


def third_party_imports(package: Path) -> dict[str, set[str]]:
    """Per module, the top-level names of the modules it imports from outside the package."""
    modules = modules_of(package)
    return {
        name: {m.split(".")[0] for m in imports_of(path, name, modules) if m and not m.startswith(package.name)}
        for name, path in modules.items()
    }


def part_of(module: str) -> str:
    """The part a module belongs to: its first name below the package (``specguard.engine.run_spec`` -> ``engine``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def layer_violations(graph: Mapping[str, set[str]], allowed: Mapping[str, frozenset[str]] = ALLOWED) -> list[str]:
    """Each import that runs against the layering, as ``importer -> imported``.

    The facade (the package's ``__init__``) may import anything; nothing may import the facade.
    """
    out = []
    for module, deps in sorted(graph.items()):
        for dep in sorted(deps):
            if part_of(dep) == "__init__":
                out.append(f"{module} -> {dep} (the facade: import the module that defines the name)")
            elif part_of(module) != "__init__" and part_of(dep) not in allowed[part_of(module)]:
                out.append(f"{module} -> {dep} ({part_of(module)} may not import {part_of(dep)})")
    return out


def cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def deep_learning_imports(package: Path) -> list[str]:
    """Modules of the core and the tools that import torch or stable-baselines3."""
    return [
        f"{module} imports {', '.join(sorted(names & set(DEEP_LEARNING)))}"
        for module, names in sorted(third_party_imports(package).items())
        if part_of(module) in NO_DEEP_LEARNING and names & set(DEEP_LEARNING)
    ]


def pytest_imports(package: Path) -> list[str]:
    """Modules outside the parts of :data:`PYTEST_PARTS` that import pytest (its internals, pluggy or xdist)."""
    return [
        f"{module} imports {', '.join(sorted(names & set(PYTEST)))}"
        for module, names in sorted(third_party_imports(package).items())
        if part_of(module) not in PYTEST_PARTS and names & set(PYTEST)
    ]


# -- the package itself ------------------------------------------------------------------


def test_every_module_belongs_to_a_part_with_rules():
    parts = {part_of(m) for m in modules_of(PACKAGE)} - {"__init__"}
    assert parts <= set(ALLOWED), f"parts without import rules: {sorted(parts - set(ALLOWED))}"


def test_no_module_imports_against_the_layering():
    assert layer_violations(import_graph(PACKAGE)) == []


def test_no_import_cycles():
    assert cycles(import_graph(PACKAGE)) == []


def test_the_core_and_the_tools_never_import_torch_or_stable_baselines3():
    assert deep_learning_imports(PACKAGE) == []


def test_only_the_pytest_door_and_the_kit_import_pytest():
    """``specguard show``/``plan`` on a pytest file runs pytest in a child process, never in the CLI's."""
    assert pytest_imports(PACKAGE) == []


# -- the checker can fail ----------------------------------------------------------------------


def write_package(root: Path, files: Mapping[str, str]) -> Path:
    package = root / "specguard"
    for relative, source in {"__init__.py": "", **files}.items():
        path = package / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(source))
        for folder in path.relative_to(package).parents:
            (package / folder / "__init__.py").touch()
    return package


def test_a_lazy_import_of_the_engine_from_the_tree_is_a_violation(tmp_path):
    package = write_package(
        tmp_path,
        {
            "tree/nodes.py": """
                def strategy():
                    from specguard.training.train import train_run
                    return train_run
            """,
            "training/train.py": "from specguard.tree import nodes\n",
        },
    )
    assert layer_violations(import_graph(package)) == [
        "specguard.tree.nodes -> specguard.training.train (tree may not import training)"
    ]


UPWARD = [
    ("spec/spec.py", "training/train.py"),
    ("training/train.py", "cache/store.py"),
    ("cache/store.py", "engine/runs.py"),
    ("engine/runs.py", "gate/comparison.py"),
    ("gate/comparison.py", "report/session.py"),
    ("report/session.py", "pytest_plugin/items.py"),
]


@pytest.mark.parametrize(("importer", "imported"), UPWARD)
def test_an_upward_import_between_the_running_parts_is_a_violation(tmp_path, importer, imported):
    """spec below training below cache below engine below gate below report; the CLI imports no pytest plugin."""
    low, high = (m.removesuffix(".py").replace("/", ".") for m in (importer, imported))
    package = write_package(tmp_path, {importer: f"from specguard.{high} import x\n", imported: ""})
    assert layer_violations(import_graph(package)) == [
        f"specguard.{low} -> specguard.{high} ({low.split('.')[0]} may not import {high.split('.')[0]})"
    ]
    downward = write_package(tmp_path / "down", {imported: f"from specguard.{low} import x\n", importer: ""})
    assert layer_violations(import_graph(downward)) == []


def test_the_cli_importing_the_pytest_plugin_is_a_violation(tmp_path):
    """The two doors are siblings: the CLI renders specs with ``report/``, never through a pytest plugin module."""
    package = write_package(
        tmp_path, {"cli/main.py": "from specguard.pytest_plugin.items import spec_of\n", "pytest_plugin/items.py": ""}
    )
    assert layer_violations(import_graph(package)) == [
        "specguard.cli.main -> specguard.pytest_plugin.items (cli may not import pytest_plugin)"
    ]


def test_the_engine_importing_the_cli_and_the_plugin_are_violations(tmp_path):
    package = write_package(
        tmp_path,
        {
            "engine/run_spec.py": "from specguard.cli import main\nfrom specguard.pytest_plugin.report import md\n",
            "cli/main.py": "",
            "pytest_plugin/report.py": "",
        },
    )
    assert layer_violations(import_graph(package)) == [
        "specguard.engine.run_spec -> specguard.cli.main (engine may not import cli)",
        "specguard.engine.run_spec -> specguard.pytest_plugin.report (engine may not import pytest_plugin)",
    ]


def test_a_cycle_through_a_type_checking_import_is_found(tmp_path):
    package = write_package(
        tmp_path,
        {
            "construction/compiled.py": "from specguard.construction.codegen import source_of\n",
            "construction/codegen.py": """
                from typing import TYPE_CHECKING
                if TYPE_CHECKING:
                    from specguard.construction.compiled import CompiledTree
            """,
            "construction/env.py": "from specguard.construction import compiled\n",
        },
    )
    assert cycles(import_graph(package)) == [["specguard.construction.codegen", "specguard.construction.compiled"]]
    assert layer_violations(import_graph(package)) == []


def test_relative_imports_and_the_facade_are_resolved(tmp_path):
    package = write_package(
        tmp_path,
        {
            "engine/run_spec.py": "from . import runs\nfrom .runs import Runs\nimport specguard\n",
            "engine/runs.py": "from .. import error\n",
            "error.py": "",
        },
    )
    graph = import_graph(package)
    assert graph["specguard.engine.run_spec"] == {"specguard", "specguard.engine.runs"}
    assert graph["specguard.engine.runs"] == {"specguard.error"}
    assert layer_violations(graph) == [
        "specguard.engine.run_spec -> specguard (the facade: import the module that defines the name)"
    ]


def test_torch_in_the_construction_is_found(tmp_path):
    package = write_package(tmp_path, {"construction/env.py": "def f():\n    import torch.nn\n"})
    assert deep_learning_imports(package) == ["specguard.construction.env imports torch"]


def test_a_lazy_pytest_import_in_the_report_or_the_cli_is_found(tmp_path):
    package = write_package(
        tmp_path,
        {
            "report/show.py": "def look(args):\n    import pytest\n    return pytest.main(args)\n",
            "cli/main.py": "from _pytest.config import ExitCode\n",
            "pytest_plugin/plugin.py": "import pytest\nimport pluggy\n",
            "testing.py": "import pytest\n",
        },
    )
    assert pytest_imports(package) == ["specguard.cli.main imports _pytest", "specguard.report.show imports pytest"]


@pytest.mark.parametrize("module", ["specguard.tree.nodes", "specguard.engine.run_spec", "specguard.cli.main"])
def test_the_real_graph_is_read(module):
    graph = import_graph(PACKAGE)
    assert graph[module], f"{module} imports nothing of specguard? the reader is broken"


# -- every docstring example is collected ------------------------------------------------------

EXAMPLE = re.compile(r"^\s*>>> ", re.MULTILINE)


def collected_files(root: Path, *args: str) -> set[str]:
    """The files (relative to ``root``) holding at least one item pytest collects for ``pytest --collect-only -q``."""
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", *args],
        cwd=root,
        capture_output=True,
        text=True,
        check=False,
    ).stdout
    return {line.split("::")[0] for line in out.splitlines() if "::" in line}


def test_every_docstring_example_is_collected_by_the_readme_test_command():
    """README's test command is ``pytest`` over its ``testpaths``; a folder pytest skips (``build``) hides examples."""
    root = PACKAGE.parent
    with_examples = {
        path.relative_to(root).as_posix()
        for path in modules_of(PACKAGE).values()
        if EXAMPLE.search(path.read_text(encoding="utf-8"))
    }
    assert with_examples, "no module has an example? the reader is broken"
    assert sorted(with_examples - collected_files(root, PACKAGE.name)) == []


# -- one home for errors -----------------------------------------------------------------------


def exception_classes_outside_error(package: Path) -> list[str]:
    """Classes deriving from an exception or warning (a builtin one or one of ``error.py``'s) defined elsewhere."""
    error_module = package / "error.py"
    known = {
        name for name, value in vars(builtins).items() if isinstance(value, type) and issubclass(value, BaseException)
    }
    if error_module.exists():
        known |= {n.name for n in ast.walk(ast.parse(error_module.read_text())) if isinstance(n, ast.ClassDef)}
    found = []
    for name, path in modules_of(package).items():
        if path == error_module:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ClassDef) and any(ast.unparse(b).rpartition(".")[2] in known for b in node.bases):
                found.append(f"{name}.{node.name}")
    return sorted(found)


def test_every_exception_class_is_defined_in_error():
    assert exception_classes_outside_error(PACKAGE) == []


def test_an_exception_class_outside_error_is_found(tmp_path):
    package = write_package(
        tmp_path,
        {
            "error.py": "class SpecError(Exception):\n    pass\n",
            "engine/runs.py": "from specguard import error\nclass Late(error.SpecError):\n    pass\n",
            "registry.py": "class Loud(UserWarning):\n    pass\nclass Plain:\n    pass\n",
        },
    )
    assert exception_classes_outside_error(package) == ["specguard.engine.runs.Late", "specguard.registry.Loud"]
