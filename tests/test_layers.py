"""The package's architecture, kept by a test: which part may import which, and no import cycles.

Every import counts, wherever it is written: at module level, inside a
function (a lazy import is still a dependency) or under ``TYPE_CHECKING`` (a
design dependency). Parts, lowest first:

- base: ``error``, ``validation``, ``version``, ``utils/`` (``validation`` reads the separators of
  ``utils.node_paths`` and writes numbers by ``utils.text``; ``utils.options`` reads option text by
  ``validation``'s rules: the two parts may import each other, module by module without a cycle);
- ``extend`` (the operator API), then ``tree/`` (the built-in nodes); ``starts/`` (start spaces and how an env is
  put in one: it knows nothing of trees); then ``construction/`` (the constructed env, made in a start space's
  wrapper when given one, and the ``EpisodePolicy`` protocol that training and the falsifier share);
- ``stats/`` (intervals, anytime looks, comparisons: numbers only);
- ``falsify/`` (robustness margins, the guided search for failing starts: over any policy callable); nothing
  below the engine imports it: the spec and training need only what ``starts/`` and ``construction/`` hold;
- ``parallel/`` (tasks in processes or on a cluster: generic, it knows nothing of specs);
- the public tools over the core: ``strategies``, ``registry``, ``contract/``, ``testing``;
- ``spec/`` (the spec, its budget, the algorithms, spec files), then ``evaluation/`` (a policy's evaluation
  episodes and their seeds, a model as a policy, rollouts), then ``training/`` (one seed), then ``cache/``
  (run identity and the store), then ``agents/`` (an agent trained elsewhere, loaded as one policy: it acts as a
  trained model does, and is fingerprinted as a spec's functions are; evaluated, never trained, it imports
  ``evaluation/`` and not ``training/``), then ``engine/`` (``run_spec``, its runs and
  verdicts), then ``gate/`` (the baseline gate);
- ``report/`` (session reports, figures, GIFs, spec rendering);
- the doors: ``pytest_plugin/`` and ``cli/``; and the facade ``specguard`` (``__init__``) and ``__main__``.

Every exception and warning class a user may catch is defined in ``error``; the internal signals (raised and
caught inside specguard) each beside the code that raises them (:data:`SIGNALS`); any other is a violation.
Beside the layering: every docstring example is collected, no folder holds more than ten modules, and every
test file is named after the module, part or topic it tests.
Only the pytest door (and ``testing``, the kit's pytest parametrisation) imports pytest: the CLI shows a pytest
goal-spec file by running pytest in a child process.
"""

from __future__ import annotations

import ast
import builtins
import importlib
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
CORE = BASE | {"extend", "tree", "starts", "construction"}
TOOLS = CORE | {"strategies", "registry", "contract", "testing"}
RUNNING = TOOLS | {"stats", "parallel", "falsify", "spec", "evaluation", "training", "cache", "agents"}
# Per part, the parts its modules may import (its own included).
ALLOWED: Mapping[str, frozenset[str]] = {
    "error": frozenset({"error"}),
    "version": frozenset({"version"}),
    "validation": frozenset({"validation", "error", "utils"}),
    "utils": BASE,
    "extend": BASE | {"extend"},
    "tree": BASE | {"extend", "tree"},
    "starts": BASE | {"starts"},
    "construction": CORE,
    "stats": BASE | {"stats"},
    "strategies": BASE | {"extend", "tree", "strategies"},
    "registry": BASE | {"extend", "tree", "registry"},
    "contract": CORE | {"strategies", "contract"},
    "testing": CORE | {"contract", "testing"},
    "falsify": CORE | {"stats", "falsify"},
    "parallel": BASE | {"parallel"},
    "spec": CORE | {"stats", "spec"},
    "evaluation": CORE | {"spec", "evaluation"},
    "training": CORE | {"stats", "parallel", "spec", "evaluation", "training"},
    "cache": CORE | {"stats", "parallel", "spec", "evaluation", "training", "cache"},
    # An agent trained elsewhere is evaluated, never trained: agents/ reaches evaluation/, not training/.
    "agents": CORE | {"stats", "spec", "evaluation", "cache", "agents"},
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
    "starts",
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


MAX_MODULES = 10  # a folder is one concept: past ten modules it holds more than one


def crowded_folders(package: Path, limit: int = MAX_MODULES) -> list[str]:
    """Folders of ``package`` (itself included) holding more than ``limit`` modules, ``__init__`` not counted."""
    crowded = []
    for folder in sorted({package, *(p.parent for p in package.rglob("__init__.py"))}):
        modules = [p for p in folder.glob("*.py") if p.name != "__init__.py"]
        if len(modules) > limit:
            crowded.append(f"{folder.relative_to(package.parent)}: {len(modules)} modules")
    return crowded


# -- the package itself ------------------------------------------------------------------


def test_every_module_belongs_to_a_part_with_rules():
    parts = {part_of(m) for m in modules_of(PACKAGE)} - {"__init__"}
    assert parts <= set(ALLOWED), f"parts without import rules: {sorted(parts - set(ALLOWED))}"


def test_no_module_imports_against_the_layering():
    assert layer_violations(import_graph(PACKAGE)) == []


def clashing_module_names(package: Path) -> list[str]:
    """Module names (``__init__`` aside) that more than one folder of ``package`` uses, with the modules."""
    by_name: dict[str, list[str]] = {}
    for name, path in modules_of(package).items():
        if path.name != "__init__.py":
            by_name.setdefault(path.stem, []).append(name)
    return [f"{stem}: {', '.join(sorted(names))}" for stem, names in sorted(by_name.items()) if len(names) > 1]


def test_no_two_modules_share_a_name():
    assert clashing_module_names(PACKAGE) == [], "a module's name says its one job, once in the package"


def test_two_policy_modules_clash(tmp_path):
    package = write_package(tmp_path, {"construction/policy.py": "", "training/policy.py": "", "training/train.py": ""})
    assert clashing_module_names(package) == ["policy: specguard.construction.policy, specguard.training.policy"]


def test_no_folder_holds_more_than_ten_modules():
    assert crowded_folders(PACKAGE) == []


def test_a_folder_of_eleven_modules_is_crowded(tmp_path):
    folder = tmp_path / "pkg" / "part"
    folder.mkdir(parents=True)
    for parent in (tmp_path / "pkg", folder):
        (parent / "__init__.py").write_text("")
    for i in range(11):
        (folder / f"m{i}.py").write_text("")
    assert crowded_folders(tmp_path / "pkg") == ["pkg/part: 11 modules"]
    (folder / "m10.py").unlink()
    assert crowded_folders(tmp_path / "pkg") == []


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
    ("cache/store.py", "engine/seeds.py"),
    ("engine/seeds.py", "gate/comparison.py"),
    ("gate/comparison.py", "report/session_report.py"),
    ("report/session_report.py", "pytest_plugin/items.py"),
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


@pytest.mark.parametrize(
    ("importer", "imported"),
    [
        ("spec/spec.py", "falsify/search.py"),
        ("training/train.py", "falsify/search.py"),
        ("cache/fingerprint.py", "falsify/assertion.py"),
        ("starts/space.py", "construction/env.py"),
        ("starts/space.py", "tree/nodes.py"),
    ],
)
def test_the_spec_training_and_cache_importing_the_falsifier_are_violations(tmp_path, importer, imported):
    """What they share with it (start spaces, the episode policy) lies lower: ``starts/`` below ``construction/``."""
    low, high = (m.removesuffix(".py").replace("/", ".") for m in (importer, imported))
    package = write_package(tmp_path, {importer: f"from specguard.{high} import x\n", imported: ""})
    assert layer_violations(import_graph(package)) == [
        f"specguard.{low} -> specguard.{high} ({low.split('.')[0]} may not import {high.split('.')[0]})"
    ]


def test_the_construction_and_the_falsifier_importing_start_spaces_are_allowed(tmp_path):
    package = write_package(
        tmp_path,
        {
            "construction/env.py": "from specguard.starts.space import StartSpace\n",
            "falsify/search.py": "from specguard.starts.space import starts_of\n",
            "training/train.py": "from specguard.construction.episode_policy import EpisodePolicy\n",
            "starts/space.py": "",
            "construction/episode_policy.py": "",
        },
    )
    assert layer_violations(import_graph(package)) == []


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
            "engine/run_spec.py": "from . import seeds\nfrom .seeds import Runs\nimport specguard\n",
            "engine/seeds.py": "from .. import error\n",
            "error.py": "",
        },
    )
    graph = import_graph(package)
    assert graph["specguard.engine.run_spec"] == {"specguard", "specguard.engine.seeds"}
    assert graph["specguard.engine.seeds"] == {"specguard.error"}
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


@pytest.mark.slow
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


# -- one home for errors, one for each internal signal ----------------------------------------------

SIGNALS: Mapping[str, frozenset[str]] = {
    "specguard.contract.trees": frozenset({"Broken"}),
    "specguard.utils.imports": frozenset({"ExitAtImport", "ImportFailed"}),
    "specguard.report.gifs": frozenset({"NoFrames"}),
    "specguard.report.offscreen": frozenset({"NoOffscreen"}),
}
"""The internal signals (raised and caught inside specguard, never reaching a user), each beside the code that
raises it. ``error`` holds only what users catch (as Gymnasium's ``error.py``)."""


def misplaced_exception_classes(package: Path, signals: Mapping[str, frozenset[str]] = SIGNALS) -> list[str]:
    """Exception and warning classes defined away from their home, as ``module.Class (why)``.

    A class deriving from one of ``error.py``'s is public: its home is ``error``. An internal signal's home is
    its module in ``signals``, never ``error``. Any other class deriving from a builtin exception or warning, or
    from a signal, is misplaced wherever it is defined.
    """
    error_module = package / "error.py"
    builtin = {
        name for name, value in vars(builtins).items() if isinstance(value, type) and issubclass(value, BaseException)
    }
    homes = {signal: module for module, names in signals.items() for signal in names}
    public = set()
    if error_module.exists():
        public = {n.name for n in ast.walk(ast.parse(error_module.read_text())) if isinstance(n, ast.ClassDef)}
    public -= set(homes)
    found = []
    for name, path in modules_of(package).items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.ClassDef):
                continue
            bases = {ast.unparse(b).rpartition(".")[2] for b in node.bases}
            where = f"{name}.{node.name}"
            if path == error_module:
                if node.name in homes:
                    found.append(f"{where} (an internal signal: its home is {homes[node.name]})")
            elif bases & public:
                found.append(f"{where} (a public exception: its home is {package.name}.error)")
            elif bases & (builtin | set(homes)) and homes.get(node.name) != name:
                found.append(f"{where} (neither public, in {package.name}.error, nor a signal listed at its home)")
    return sorted(found)


def test_every_exception_class_is_in_error_or_a_signal_at_its_home():
    assert misplaced_exception_classes(PACKAGE) == []


@pytest.mark.parametrize(("module", "signal"), [(m, s) for m, names in SIGNALS.items() for s in sorted(names)])
def test_every_listed_signal_is_defined_at_its_home(module, signal):
    cls = getattr(importlib.import_module(module), signal)
    assert issubclass(cls, BaseException) and cls.__module__ == module
    assert not hasattr(importlib.import_module("specguard.error"), signal)


def test_a_misplaced_exception_class_is_found(tmp_path):
    package = write_package(
        tmp_path,
        {
            "error.py": "class SpecError(Exception):\n    pass\nclass Broken(Exception):\n    pass\n",
            "engine/seeds.py": "from specguard import error\nclass Late(error.SpecError):\n    pass\n",
            "registry.py": "class Loud(UserWarning):\n    pass\nclass Plain:\n    pass\n",
            "contract/trees.py": "class Broken(Exception):\n    pass\nclass Worse(Broken):\n    pass\n",
            "report/gifs.py": "class Broken(Exception):\n    pass\nclass Stray(RuntimeError):\n    pass\n",
        },
    )
    assert misplaced_exception_classes(package, {"specguard.contract.trees": frozenset({"Broken"})}) == [
        "specguard.contract.trees.Worse (neither public, in specguard.error, nor a signal listed at its home)",
        "specguard.engine.seeds.Late (a public exception: its home is specguard.error)",
        "specguard.error.Broken (an internal signal: its home is specguard.contract.trees)",
        "specguard.registry.Loud (neither public, in specguard.error, nor a signal listed at its home)",
        "specguard.report.gifs.Broken (neither public, in specguard.error, nor a signal listed at its home)",
        "specguard.report.gifs.Stray (neither public, in specguard.error, nor a signal listed at its home)",
    ]


def test_a_signal_at_its_home_is_no_violation(tmp_path):
    package = write_package(
        tmp_path,
        {
            "error.py": "class SpecError(Exception):\n    pass\n",
            "contract/trees.py": "class Broken(Exception):\n    pass\n",
        },
    )
    assert misplaced_exception_classes(package, {"specguard.contract.trees": frozenset({"Broken"})}) == []


# -- every test file is named after what it tests ----------------------------------------------

TESTS = PACKAGE.parent / "tests"
TOPICS: Mapping[str, str] = {
    "ci_recipe": "the CI workflows of examples/ci and their local play",
    "docs": "the pages under docs/: links, examples, the layout table",
    "doors": "one spec judged alike by run_spec, specguard run and pytest --goal-specs",
    "layers": "the package's architecture (this file)",
    "packaging": "the two distributions as an index shows them",
    "readme": "README, the front page",
    "semantics": "the rules of docs/semantics.md, across both evaluators",
    "tiers": "the suite's fast and slow tiers (the repository's conftest.py)",
}
"""The test files that test no one module or part: each its own topic, kept short."""


def misnamed_tests(tests: Path, package: Path, topics: Iterable[str] = TOPICS) -> list[str]:
    """The ``test_*.py`` files of ``tests`` whose name names no module, part or topic.

    ``test_<name>.py`` is named for what it tests when ``<name>`` is a module's name (a
    package's ``__init__`` is ``init``, a private ``_draw`` is ``draw``), a part's (a folder's)
    or a topic's, or starts with one of them and ``_``: ``test_preflight_met_at_start.py``
    tests one behaviour of ``construction/preflight.py``. A module renamed without its test
    file leaves the old name naming nothing, unless the old name starts with another name
    (``falsify_item`` with the part ``falsify``).
    """
    modules = modules_of(package)
    known = {name.rpartition(".")[2] for name in modules} | {path.stem.strip("_") for path in modules.values()}
    known |= set(topics)
    out = []
    for path in sorted(tests.glob("test_*.py")):
        words = path.stem.removeprefix("test_").split("_")
        if not any("_".join(words[:k]) in known for k in range(1, len(words) + 1)):
            out.append(path.name)
    return out


FACE = 32
"""The most names ``specguard.__all__`` holds (Gymnasium's shape: the language, the spec, the doors; the rest in
its parts and ``specguard.error``)."""


def test_the_public_face_stays_small():
    assert len(specguard.__all__) <= FACE, sorted(specguard.__all__)


def test_every_test_file_names_the_module_part_or_topic_it_tests():
    assert misnamed_tests(TESTS, PACKAGE) == [], "rename them after what they test, or add a topic to TOPICS"


def test_a_test_file_named_after_a_renamed_module_is_found(tmp_path):
    package = write_package(tmp_path, {"construction/preflight.py": "", "tree/_draw.py": ""})
    tests = tmp_path / "tests"
    tests.mkdir()
    for name in ["checks", "preflight", "preflight_met_at_start", "construction", "draw", "init", "docs", "doc"]:
        (tests / f"test_{name}.py").touch()
    (tests / "helpers.py").touch()
    assert misnamed_tests(tests, package, topics=["docs"]) == ["test_checks.py", "test_doc.py"]
