"""The ``[falsify]`` item of ``@sg.goal_spec(falsify=...)``, driven through pytester on tiny budgets; its rule alone."""

from __future__ import annotations

import json
import re
import textwrap

import pytest

import specguard as sg
from specguard.falsify.assertion import Falsify, as_falsify, falsify_verdict
from specguard.falsify.search import Falsification
from specguard.starts.space import StartSpace
from specguard.stats.verdicts import RunVerdict

HEADER = """
import dataclasses

import pytest
import specguard as sg

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
PENDULUM = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
# Upright: a policy trained for 128 steps misses it from nearly every start.
UPRIGHT = sg.All(sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)), sg.Goal("slow", omega=(-8, 8)), name="up")
# Anywhere: every episode enters it at its first step, whatever the policy and the start, so nothing can falsify it
# (a root goal met at the start itself is refused before training: GoalMetAtStart).
from specguard.testing import ReplayEnv
STEPS = [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]  # x, y, omega: omega enters [0.5, 8] at the first step
STEP_IN = sg.InitialEnv(lambda: ReplayEnv(STEPS), features=("x", "y", "omega"))
ANYWHERE = sg.All(sg.Goal("position", x=(-1.0, 1.0)), sg.Goal("slow", omega=(0.5, 8)), name="anywhere")
EVERYWHERE = sg.StartSpace({"x": (-1.0, 1.0)}, set_state=lambda env, values: env.reset()[0])
SEARCH = dict(examples=4, uniform=8)


def tiny(tree):
    budget = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=4, checkpoints=1)
    initial = STEP_IN if tree is ANYWHERE else PENDULUM
    return sg.Spec(initial, tree, budget=budget, trainer=sg.SB3(hyperparameters=TINY))
"""


def run(pytester: pytest.Pytester, body: str, *args: str) -> pytest.RunResult:
    pytester.makepyfile(test_specs=HEADER + textwrap.dedent(body))
    pytester.makeini("[pytest]\ngoal_specs_workers = 1\n")
    cache = pytester.path / "cache"
    return pytester.runpytest_subprocess("-p", "no:cacheprovider", f"--goal-specs-cache-dir={cache}", *args)


def test_a_counterexample_fails_the_falsify_item_with_its_report(pytester):
    result = run(
        pytester,
        """
        @sg.goal_spec(expect={"slow": 0.0}, falsify=sg.Falsify({"theta": (-1.0, 1.0)}, **SEARCH))
        def test_up():
            return tiny(UPRIGHT)


        @sg.goal_spec(expect={"slow": 0.0}, falsify=sg.Falsify(EVERYWHERE, **SEARCH))
        def test_anywhere():
            return tiny(ANYWHERE)
        """,
        "--goal-specs",
        "-v",
    )
    result.assert_outcomes(passed=3, failed=1)
    result.stdout.fnmatch_lines(
        [
            "*test_up[[]slow[]] PASSED*",
            "*test_up[[]falsify[]] FAILED*",
            "*test_anywhere[[]falsify[]] PASSED*",
            "*falsified:*",
            "*seed 0: missed (a counterexample found)*",
            "*counterexample (*): theta=*, omega=*",
            "*missed: up*",
            "*failure rate over the start space: *(*/8 uniform draws), interval*",
        ]
    )


def test_a_failure_rate_above_max_rate_fails_and_one_allowed_passes(pytester):
    result = run(
        pytester,
        """
        @sg.goal_spec(expect={"slow": 0.0}, falsify=sg.Falsify(max_rate=0.1, **SEARCH))
        def test_strict():
            return tiny(UPRIGHT)


        # 0 of 8 failed: at most 37%
        @sg.goal_spec(expect={"slow": 0.0}, falsify=sg.Falsify(EVERYWHERE, max_rate=0.5, **SEARCH))
        def test_anywhere():
            return tiny(ANYWHERE)
        """,
        "--goal-specs",
        "-v",
    )
    result.assert_outcomes(passed=3, failed=1)
    result.stdout.fnmatch_lines(["*test_strict[[]falsify[]] FAILED*", "*seed 0: missed (a failure rate at most 0.1*"])


def test_a_malformed_falsify_fails_its_own_item_and_no_falsify_adds_no_item(pytester):
    result = run(
        pytester,
        """
        @sg.goal_spec(expect={"slow": 0.0}, falsify="everywhere")
        def test_bad():
            return tiny(ANYWHERE)


        @sg.goal_spec(expect={"slow": 0.0})
        def test_plain():
            return tiny(ANYWHERE)
        """,
        "--goal-specs",
        "--collect-only",
        "-q",
    )
    result.stdout.fnmatch_lines(["test_specs.py::test_bad[[]spec[]]", "test_specs.py::test_plain[[]slow[]]"])
    assert "falsify]" not in result.stdout.str()


def test_the_verdict_without_max_rate_is_whether_a_counterexample_was_found():
    none = Falsification(StartSpace(), uniform_failures=0, uniform_episodes=10)
    assert falsify_verdict(none, None) is RunVerdict.MET
    assert falsify_verdict(none, 0.5) is RunVerdict.MET  # 0/10 failed: at most 31% at 95%
    assert falsify_verdict(none, 0.05) is RunVerdict.UNDECIDED  # ten draws cannot show a rate under 5%


def test_the_verdict_with_max_rate_is_the_interval_rule_of_thresholds():
    def rate(failures, episodes, max_rate):
        return falsify_verdict(
            Falsification(StartSpace(), uniform_failures=failures, uniform_episodes=episodes), max_rate
        )

    assert rate(0, 100, 0.05) is RunVerdict.MET  # at most 3.6% at 95%
    assert rate(20, 100, 0.05) is RunVerdict.MISSED  # at least 12.7%
    assert rate(5, 100, 0.05) is RunVerdict.UNDECIDED  # [1.6%, 11.3%] holds 5%


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("everywhere", "expected falsify to be a Falsify"),
        (Falsify, "expected falsify to be a Falsify"),
    ],
)
def test_as_falsify_refuses_what_is_not_a_falsification(value, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        as_falsify("goal_spec 'test'", value)


def test_as_falsify_reads_every_declared_form():
    assert as_falsify("w", None) is None and as_falsify("w", False) is None
    assert as_falsify("w", True) == Falsify()
    assert as_falsify("w", {"x": (-1, 1)}).starts == StartSpace({"x": (-1, 1)})
    check = Falsify(max_rate=0.05)
    assert as_falsify("w", check) is check


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"examples": 0}, "examples to be an integer >= 1"),
        ({"uniform": -1}, "uniform to be an integer >= 0"),
        ({"max_rate": 1.0}, r"max_rate to be a number in \(0, 1\)"),
        ({"max_rate": 0.0}, r"max_rate to be a number in \(0, 1\) \(.*; None for no failing start\), got 0.0"),
        ({"max_rate": float("nan")}, r"max_rate to be a number in \(0, 1\)"),
        ({"max_rate": True}, r"max_rate to be a number in \(0, 1\)"),
        ({"max_rate": 0.1, "uniform": 0}, "needs uniform draws"),
        ({"seed": 1.5}, "seed to be an integer"),
        ({"starts": 3}, "starts to be a StartSpace"),
    ],
)
def test_falsify_refuses_bad_arguments_naming_them(kwargs, message):
    starts = kwargs.pop("starts", None)
    with pytest.raises(sg.error.InvalidSpec, match=message):
        Falsify(starts, **kwargs)


def test_goal_specs_take_falsify_per_spec(pytester):
    result = run(
        pytester,
        """
        up = dataclasses.replace(tiny(UPRIGHT), expect={"slow": 0.0})
        test_specs = sg.goal_specs({"up": up}, falsify={"up": sg.Falsify(**SEARCH)})
        """,
        "--goal-specs",
        "-v",
    )
    result.assert_outcomes(passed=1, failed=1)
    result.stdout.fnmatch_lines(["*test_specs[[]up-up/slow[]] PASSED*", "*test_specs[[]up-falsify[]] FAILED*"])


def test_goal_specs_refuse_falsify_for_a_spec_they_do_not_have():
    pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    spec = sg.Spec(pendulum, sg.Goal("up", x=(0.9, 1.0)), budget=sg.Budget(timesteps=128), expect={"up": 0.5})
    with pytest.raises(sg.error.InvalidSpec, match=r"goal_specs\(falsify=...\).*names specs \['down'\]"):
        sg.goal_specs({"up": spec}, falsify={"down": True})


def test_the_report_gets_a_gif_replaying_each_counterexample(pytester):
    result = run(
        pytester,
        """
        @sg.goal_spec(expect={"slow": 0.0}, falsify=sg.Falsify({"theta": (-1.0, 1.0)}, **SEARCH))
        def test_up():
            return tiny(UPRIGHT)
        """,
        "--goal-specs",
        "--goal-specs-report=report",
    )
    result.assert_outcomes(passed=1, failed=1)
    out = result.stdout.str()
    gif = pytester.path / "report" / "test_specs.py__test_up-falsify-seed0.gif"
    assert gif.exists() and f"seed 0: counterexample episode: {gif.relative_to(pytester.path)}" in out
    # The GIF replays the counterexample's episode: as many steps as the falsifier's report says it ran.
    steps = re.search(r"episode: (\d+) steps, ", out).group(1)
    assert re.search(rf"falsify-seed0\.gif \(up, {steps} steps; goals met at the end: .*missed: up", out)
    # The Markdown report shows the counterexample with its GIF; the JSON keeps its exact start.
    markdown = (pytester.path / "report" / "goal-specs.md").read_text()
    assert "### Counterexamples" in markdown and f"]({gif.name})" in markdown
    assert "**`test_specs.py::test_up`**, seed 0: missed (a counterexample found): `theta=" in markdown
    data = json.loads((pytester.path / "report" / "goal-specs.json").read_text())
    (found,) = data["counterexamples"]
    assert found["gif"] == gif.name and found["missed"] and f"theta={found['start']['theta']!r}" in out  # exact


class _Reporter:
    def __init__(self, isatty):
        self.isatty, self.lines = isatty, []

    def ensure_newline(self):
        pass

    def write_line(self, line):
        self.lines.append(line)


class _Config:
    """What the terminal sinks read of a pytest config: verbosity, the reporter, markup."""

    def __init__(self, *, isatty=True, verbosity=0):
        self.reporter, self.verbosity = _Reporter(isatty), verbosity
        self.pluginmanager = self

    def get_plugin(self, name):
        return self.reporter if name == "terminalreporter" else None

    def get_verbosity(self):
        return self.verbosity

    def get_terminal_writer(self):
        return type("Writer", (), {"hasmarkup": True})()


def test_falsify_progress_lines_reach_a_live_terminal_as_training_s_do_and_never_a_log_or_quiet_run():
    from specguard.pytest_plugin.session import terminal_lines

    live = _Config()
    terminal_lines(live)("up seed 0: guided search: up to 200 episodes")
    assert live.reporter.lines == ["[specguard] up seed 0: guided search: up to 200 episodes"]
    for quiet in (_Config(isatty=False), _Config(verbosity=-1)):
        terminal_lines(quiet)("anything")
        assert quiet.reporter.lines == []


def test_in_a_log_training_progress_shows_once_every_interval_and_each_seeds_last_line(monkeypatch):
    # A CI log is not a terminal: a LunarLander item once printed nothing for 13 minutes.
    from specguard.pytest_plugin import session
    from specguard.training.progress import ProgressEvent

    clock = [0.0]
    monkeypatch.setattr(session.time, "monotonic", lambda: clock[0])
    update = ProgressEvent("up", 0, "update", steps=10, budget=100, elapsed_s=1.0, success=None, episodes=0)
    done = ProgressEvent("up", 0, "done", steps=100, budget=100, elapsed_s=9.0, success=1.0, episodes=4)
    log = _Config(isatty=False)
    write = session.terminal_progress(log, every=60)
    for t in (10.0, 59.0, 61.0, 100.0, 122.0):
        clock[0] = t
        write(update)
    assert len(log.reporter.lines) == 2  # at 61 s, then at 122 s (60 s after the last line shown)
    write(done)
    assert len(log.reporter.lines) == 3 and "done" in log.reporter.lines[-1]
    silent = _Config(isatty=False)
    write = session.terminal_progress(silent, every=0)  # --goal-specs-progress-every=0: each seed's last line
    clock[0] = 1000.0
    write(update), write(done)
    assert len(silent.reporter.lines) == 1
