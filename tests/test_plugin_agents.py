"""The pytest plugin judging agents trained elsewhere: goal specs returning an ``sg.AgentCheck``, through pytester."""

from __future__ import annotations

import json
import textwrap
import xml.etree.ElementTree as ET

import pytest
from test_plugin import run

HEADER = """
import numpy as np
import pytest
import specguard as sg

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))


def off_the_edges(s, a):
    return abs(s.x) > 2.0


# Keep the pole up until the end (the initial env's horizon), and the cart off the edges (a safety rate).
BALANCE = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance").annotate(
    sg.Constraint(off_the_edges, name="edges")
)
RIGHT = sg.All(BALANCE, sg.Goal("right", theta=(0.1, None)), name="both")


def keep(expect=(), tree=BALANCE):
    budget = sg.Budget(timesteps=1, eval_episodes=10, max_eval_episodes=10)
    return sg.Spec(CARTPOLE, tree, budget=budget, expect=dict(expect))


def lean(obs):
    # push toward the lean: the pole falls within a few dozen steps, the cart stays on the track
    return int(obs[2] > 0)


RNG = np.random.default_rng(0)


def random_policy(obs):
    return int(RNG.integers(2))
"""

CONFTEST = """
def pytest_goal_spec_result(item, spec, result):
    with open("results.txt", "a") as f:
        f.write(f"{item.nodeid} {spec.label} {result.runs[0].episodes}\\n")
"""


def write(pytester: pytest.Pytester, body: str) -> None:
    # Not test_agents.py: an in-process run beside tests/test_agents.py (imported by then) would not import it.
    pytester.makepyfile(test_agent_checks=HEADER + textwrap.dedent(body))
    pytester.makeconftest(CONFTEST)


def results(pytester: pytest.Pytester) -> list[str]:
    """The results ``pytest_goal_spec_result`` heard of: ``nodeid spec episodes``, one line each."""
    path = pytester.path / "results.txt"
    return path.read_text().splitlines() if path.exists() else []


AGENTS = """
@sg.goal_spec(expect={"edges": 0.5, "balance": 0.5}, xfail={"balance": "push toward the lean drops the pole"})
def test_lean():
    return sg.AgentCheck(keep(), lean)


@sg.goal_spec(expect=0.5)
def test_random():
    return sg.AgentCheck(keep(), random_policy)


@sg.goal_spec(expect={"edges": 0.5}, xfail={"edges": "thought to drive off the track"})
def test_safe_after_all():
    return sg.AgentCheck(keep(), lean)


test_declared = sg.goal_specs({"lean": sg.AgentCheck(keep({"edges": 0.5}), lean, seed=1)})
"""


def test_an_agent_check_is_judged_per_goal_with_xfail_xpass_table_and_junit(pytester):
    write(pytester, AGENTS)
    junit = pytester.path / "junit.xml"
    result = run(pytester, "--goal-specs", f"--junitxml={junit}", "-rX")
    result.assert_outcomes(passed=2, failed=1, xfailed=1, xpassed=1)
    result.stdout.fnmatch_lines(
        [
            "*goal 'balance' of spec 'balance' missed its threshold",
            "*success 0% (0/10), interval [[]0.00, 0.31[]], threshold >= 0.5",
            "*runs: 0 of 1 met (1 required); seeds 0",
            "*agent 'random_policy': 10 evaluation episodes (env seeds 1000000..1000009)*",
        ]
    )
    result.stdout.fnmatch_lines(
        [
            "*= specguard goal specs =*",
            "spec*goal*success*interval*threshold*runs met*per seed*verdict*training",
            "test_agent_checks.py::test_lean *balance *0% (0/10)*>= 0.5*agent: 10 episodes*xfailed*-",
            "test_agent_checks.py::test_lean *balance:edges (safe)*100% (10/10)*>= 0.5*agent: 10 episodes*passed*-",
            "test_agent_checks.py::test_random *balance *0% (0/10)*>= 0.5*agent: 10 episodes*failed*-",
            "test_agent_checks.py::test_safe_after_all *balance:edges (safe)*100% (10/10)*>= 0.5*agent: 10 episodes"
            "*xpassed*-",
            "test_agent_checks.py::test_declared[[]lean[]] *balance:edges (safe)*100% (10/10)*>= 0.5*agent: 10 "
            "episodes*passed*-",
        ]
    )
    assert "0.0s" not in result.stdout.str().split("specguard goal specs")[-1]  # an agent trains nothing
    # judged once per test, its items sharing the result, which other plugins hear of
    heard = sorted(line.split("[")[0].split(" ")[0] for line in results(pytester))
    assert heard == [
        "test_agent_checks.py::test_declared",
        "test_agent_checks.py::test_lean",
        "test_agent_checks.py::test_random",
        "test_agent_checks.py::test_safe_after_all",
    ]
    props = {
        p.get("name"): p.get("value")
        for case in ET.parse(junit).getroot().iter("testcase")
        if case.get("name") == "test_lean[edges]"
        for p in case.iter("property")
    }
    assert props["specguard.balance:edges.threshold"] == "0.5"
    assert props["specguard.balance:edges.episodes"] == "10"
    assert props["specguard.balance:edges.train_seconds"] == "0.0"
    row = json.loads(props["specguard"])
    assert (row["outcome"], row["successes"], row["per_seed"][0]["seed"]) == ("passed", 10, 0)
    assert row["notes"][0].startswith("agent 'lean': 10 evaluation episodes")


def test_agent_items_are_skipped_without_the_flag_and_a_wrong_return_fails_in_one_line(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"edges": 0.5})
        def test_lean():
            return sg.AgentCheck(keep(), lean)


        @sg.goal_spec(expect=0.5)
        def test_an_agent():
            return lean
        """,
    )
    result = pytester.runpytest("-p", "no:cacheprovider", "-rs")
    result.assert_outcomes(skipped=2)
    result.stdout.fnmatch_lines(["*run `pytest --goal-specs` to train it and check its goals*"])
    result = run(pytester, "--goal-specs")
    result.assert_outcomes(passed=1, failed=1)
    result.stdout.fnmatch_lines(
        [
            "test_agent_checks.py::test_an_agent[[]root[]]: a goal spec must return a specguard.Spec or a "
            "specguard.AgentCheck, got function"
        ]
    )
    assert "Traceback" not in result.stdout.str()


def test_undecided_agent_goals_follow_the_sessions_undecided_option(pytester):
    # "right" (the last state leans right) holds in about 4 of 10 starts: undecided at 0.4 after 10 episodes
    write(
        pytester,
        """
        @sg.goal_spec(expect={"right": 0.4})
        def test_right():
            return sg.AgentCheck(keep(tree=RIGHT), lean)
        """,
    )
    run(pytester, "--goal-specs", "--goal-specs-undecided=xfail").assert_outcomes(xfailed=1)
    run(pytester, "--goal-specs", "--goal-specs-undecided=fail").assert_outcomes(failed=1)


def test_an_agent_items_falsify_item_searches_the_agent_and_is_left_out_of_its_saved_entry(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"edges": 0.5}, falsify=True)
        def test_lean():
            return sg.AgentCheck(keep(), lean)
        """,
    )
    saved = run(pytester, "--goal-specs", "--goal-specs-save=main")
    saved.assert_outcomes(passed=1, failed=1)
    saved.stdout.fnmatch_lines(
        [
            "*test_lean[[]falsify[]]*",
            "falsified:",
            "*seed 0: missed (a counterexample found)*",
            "*missed: balance*",
            "*wrote baseline*main.json: replaced none, added 1 spec (test_agent_checks.py::test_lean), kept none",
        ]
    )
    compared = run(pytester, "--goal-specs", "--goal-specs-compare=main", "-k", "not falsify")
    compared.assert_outcomes(passed=1, deselected=1)
    compared.stdout.fnmatch_lines(["*test_lean*balance:edges*passed*unchanged: the same agent as baseline 'main'*"])
    (path,) = (pytester.path / "cache").parent.rglob("main.json")
    assert list(
        json.loads(path.read_text())["agents"]["test_agent_checks.py::test_lean"]["episodes"][0]["outcomes"]
    ) == ["balance:edges"]


def test_xdist_judges_agents_on_the_workers_and_reports_on_the_controller(pytester):
    write(pytester, AGENTS)
    result = run(pytester, "--goal-specs", "-n", "2", "--dist", "loadgroup")
    result.assert_outcomes(passed=2, failed=1, xfailed=1, xpassed=1)
    result.stdout.fnmatch_lines(
        [
            "*= specguard goal specs =*",
            "test_agent_checks.py::test_lean *balance *0% (0/10)*xfailed*",
            "test_agent_checks.py::test_lean *balance:edges (safe)*100% (10/10)*passed*",
        ]
    )
    assert len(results(pytester)) >= 4  # each worker judges its tests once


def test_an_agents_report_has_its_own_rollout_and_counterexample_gifs_and_no_training_panel(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"edges": 0.5}, falsify=True)
        def test_lean():
            return sg.AgentCheck(keep(), lean)
        """,
    )
    report = pytester.path / "report"
    result = run(pytester, "--goal-specs", f"--goal-specs-report={report}", "--goal-specs-no-cache")
    result.assert_outcomes(passed=1, failed=1)
    assert "no rollout GIF" not in result.stdout.str()
    result.stdout.fnmatch_lines(["*seed 0: counterexample episode: *test_lean-falsify-seed0.gif (*)"])
    data = json.loads((report / "goal-specs.json").read_text())
    (counterexample,) = data["counterexamples"]
    assert counterexample["gif"] == "test_agent_checks.py__test_lean-falsify-seed0.gif"
    assert (report / counterexample["gif"]).stat().st_size > 0
    assert (report / "test_agent_checks.py__test_lean.gif").stat().st_size > 0
    assert [row["agent"] for row in data["goals"]] == ["lean"]
    assert not (report / "goal-specs.png").exists()  # an agent trains nothing: no panel of empty curves
    markdown = (report / "goal-specs.md").read_text()
    assert "agent 'lean' (no training: an agent trained elsewhere), seed 0, one evaluation episode" in markdown


def test_the_plot_leaves_out_an_agents_group_beside_a_trained_ones():
    from specguard.report.plots import curves_figure

    point = {"timesteps": 10, "success": {"up": 0.5}}
    trained = {"group": "t.py::trained", "goal": "up", "threshold": 0.5, "curves": [[point]], "per_seed": []}
    agent = {"group": "t.py::agent", "goal": "up", "threshold": 0.5, "curves": [[]], "per_seed": [], "agent": "lean"}
    figure = curves_figure([trained, agent])
    assert [ax.get_title() for ax in figure.axes if ax.get_visible()] == ["trained"]
    assert curves_figure([agent]) is None


def test_an_interrupted_session_writes_a_report_that_says_so(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"edges": 0.5})
        def test_lean():
            return sg.AgentCheck(keep(), lean)


        def test_stopped():
            raise KeyboardInterrupt  # Ctrl-C while this item runs


        def test_never_ran():
            pass
        """,
    )
    report = pytester.path / "report"
    result = run(pytester, "--goal-specs", f"--goal-specs-report={report}")
    assert result.ret == pytest.ExitCode.INTERRUPTED
    data = json.loads((report / "goal-specs.json").read_text())
    assert [row["verdict"] for row in data["goals"]] == ["passed"]
    assert data["interrupted"] == "the session was interrupted after 1 of 3 items ran"
    markdown = (report / "goal-specs.md").read_text()
    assert "**Incomplete**: the session was interrupted after 1 of 3 items ran" in markdown
    # a session that ran every item says nothing of it
    write(pytester, AGENTS)
    run(pytester, "--goal-specs", f"--goal-specs-report={report}")
    assert json.loads((report / "goal-specs.json").read_text())["interrupted"] is None
    assert "Incomplete" not in (report / "goal-specs.md").read_text()
