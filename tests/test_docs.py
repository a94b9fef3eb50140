"""The documentation under ``docs/``: self-contained, its links lead somewhere, and its examples are the code's.

The pages' ``{doctest}`` and ``{testcode}`` blocks run in ``sphinx-build -b doctest`` (``.ci/run``); the
``python`` blocks that show a test module or a worked operator are checked here against the code.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
from markdown_pages import DOCS, ROOT, broken_links, page, python_blocks

from example_specs.at_least import AtLeast
from specguard.testing import parametrize_with_checks

# Written in two parts, so that this file does not match itself.
OUTSIDE = re.compile(("SPEC" + r"\.md|\.\./" + "shared|/work/" + "shared").encode())
"""References to files outside the repository: the team's notes, which users do not have."""


def tracked_files() -> list[str]:
    try:
        out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as e:
        pytest.skip(f"not a git checkout ({e})")
    return [name for name in out.decode().split("\0") if name]


@pytest.mark.slow
def test_no_tracked_file_points_outside_the_repository():
    found = []
    for name in tracked_files():
        path = ROOT / name
        if not path.is_file():
            continue
        for number, line in enumerate(path.read_bytes().splitlines(), 1):
            if OUTSIDE.search(line):
                found.append(f"{name}:{number}: {line.decode(errors='replace').strip()[:100]}")
    assert found == [], "these lines point outside the repository; point to docs/ instead:\n" + "\n".join(found)


PAGES = sorted(
    p.relative_to(ROOT).as_posix()
    for p in [*DOCS.rglob("*.md"), ROOT / "plugins" / "README.md"]
    if "_build" not in p.relative_to(ROOT).parts
)


def test_the_docs_have_pages():
    assert "docs/semantics.md" in PAGES and len(PAGES) > 10


@pytest.mark.parametrize("markdown", PAGES)
def test_links_resolve(markdown):
    assert broken_links(ROOT / markdown) == []


# -- "Gating specs with pytest": the goal-spec example collects one item per goal -----------------


def test_goal_spec_example_collects_one_item_per_goal(pytester):
    blocks = python_blocks(page("guide/pytest-plugin.md"))
    first = next(b for b in blocks if "test_pendulum_specs.py" in b)
    second = next(b for b in blocks if "def test_weighted" in b)
    pytester.makepyfile(test_pendulum_specs=first + "\n\n" + second)
    result = pytester.runpytest("-p", "no:cacheprovider", "-q", "-rs")
    result.assert_outcomes(skipped=4)
    result = pytester.runpytest("-p", "no:cacheprovider", "--collect-only", "-q")
    result.stdout.fnmatch_lines(
        [
            "test_pendulum_specs.py::test_refined[[]pendulum[]]",
            "test_pendulum_specs.py::test_refined[[]stabilization[]]",
            "test_pendulum_specs.py::test_weighted[[]pendulum[]]",
            "test_pendulum_specs.py::test_weighted[[]position[]]",
        ]
    )


# -- "Writing an operator": the worked example is a tested file ----------------------------------


def test_operator_example_is_the_tested_file():
    shown = next(b for b in python_blocks(page("guide/writing-an-operator.md")) if "class AtLeast(Node)" in b)
    source = (ROOT / "example_specs" / "at_least.py").read_text(encoding="utf-8")
    for line in shown.splitlines():
        if line.strip() and not line.lstrip().startswith("..."):
            assert line in source, f"the page shows a line the file does not have: {line!r}"


@parametrize_with_checks([AtLeast])
def test_operator_example_passes_the_contract_kit(operator, check):
    check(operator)


# -- "Development": the layout table names every module under its part ---------------------------


def test_layout_names_every_module_under_its_part():
    import specguard

    text = page("guide/development.md").read_text(encoding="utf-8")
    table = text.split("## Layout", 1)[1].split("\n\n")[2]
    rows = {}
    for line in table.splitlines()[2:]:
        part, modules = line.strip("|").split("|", 1)
        rows[part.strip().strip("`").rstrip("/")] = modules
    package = Path(specguard.__file__).parent
    missing = []
    for path in sorted(package.rglob("*.py")):
        relative = path.relative_to(package)
        if path.name == "__init__.py" or "__pycache__" in relative.parts:
            continue
        part = relative.parts[0] if len(relative.parts) > 1 else None
        row = rows.get({"contract": "public tools", "utils": "base"}.get(part, part)) if part else table
        if row is None or f"`{path.stem}`" not in row:
            missing.append(str(relative))
    assert missing == [], f"the layout table of docs/guide/development.md does not list: {missing}"
