"""An agent judged under pytest, saved in a baseline and compared with it on the saved episodes
(:mod:`specguard.gate.saved_agent`), through pytester."""

from __future__ import annotations

import json

import pytest
from test_plugin import run
from test_plugin_agents import write

from specguard.gate.baseline import load_baseline, save_baseline

# "right" (the pole ends leaning right): always pushing left meets it in every episode; pushing the way the cart
# started meets it in about half of them (the cart's start decides the fall), as often as the baseline, never more.
GATE = """
RIGHT = sg.Goal("right", theta=(0.1, None)).annotate(sg.Constraint(off_the_edges, name="edges"))


def left(obs):
    return 0


def left_too(obs):  # another agent (its code differs), playing as left does
    return 0 if obs[0] < 10 else 1


def by_cart(obs):
    return int(obs[0] > 0)


@sg.goal_spec(expect={{"right": 0.1, "right:edges": 0.5}})
def test_gate():
    budget = sg.Budget(timesteps=1, eval_episodes=30, max_eval_episodes=30)
    return sg.AgentCheck(sg.Spec(CARTPOLE, RIGHT, budget=budget), {agent}{options})
"""


def gate(pytester: pytest.Pytester, agent: str, options: str = "") -> None:
    write(pytester, GATE.format(agent=agent, options=options))


def baseline_path(pytester: pytest.Pytester):
    return pytester.path / "baselines" / "main.json"


def test_an_agent_is_saved_beside_trained_specs_and_compared_on_its_saved_episodes(pytester):
    save_baseline(
        baseline_path(pytester), {"other.py::test_trained::goal": [(3, 4)]}, {"other.py::test_trained::goal": "k"}
    )
    gate(pytester, "left")
    saved = run(pytester, "--goal-specs", "--goal-specs-save=main")
    saved.assert_outcomes(passed=2)
    saved.stdout.fnmatch_lines(["*wrote baseline*main.json: replaced none, added 1 spec (*::test_gate), kept 1 other"])
    baseline = load_baseline(baseline_path(pytester))
    assert list(baseline.runs) == ["other.py::test_trained::goal"]  # the trained spec's entry kept
    entry = baseline.agents["test_agent_checks.py::test_gate"]
    assert entry.name == "left" and entry.settings == {"observation": "env", "wrap": None, "seed_base": 1_000_000}
    assert entry.seeds == list(range(1_000_000, 1_000_030))
    assert entry.outcomes == {"right": [1] * 30, "right:edges": [1] * 30}
    stored = json.loads(baseline_path(pytester).read_text())["agents"]["test_agent_checks.py::test_gate"]
    assert stored["episodes"][0] == {"seed": 1_000_000, "outcomes": {"right": 1, "right:edges": 1}}

    same = run(pytester, "--goal-specs", "--goal-specs-compare=main")
    same.assert_outcomes(passed=2)
    same.stdout.fnmatch_lines(
        ["*test_gate*right *passed*unchanged: the same agent as baseline 'main' ('left'; its outcomes are the "
         "baseline's); not compared"]
    )  # fmt: skip
    assert "Holm" not in same.stdout.str()  # nothing compared, nothing in the family

    gate(pytester, "left_too")
    fine = run(pytester, "--goal-specs", "--goal-specs-compare=main")
    fine.assert_outcomes(passed=2)
    fine.stdout.fnmatch_lines(
        [
            "*test_gate*right *passed*unchanged within chance: 100% -> 100% (a drop of 14 points at most, under the "
            "margin of 20; paired on 30 saved episodes, 0 lost, 0 gained)",
            "*test_gate*right:edges (safe)*passed*unchanged within chance: 100% -> 100%*",
            "specguard: Holm's step-down procedure over 2 comparisons at family-wise 5%; each comparison was judged "
            "at 0.017 (Holm's first step over the 3 goals and safety rates of the baseline)",
            "specguard: dropped: none",
            "specguard: saved episodes paired per agent: test_agent_checks.py::test_gate 30",
        ]
    )


def test_an_agent_that_fails_more_of_the_saved_episodes_dropped_and_fails(pytester):
    gate(pytester, "left")
    run(pytester, "--goal-specs", "--goal-specs-save=main").assert_outcomes(passed=2)
    gate(pytester, "by_cart")
    plan = run(pytester, "--goal-specs", "--goal-specs-compare=main", "--goal-specs-plan")
    plan.stdout.fnmatch_lines(
        [
            "test_agent_checks.py::test_gate: an agent trained elsewhere (AgentCheck), judged by check_agent: *",
            "comparison with a baseline: paired on 30 saved episodes (agent 'left', env seeds 1000000..1000029); "
            "exact one-sided McNemar test on paired episodes, each judged at 0.025 (5% over 2 comparisons, Holm's "
            "first step)*",
        ]
    )
    worse = run(pytester, "--goal-specs", "--goal-specs-compare=main")
    worse.assert_outcomes(passed=1, failed=1)
    worse.stdout.fnmatch_lines(
        [
            "*hint: success dropped: 100% -> 53% (p = 6.1e-05 <= 0.025; paired on 30 saved episodes, 14 lost, "
            "0 gained) against baseline 'main'",
            "*test_gate*right *failed*dropped: 100% -> 53%*",
            "*test_gate*right:edges (safe)*passed*unchanged within chance*",
            "specguard: dropped: test_agent_checks.py::test_gate::right",
        ]
    )


MORE = """

@sg.goal_spec(expect=0.1)
def test_more():
    budget = sg.Budget(timesteps=1, eval_episodes=30, max_eval_episodes=30)
    return sg.AgentCheck(sg.Spec(CARTPOLE, sg.Goal("right", theta=({bound}, None)), budget=budget), left)
"""


def test_old_baselines_other_settings_and_trained_entries_are_not_compared_saying_why(pytester):
    path = baseline_path(pytester)
    path.parent.mkdir()
    trained = {"runs": [[3, 4]], "spec": "k", "seeds": [0]}
    path.write_text(json.dumps({"format": 3, "goals": {"test_agent_checks.py::test_gate::right": trained}}))
    write(pytester, GATE.format(agent="left", options="") + MORE.format(bound=0.1))
    old = run(pytester, "--goal-specs", "--goal-specs-compare=main")
    old.assert_outcomes(passed=3)
    old.stdout.fnmatch_lines(
        [
            "*test_gate*right *passed*not compared: baseline 'main' holds a trained spec's figures for this test, "
            "not an agent's",
            "*test_more*right *passed*not compared: baseline 'main' holds no agent saved for this test",
        ]
    )
    run(pytester, "--goal-specs", "--goal-specs-save=main").assert_outcomes(passed=3)
    assert sorted(load_baseline(path).agents) == ["test_agent_checks.py::test_gate", "test_agent_checks.py::test_more"]
    assert load_baseline(path).runs == {}  # the agent saved for test_gate replaced its trained goals
    write(pytester, GATE.format(agent="left_too", options=", seed=1") + MORE.format(bound=0.15))
    other = run(pytester, "--goal-specs", "--goal-specs-compare=main")
    other.assert_outcomes(passed=3)
    other.stdout.fnmatch_lines(
        [
            "*test_gate*right *passed*not compared: other evaluation settings than baseline 'main''s (seed_base "
            "1100000, not 1000000 as saved)",
            "*test_more*right *passed*not compared: the spec changed since baseline 'main' (a saved agent is "
            "compared on its spec)",
        ]
    )
