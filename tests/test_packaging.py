"""What an index shows of the two distributions (specguard, plugins/' specguard-plugins): license, Python, description.

Building and installing them is `.ci/release_smoke.sh`'s part; these read the metadata the build reads.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tarfile
import tomllib
from pathlib import Path

import pytest
from markdown_pages import ROOT, python_blocks

from specguard.version import __version__

PROJECTS = [ROOT, ROOT / "plugins"]

TARGET = re.compile(
    r"""\]\(\s*<?([^)\s>]+)"""  # [text](target), ![alt](target)
    r"""|^\s*\[[^\]]+\]:\s*<?(\S+?)>?\s*$"""  # [label]: target
    r"""|\b(?:href|src)\s*=\s*["']([^"']+)""",  # <a href="target">, <img src="target">
    flags=re.M,
)
"""A link's or an image's target in Markdown (inline or by reference) or in its HTML; one group holds it."""


def metadata(project: Path) -> dict[str, object]:
    return tomllib.loads((project / "pyproject.toml").read_text(encoding="utf-8"))["project"]


def long_description(project: Path) -> Path:
    readme = metadata(project)["readme"]
    return project / (readme if isinstance(readme, str) else readme["file"])


def relative_targets(markdown: str) -> list[str]:
    """The targets that are not absolute URLs (``scheme:``), outside code blocks: an index page shows the text alone."""
    prose = re.sub(r"^```.*?^```", "", markdown, flags=re.S | re.M)
    targets = [next(g for g in m.groups() if g) for m in TARGET.finditer(prose)]
    return [t for t in targets if not re.match(r"[a-zA-Z][a-zA-Z0-9+.-]*:", t)]


def test_relative_targets_finds_every_form_of_link():
    text = "[a](docs/x.md) ![b](img.png) [c](#c) [d](https://x.org)\n[e]: ../f.md\n<img src='g.png'>\n```\n[h](i)\n```"
    assert relative_targets(text) == ["docs/x.md", "img.png", "#c", "../f.md", "g.png"]


@pytest.mark.parametrize("project", PROJECTS, ids=lambda p: p.relative_to(ROOT).as_posix() or ".")
def test_the_long_description_has_no_relative_link(project):
    page = long_description(project)
    assert relative_targets(page.read_text(encoding="utf-8")) == [], f"{page.relative_to(ROOT)} links relatively"


@pytest.mark.parametrize("project", PROJECTS, ids=lambda p: p.relative_to(ROOT).as_posix() or ".")
def test_the_distribution_ships_the_mit_license(project):
    meta = metadata(project)
    assert (meta["license"], meta["license-files"]) == ("MIT", ["LICENSE"])
    text = (project / "LICENSE").read_text(encoding="utf-8")
    assert text.startswith("MIT License\n\nCopyright (c) 2026 the specguard authors\n")
    assert text == (ROOT / "LICENSE").read_text(encoding="utf-8")


@pytest.mark.parametrize("project", PROJECTS, ids=lambda p: p.relative_to(ROOT).as_posix() or ".")
def test_the_classifiers_name_exactly_the_supported_pythons(project):
    meta = metadata(project)
    assert meta["requires-python"] == ">=3.11"
    listed = sorted(c.rsplit(" ", 1)[1] for c in meta["classifiers"] if re.fullmatch(r".*Python :: 3\.\d+", c))
    assert listed == ["3.11", "3.12", "3.13"]


def test_hypothesis_is_a_dependency_and_no_extra():
    meta = metadata(ROOT)
    assert any(re.match(r"hypothesis\b", d) for d in meta["dependencies"])
    extras = meta["optional-dependencies"]
    assert "hypothesis" not in extras
    assert [e for e, deps in extras.items() if any(re.match(r"hypothesis\b", d) for d in deps)] == []


def test_the_changelog_has_a_section_for_this_version_below_unreleased():
    headings = re.findall(r"^## (.+)$", (ROOT / "CHANGELOG.md").read_text(encoding="utf-8"), flags=re.M)
    assert headings[0] == "Unreleased"
    assert __version__ in headings
    assert metadata(ROOT / "plugins")["version"] == __version__, "the two distributions are released together"


def test_the_long_descriptions_goal_spec_collects_one_item_per_goal(pytester):
    (example,) = python_blocks(long_description(ROOT))
    pytester.makepyfile(test_pendulum_specs=example)
    result = pytester.runpytest("-p", "no:cacheprovider", "--collect-only", "-q")
    items = [line for line in result.stdout.lines if "::" in line]
    assert items == [f"test_pendulum_specs.py::test_upright[{goal}]" for goal in ("pendulum", "stabilization")]


SDIST_INPUTS = {ROOT: ["specguard", "tests"], ROOT / "plugins": ["specguard_plugins", "tests"]}
"""Besides its metadata files, what each project's sdist could take by setuptools' defaults: its package, tests/."""


def sdist_names(project: Path, tmp_path: Path) -> set[str]:
    """The files of ``project``'s sdist (paths inside its top folder): the one in ``$SPECGUARD_DIST_DIR`` where
    that is set (``.ci/run`` builds the release once, with ``.ci/release_smoke.sh --build``), else built from a
    copy by setuptools itself."""
    built = os.environ.get("SPECGUARD_DIST_DIR")
    if built:
        name = tomllib.loads((project / "pyproject.toml").read_text())["project"]["name"].replace("-", "_")
        (archive,) = Path(built).glob(f"{name}-*.tar.gz")
        return _members(archive)
    pytest.importorskip("setuptools", minversion="77")  # the build backend both pyproject.toml name
    source, out = tmp_path / "source", tmp_path / "out"
    ignore = shutil.ignore_patterns("__pycache__", "*.py[cod]", "*.egg-info")
    for folder in SDIST_INPUTS[project]:
        shutil.copytree(project / folder, source / folder, ignore=ignore)
    for name in ["pyproject.toml", "MANIFEST.in", "LICENSE", "README.md", "DESCRIPTION.md"]:
        if (project / name).exists():
            shutil.copy(project / name, source / name)
    build = "import sys; from setuptools import build_meta; build_meta.build_sdist(sys.argv[1])"
    subprocess.run([sys.executable, "-c", build, str(out)], cwd=source, check=True, capture_output=True)
    (archive,) = out.glob("*.tar.gz")
    return _members(archive)


def _members(archive: Path) -> set[str]:
    with tarfile.open(archive) as tar:
        return {m.name.split("/", 1)[1] for m in tar.getmembers() if m.isfile()}


@pytest.mark.slow
def test_specguards_sdist_leaves_out_the_tests_that_need_the_checkout(tmp_path):
    names = sdist_names(ROOT, tmp_path)
    assert "specguard/__init__.py" in names and "LICENSE" in names
    assert [n for n in names if n.startswith("tests/")] == []


@pytest.mark.slow
def test_the_plugins_sdist_ships_its_tests_whole(tmp_path):
    tests = ROOT / "plugins" / "tests"
    shipped = {n for n in sdist_names(ROOT / "plugins", tmp_path) if n.startswith("tests/")}
    assert shipped == {f"tests/{p.relative_to(tests).as_posix()}" for p in tests.rglob("*.py")}
    assert {"tests/__init__.py", "tests/conftest.py", "tests/helpers.py"} <= shipped


DOCTESTS_OFF_THE_CHECKOUT = """
import doctest, importlib, importlib.util, pkgutil, sys
from pathlib import Path

from hypothesis import HealthCheck, settings

import specguard

# As tests/conftest.py's profiles: on a busy machine a slow draw is no failure of the example.
settings.register_profile("doctests", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("doctests")
root = Path(specguard.__file__).resolve().parents[1]
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != root]
if importlib.util.find_spec("example_specs") is not None:
    sys.exit("the checkout's example_specs is still importable")
tried = failed = 0
for info in pkgutil.walk_packages(specguard.__path__, "specguard."):
    if info.name != "specguard.__main__":  # importing it runs the command line
        outcome = doctest.testmod(importlib.import_module(info.name), optionflags=doctest.ELLIPSIS)
        tried, failed = tried + outcome.attempted, failed + outcome.failed
print(f"{tried} examples, {failed} failed")
"""


@pytest.mark.slow
def test_the_docstring_examples_pass_without_the_checkout(tmp_path):
    """An installed wheel's examples: every module's, run with the repository root (example_specs/) off sys.path."""
    done = subprocess.run(
        [sys.executable, "-c", DOCTESTS_OFF_THE_CHECKOUT], cwd=tmp_path, capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-4000:]
    tried, failed = re.fullmatch(r"(\d+) examples, (\d+) failed", done.stdout.strip().splitlines()[-1]).groups()
    assert int(tried) > 100 and failed == "0", done.stdout[-4000:]
