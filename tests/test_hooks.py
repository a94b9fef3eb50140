"""The hooks other plugins implement (``pytest_goal_spec_result``, ``..._falsification``), through pytester.

A conftest implements them and writes what it heard, one JSON line a call; the tests read the lines.
"""

from __future__ import annotations

import json
import textwrap

import pytest
from markdown_pages import page, python_blocks

CONFTEST = """
import json


def hear(**fields):
    with open("heard.jsonl", "a") as out:
        out.write(json.dumps(fields) + "\\n")


def pytest_goal_spec_result(item, spec, result):
    outcomes = {path: result.outcome(path).value for path in result.goals}
    seeds = [run.seed for run in result.runs]
    hear(hook="result", item=item.name, timesteps=spec.budget.timesteps, goals=outcomes, seeds=seeds)


def pytest_goal_spec_falsification(item, seed, falsification, verdict):  # a subset of the arguments
    hear(hook="falsification", item=item.name, seed=seed, verdict=verdict.value, found=falsification.found)
"""

SPECS = """
import pytest
import specguard as sg

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
PENDULUM = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
# Upright: a policy trained for 128 steps misses it from nearly every start.
UPRIGHT = sg.All(sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)), sg.Goal("slow", omega=(-8, 8)), name="up")


def tiny(seeds=1):
    budget = sg.Budget(timesteps=128, min_seeds=seeds, eval_episodes=4, checkpoints=1)
    return sg.Spec(PENDULUM, UPRIGHT, budget=budget, trainer=sg.SB3(hyperparameters=TINY))


@sg.goal_spec(
    expect={"slow": 0.0, "position": 0.95},
    xfail={"position": "never within 128 steps"},
    falsify=sg.Falsify({"theta": (-1.0, 1.0)}, examples=4, uniform=8),
)
def test_up():
    return tiny(seeds=2)


def test_by_the_fixture(goal_spec_result):
    goal_spec_result(tiny())
"""


def heard(pytester: pytest.Pytester, *args: str) -> tuple[pytest.RunResult, list[dict]]:
    pytester.makeconftest(CONFTEST)
    pytester.makepyfile(test_specs=textwrap.dedent(SPECS))
    pytester.makeini("[pytest]\ngoal_specs_workers = 1\n")
    cache = pytester.path / "cache"
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", f"--goal-specs-cache-dir={cache}", *args)
    lines = pytester.path / "heard.jsonl"
    return result, [json.loads(line) for line in lines.read_text().splitlines()] if lines.exists() else []


def test_each_spec_result_and_each_falsified_run_is_heard_once(pytester):
    result, calls = heard(pytester, "--goal-specs", "--goal-specs-budget-scale=2")
    result.assert_outcomes(passed=2, xfailed=1, failed=1)  # [falsify] fails: 256 steps never hold the pendulum up
    assert calls == [
        # test_up's three items share one result: heard once, from the first item that ran it, with the spec as
        # trained (the session's budget scale applied: 2 x 128 steps)
        {
            "hook": "result",
            "item": "test_up[slow]",
            "timesteps": 256,
            "goals": {"up/slow": "passed", "up/position": "failed"},
            "seeds": [0, 1],
        },
        {"hook": "falsification", "item": "test_up[falsify]", "seed": 0, "verdict": "missed", "found": True},
        {"hook": "falsification", "item": "test_up[falsify]", "seed": 1, "verdict": "missed", "found": True},
        # a spec of its own (one seed, no thresholds), trained by the fixture
        {"hook": "result", "item": "test_by_the_fixture", "timesteps": 256, "goals": {}, "seeds": [0]},
    ]


def test_the_guides_example_conftest_writes_each_result(pytester):
    """docs/guide/pytest-plugin.md's example, loaded beside the test's own conftest as a plugin module."""
    example = next(b for b in python_blocks(page("guide/pytest-plugin.md")) if "def pytest_goal_spec_result" in b)
    pytester.makepyfile(guide_hooks=example)
    result, calls = heard(pytester, "--goal-specs", "-p", "guide_hooks", "-k", "test_by_the_fixture")
    result.assert_outcomes(passed=1, deselected=3)
    (written,) = [json.loads(line) for line in (pytester.path / "spec-results.jsonl").read_text().splitlines()]
    assert written["test"] == "test_specs.py::test_by_the_fixture" and written["goals"] == {}
    assert [run["seed"] for run in written["runs"]] == [0] == calls[0]["seeds"]


def test_without_goal_specs_nothing_is_heard(pytester):
    result, calls = heard(pytester)
    result.assert_outcomes(skipped=4)
    assert calls == []
