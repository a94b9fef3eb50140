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


def test_readme_first_screen_holds_the_tagline_a_goal_spec_test_and_the_two_commands():
    first_screen = README.read_text(encoding="utf-8").splitlines()[:40]
    text = "\n".join(first_screen)
    assert first_screen[2].startswith("**pytest for reinforcement-learning specifications.**")
    assert "@sg.goal_spec(" in text and "$ pytest --goal-specs test_pendulum_specs.py" in text
    assert 'pip install -c constraints.txt -e ".[examples]" -e ./plugins && pytest --goal-specs example_specs' in text
    assert 'pip install -c constraints.txt -e ".[dev]" -e ./plugins && pytest -n 2' in text


def test_readme_goal_spec_test_builds_the_spec_its_output_shows():
    import specguard as sg

    block = next(b for b in python_blocks(README) if "@sg.goal_spec" in b)
    namespace: dict[str, object] = {}
    exec(compile(block, str(README), "exec"), namespace)
    spec = namespace["test_upright_and_still"]()
    assert isinstance(spec, sg.Spec) and spec.tree.name == "pendulum"
    assert spec.budget.timesteps == 100_000 and spec.trainer.n_envs == 4


def test_readme_cites_the_source_paper_by_its_title_where_it_first_names_it():
    text = " ".join(README.read_text(encoding="utf-8").split())  # one line: the title may wrap anywhere
    title = "*Iterative Environment Design for Deep Reinforcement Learning Based on Goal-Oriented Specification*"
    first = min(text.find(word) for word in ("paper", title) if word in text)
    assert text.find(title) == first, text[max(0, first - 200) : first + 100]
