"""README, the front page: its Pendulum example runs and prints what it shows, and its links lead somewhere."""

from __future__ import annotations

import contextlib
import io
import tomllib

from markdown_pages import DOCS, ROOT, broken_links, python_blocks

README = ROOT / "README.md"


def test_readme_language_example_prints_what_it_shows():
    example = next(b for b in python_blocks(README) if "sg.make_env(pendulum, tree)" in b)
    shown = [line[2:] for line in example.splitlines() if line.startswith("# ")]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(example, str(README), "exec"), {})
    assert out.getvalue().splitlines() == shown


def test_readme_links_every_page_of_the_docs():
    text = README.read_text(encoding="utf-8")
    pages = [p.relative_to(ROOT).as_posix() for p in DOCS.rglob("*.md") if "_build" not in p.parts]
    # docs/index.md is the site's front page, README itself; the API pages hang under docs/api/index.md.
    listed = [p for p in pages if p != "docs/index.md" and (not p.startswith("docs/api/") or p.endswith("index.md"))]
    assert [p for p in listed if f"]({p})" not in text] == [], "README does not link these pages"


def test_readme_links_resolve():
    assert broken_links(README) == []


def test_readme_summary_names_the_cluster_engine_and_its_extra():
    summary = README.read_text(encoding="utf-8").split("It has:", 1)[1].split("\n\n", 1)[0]
    assert "Dask cluster" in summary and "the `cluster` extra" in summary
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]["optional-dependencies"]
    assert [d for d in extras["cluster"] if d.startswith("distributed")], "the cluster extra installs Dask"
