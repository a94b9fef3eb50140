"""The CI recipe: the workflow shipped in examples/ci does what docs/guide/ci.md says, and its local play reads it.

The play itself (``examples/ci/play_recipe.py``: main saves, a sabotaged pull
request fails, an unchanged one passes) trains a tiny spec for about a minute:
``.ci/run`` runs it after the test suite.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

CI = Path(__file__).resolve().parents[1] / "examples" / "ci"


def play_recipe():
    spec = importlib.util.spec_from_file_location("play_recipe", CI / "play_recipe.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_play_takes_the_workflows_own_commands():
    commands = play_recipe().workflow_commands((CI / "github-actions.yml").read_text())
    assert commands == {
        "main": ["pytest", "--goal-specs", "--goal-specs-save", "main", "--goal-specs-report", "specguard-report"],
        "pull request": [
            "pytest",
            "--goal-specs",
            "--goal-specs-compare",
            "main",
            "--goal-specs-report",
            "specguard-report",
        ],
    }
    assert play_recipe().workflow_commands("run: pytest --goal-specs -q\n") == {}


def test_the_github_workflow_restores_on_every_run_and_saves_only_on_main():
    text = (CI / "github-actions.yml").read_text()
    steps = text.split("\n      - ")
    restore = next(s for s in steps if "actions/cache/restore" in s)
    save = next(s for s in steps if "actions/cache/save" in s)
    for step in (restore, save):
        assert ".specguard/cache" in step and ".specguard/baselines" in step
    assert "if:" not in restore and "github.event_name == 'push'" in save
    main = next(s for s in steps if "--goal-specs-save main" in s)
    pull = next(s for s in steps if "--goal-specs-compare main" in s)
    assert "github.event_name == 'push'" in main and "github.event_name == 'pull_request'" in pull
    assert re.search(r"goal-specs\.md >> \"\$GITHUB_STEP_SUMMARY\"", text)
    assert "actions/upload-artifact" in text and "SPECGUARD_CACHE_KEY: ${{ secrets.SPECGUARD_CACHE_KEY }}" in text


def test_the_gitlab_jobs_push_the_cache_on_main_and_pull_it_in_merge_requests():
    text = (CI / "gitlab-ci.yml").read_text()
    main = text.split("goal-specs-main:")[1].split("goal-specs-merge-request:")[0]
    merge = text.split("goal-specs-merge-request:")[1]
    assert "policy: pull-push" in main and "--goal-specs-save main" in main
    assert "policy: pull}" in merge and "--goal-specs-compare main" in merge
    assert text.count("unprotect: true") == 2
