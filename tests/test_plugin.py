"""The pytest plugin, driven through pytester on tiny budgets."""

from __future__ import annotations

import json
import re
import textwrap
import xml.etree.ElementTree as ET

import pytest

HEADER = """
import pytest
import specguard as sg

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}


@pytest.fixture
def pendulum():
    return sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))


@pytest.fixture
def tree():
    return sg.All(
        sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)),
        sg.Goal("stabilization", omega=(-0.25, 0.25)),
        name="pendulum",
    )


def tiny(pendulum, tree, seeds=1, episodes=4, max_episodes=None):
    budget = sg.Budget(timesteps=128, min_seeds=seeds, eval_episodes=episodes, max_eval_episodes=max_episodes)
    return sg.Spec(pendulum, tree, budget=budget, trainer=sg.SB3(hyperparameters=TINY))
"""


def write(pytester: pytest.Pytester, body: str) -> None:
    pytester.makepyfile(test_specs=HEADER + textwrap.dedent(body))
    pytester.makeini("[pytest]\ngoal_specs_workers = 1\n")


def run(pytester: pytest.Pytester, *args: str) -> pytest.RunResult:
    cache = pytester.path / "cache"
    return pytester.runpytest_subprocess("-p", "no:cacheprovider", f"--goal-specs-cache-dir={cache}", *args)


PASS_AND_XFAIL = """
@sg.goal_spec(expect={"stabilization": 0.0, "position": 0.95}, xfail={"position": "never within 128 steps"})
def test_tiny(pendulum, tree):
    return tiny(pendulum, tree, seeds=2)


@sg.goal_spec(expect=0.9)
def test_root_fails(pendulum, tree):
    return tiny(pendulum, tree)


def test_ordinary():
    assert True
"""


def test_items_are_skipped_without_the_flag(pytester):
    write(pytester, PASS_AND_XFAIL)
    result = pytester.runpytest("-p", "no:cacheprovider", "-rs", "--collect-only", "-q")
    result.stdout.fnmatch_lines(
        [
            "test_specs.py::test_tiny[stabilization]",
            "test_specs.py::test_tiny[position]",
            "test_specs.py::test_root_fails[root]",
        ]
    )
    result = pytester.runpytest("-p", "no:cacheprovider", "-rs")
    result.assert_outcomes(passed=1, skipped=3)
    result.stdout.fnmatch_lines(["*run `pytest --goal-specs` to train it and check its goals*"])


def test_pass_fail_xfail_summary_and_junit(pytester):
    write(pytester, PASS_AND_XFAIL)
    junit = pytester.path / "junit.xml"
    result = run(pytester, "--goal-specs", f"--junitxml={junit}")
    result.assert_outcomes(passed=2, failed=1, xfailed=1)
    result.stdout.fnmatch_lines(
        [
            "*goal 'pendulum' of spec 'pendulum' missed its threshold",
            "*success 0% (0/4), interval [[]0.00, 0.60[]], threshold >= 0.9",
            "*runs: 0 of 1 met (1 required); seeds 0",
            "*per seed: seed 0: 0/4 (missed)",
            "*hint: sparse goal never reached in 1/1 seeds: consider a Distance annotation on 'pendulum'",
        ]
    )
    result.stdout.fnmatch_lines(
        [
            "*= specguard goal specs =*",
            "spec*goal*success*interval*threshold*runs met*per seed*verdict*training",
            "test_specs.py::test_tiny*pendulum/stabilization*>= 0*2/2*/4, */4*passed*",
            "test_specs.py::test_tiny*pendulum/position*0% (0/8)*>= 0.95*0/2*xfailed*",
            "test_specs.py::test_root_fails*pendulum*0% (0/4)*>= 0.9*0/1*failed*",
        ]
    )
    props = {
        p.get("name"): p.get("value")
        for case in ET.parse(junit).getroot().iter("testcase")
        if case.get("name") == "test_root_fails[root]"
        for p in case.iter("property")
    }
    assert props["specguard.pendulum.threshold"] == "0.9"
    assert props["specguard.pendulum.episodes"] == "4"
    assert props["specguard.pendulum.interval"].startswith("[0.0000, 0.60")
    assert re.fullmatch("seed 0: [0-9a-f]{12}", props["specguard.pendulum.weights"])  # the judged weights' digest
    row = json.loads(props["specguard"])
    assert row["outcome"] == "failed"
    assert props["specguard.pendulum.weights"] == f"seed 0: {row['per_seed'][0]['weights_digest'][:12]}"


def test_safety_thresholds_are_items_rows_and_junit_properties(pytester):
    # A constraint Pendulum never violates (|omega| <= 8) and one violated at every step, whose budget never runs
    # out: an episode with any violation is unsafe, so its safety rate is 0 while the episodes run to their end.
    write(
        pytester,
        """
        @pytest.fixture
        def guarded(tree):
            never = sg.Constraint(lambda s, a: abs(s.omega) > 8.5, name="never")
            always = sg.Constraint(lambda s, a: True, budget=1000, name="always")
            return tree.annotate(never, always)


        @sg.goal_spec(expect={"stabilization": 0.0, "never": 0.5, "pendulum:always": 0.5})
        def test_safe(pendulum, guarded):
            return tiny(pendulum, guarded)
        """,
    )
    junit = pytester.path / "junit.xml"
    report = pytester.path / "report"
    result = run(pytester, "--goal-specs", f"--junitxml={junit}", f"--goal-specs-report={report}")
    result.assert_outcomes(passed=2, failed=1)
    result.stdout.fnmatch_lines(
        [
            "*safety rate 'pendulum:always' of spec 'pendulum' missed its threshold",
            "*safe (no violation) in 0% (0/16), interval [[]0.00, 0.21[]], threshold >= 0.5",
            "*per seed: seed 0: 0/16 (missed)",
            "*hint: 'pendulum:always' was violated in 100% of evaluation episodes; in every episode of 1/1 seeds*",
        ]
    )
    result.stdout.fnmatch_lines(
        [
            "*= specguard goal specs =*",
            "spec*goal*success*interval*threshold*runs met*per seed*verdict*training",
            "test_specs.py::test_safe*pendulum/stabilization *>= 0 *1/1*passed*",
            "test_specs.py::test_safe*pendulum:never (safe) *100% (16/16)*>= 0.5*1/1*16/16*passed*",
            "test_specs.py::test_safe*pendulum:always (safe) *0% (0/16)*>= 0.5*0/1*0/16*failed*",
        ]
    )
    props = {
        p.get("name"): p.get("value")
        for case in ET.parse(junit).getroot().iter("testcase")
        if case.get("name") == "test_safe[pendulum:always]"
        for p in case.iter("property")
    }
    assert props["specguard.pendulum:always.kind"] == "safety"
    assert props["specguard.pendulum:always.success"] == "0.0"
    assert props["specguard.pendulum:always.threshold"] == "0.5"
    rows = json.loads((report / "goal-specs.json").read_text())["goals"]
    assert {r["goal"]: r["kind"] for r in rows} == {
        "pendulum/stabilization": "goal",
        "pendulum:never": "safety",
        "pendulum:always": "safety",
    }
    assert "| test_specs.py::test_safe | `pendulum:always` (safe) |" in (report / "goal-specs.md").read_text()


def test_xpass_when_an_expected_miss_starts_passing(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 0.0}, xfail={"stabilization": "paper says it misses"})
        def test_now_passes(pendulum, tree):
            return tiny(pendulum, tree)
        """,
    )
    run(pytester, "--goal-specs").assert_outcomes(xpassed=1)


def test_one_item_for_the_specs_own_thresholds_and_the_result_fixture(pytester):
    write(
        pytester,
        """
        @sg.goal_spec()
        def test_whole(pendulum, tree):
            spec = tiny(pendulum, tree)
            return sg.Spec(spec.initial_env, spec.tree, budget=spec.budget, trainer=sg.SB3(hyperparameters=TINY),
                           expect={"stabilization": 0.0})


        def test_custom(goal_spec_result, pendulum, tree):
            result = goal_spec_result(tiny(pendulum, tree))
            assert [r.seed for r in result.runs] == [0]
            assert result.runs[0].episodes == 4
        """,
    )
    result = run(pytester, "--goal-specs", "-v")
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines(["*test_whole[[]spec[]] PASSED*"])
    run(pytester).assert_outcomes(skipped=2)


def test_specs_that_differ_only_in_how_runs_are_counted_do_not_share_a_result(pytester):
    # They once shared one training result: the second reported 1/1 runs met where, run alone, it reports 2/2.
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_one_seed(pendulum, tree):
            return tiny(pendulum, tree, seeds=1)


        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_two_seeds(pendulum, tree):
            return tiny(pendulum, tree, seeds=2)
        """,
    )
    result = run(pytester, "--goal-specs")
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines(
        [
            "test_specs.py::test_one_seed*pendulum/stabilization*/4)*1/1*passed*",
            "test_specs.py::test_two_seeds*pendulum/stabilization*/8)*2/2*passed*",
        ]
    )


@pytest.mark.parametrize(("mode", "outcome"), [("fail", "failed"), ("xfail", "xfailed"), ("pass", "passed")])
def test_undecided_modes(pytester, mode, outcome):
    # Two evaluation episodes can never place a run's interval on one side of 0.5.
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 0.5})
        def test_undecided(pendulum, tree):
            return tiny(pendulum, tree, episodes=2, max_episodes=2)
        """,
    )
    result = run(pytester, "--goal-specs", f"--goal-specs-undecided={mode}", "-rxs")
    result.assert_outcomes(**{outcome: 1}, **({"warnings": 1} if mode == "pass" else {}))
    if mode == "fail":
        result.stdout.fnmatch_lines(["*could not be decided for its threshold*", "*hint: runs stayed undecided*"])


def test_save_then_compare_gates_regressions(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_gate(pendulum, tree):
            return tiny(pendulum, tree, seeds=2)
        """,
    )
    baselines = pytester.path / "baselines"
    opts = [f"--goal-specs-baseline-dir={baselines}", "--goal-specs-compare-seeds=4"]
    saved = run(pytester, "--goal-specs", "--goal-specs-save", "main", *opts)
    saved.assert_outcomes(passed=1)
    stored = json.loads((baselines / "main.json").read_text())
    key = "test_specs.py::test_gate::pendulum/stabilization"
    assert stored["format"] == 4 and stored["goals"][key]["seeds"] == [0, 1, 2, 3]  # more seeds than the spec's 2
    assert len(stored["goals"][key]["runs"]) == 4 and len(stored["goals"][key]["spec"]) == 64
    same = run(pytester, "--goal-specs", "--goal-specs-compare", *opts)
    same.assert_outcomes(passed=1)
    same.stdout.fnmatch_lines(["*unchanged: the same spec and runs as baseline 'latest' (seeds 0, 1); not compared*"])
    # A baseline where every episode succeeded: the tiny policy's success is a drop, flagged once 4 seeds are in.
    stored["goals"][key]["runs"] = [[40, 40]] * 4
    (baselines / "perfect.json").write_text(json.dumps(stored))
    dropped = run(pytester, "--goal-specs", "--goal-specs-compare", "perfect", *opts)
    dropped.assert_outcomes(failed=1)
    dropped.stdout.fnmatch_lines(
        [
            "*hint: success dropped: 100% -> *(p = * <= 0.05; 4 seeds vs 4 in the baseline, looks at 2, 4)*",
            "specguard: Holm's step-down procedure over 1 comparison at family-wise 5%; each comparison was judged at "
            "0.05 while its seeds trained (Holm's first step over the 1 goal and safety rate of the baseline)",
        ]
    )
    # The same goal of a changed spec (another threshold) is compared, and said to come from a changed spec.
    pytester.makepyfile(test_specs=(pytester.path / "test_specs.py").read_text().replace("0.0}", "0.01}"))
    changed = run(pytester, "--goal-specs", "--goal-specs-compare", "main", *opts)
    assert "the spec changed since baseline 'main'" in changed.stdout.str()


def test_report_dir_has_json_markdown_and_plot(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_report(pendulum, tree):
            return tiny(pendulum, tree)
        """,
    )
    report = pytester.path / "report"
    run(pytester, "--goal-specs", f"--goal-specs-report={report}").assert_outcomes(passed=1)
    data = json.loads((report / "goal-specs.json").read_text())
    assert data["goals"][0]["goal"] == "pendulum/stabilization" and data["goals"][0]["curves"]
    assert "| test_specs.py::test_report | `pendulum/stabilization` |" in (report / "goal-specs.md").read_text()
    assert (report / "goal-specs.png").read_bytes()[:4] == b"\x89PNG"


def test_xdist_runs_each_spec_once_and_reports_on_the_controller(pytester):
    # Each training appends a line: a spec whose items run on both workers is still trained once (the cache's
    # lock), whether or not --dist loadgroup groups them (it does not with pytest 9.2: pytest-xdist issue 1386).
    trainings = pytester.path / "trainings.txt"
    write(
        pytester,
        f"""
        import dataclasses

        from stable_baselines3.common.callbacks import BaseCallback


        class CountTraining(BaseCallback):
            def _on_training_start(self):
                with open({str(trainings)!r}, "a") as f:
                    f.write("trained\\n")

            def _on_step(self):
                return True


        COUNTING = sg.SB3(hyperparameters=TINY, callbacks=[CountTraining])


        @sg.goal_spec(expect={{"stabilization": 0.0, "pendulum": 0.0, "position": 0.0}})
        def test_a(pendulum, tree):
            return dataclasses.replace(tiny(pendulum, tree), trainer=COUNTING)


        @sg.goal_spec(expect={{"stabilization": 0.0}})
        def test_b(pendulum, tree):
            return dataclasses.replace(tiny(pendulum, tree), trainer=COUNTING)
        """,
    )
    result = run(pytester, "--goal-specs", "-n", "2", "--dist", "loadgroup")
    result.assert_outcomes(passed=4)
    result.stdout.fnmatch_lines(["*= specguard goal specs =*"])
    assert result.stdout.str().count("test_specs.py::test_a ") == 3
    assert trainings.read_text().splitlines() == ["trained", "trained"]


def test_bad_input_gives_one_clear_error_and_other_specs_still_run(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_wrong_type(pendulum, tree):
            return 42


        @sg.goal_spec(expect={"altitude": 0.5})
        def test_missing_goal(pendulum, tree):
            return tiny(pendulum, tree)


        @pytest.fixture
        def broken():
            raise RuntimeError("fixture broke")


        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_failing_fixture(broken, tree):
            return tree


        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_fine(pendulum, tree):
            return tiny(pendulum, tree)
        """,
    )
    result = run(pytester, "--goal-specs")
    result.assert_outcomes(passed=1, failed=2, errors=1)
    result.stdout.fnmatch_lines(
        [
            "*test_specs.py::test_wrong_type[[]stabilization[]]: a goal spec must return a specguard.Spec or a "
            "specguard.AgentCheck, got int",
            "*test_specs.py::test_missing_goal[[]altitude[]]: Spec 'pendulum': no node is named 'altitude'; "
            "the tree's goals are pendulum, pendulum/position, pendulum/stabilization",
        ]
    )


def test_a_malformed_decorator_fails_its_item_and_the_other_specs_still_run(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 1.0})
        def test_bad(pendulum, tree):
            return tiny(pendulum, tree)


        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_fine(pendulum, tree):
            return tiny(pendulum, tree)
        """,
    )
    result = run(pytester, "--goal-specs")
    result.assert_outcomes(passed=1, failed=1)
    result.stdout.fnmatch_lines(
        [
            "*test_specs.py::test_bad[[]spec[]]: goal_spec 'test_bad'.expect[[]'stabilization'[]]: a threshold of 1 "
            "can never be met: a run meets a threshold when its whole confidence interval lies at or above it*",
            "*Hint: ask for e.g. 0.95*",
        ]
    )
    assert "Traceback" not in result.stdout.str()
    run(pytester).assert_outcomes(skipped=2)


def test_goal_specs_gates_specs_declared_once_by_their_own_thresholds(pytester):
    write(
        pytester,
        """
        def make():
            env = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
            tree = sg.All(sg.Goal("position", x=(0.966, 1.0)), sg.Goal("stabilization", omega=(-0.25, 0.25)), name="p")
            budget = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=4)
            return {
                "tiny": sg.Spec(
                    env, tree, budget=budget, trainer=sg.SB3(hyperparameters=TINY),
                    expect={"stabilization": 0.0, "position": 0.95},
                    xfail={"position": "never within 128 steps"},
                ),
            }


        test_declared = sg.goal_specs(make())
        """,
    )
    result = run(pytester, "--goal-specs", "--goal-specs-checkpoints=1", "-v")
    result.assert_outcomes(passed=1, xfailed=1)
    result.stdout.fnmatch_lines(
        ["*test_declared?tiny-p/stabilization? PASSED*", "*test_declared?tiny-p/position? XFAIL*never within*"]
    )
    assert result.stdout.str().count("seed 0: done") == 1  # both items share one training


def test_checkpoints_make_the_budget_a_ceiling(pytester):
    # A threshold of 0 is met at once: judged at the first of 10 checkpoints (step 13 of 128), training stops.
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_tiny(pendulum, tree):
            return tiny(pendulum, tree)
        """,
    )
    anytime = run(pytester, "--goal-specs")
    anytime.assert_outcomes(passed=1)
    anytime.stdout.fnmatch_lines(["*seed 0: done, 13/128 steps*thresholds met at a checkpoint*"])
    full = run(pytester, "--goal-specs", "--goal-specs-checkpoints=1")  # another spec identity: trained again
    full.assert_outcomes(passed=1)
    full.stdout.fnmatch_lines(["*seed 0: done, 128/128 steps*"])
    assert "thresholds met" not in full.stdout.str()


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (
            "--goal-specs-undecided=maybe",
            "--goal-specs-undecided: expected one of fail, xfail, pass, got 'maybe'",
        ),
        ("--goal-specs-budget-scale=0", "--goal-specs-budget-scale: expected a finite number > 0, got '0'"),
        # inf passed the option check and then failed every item (utils.options.parse_positive now)
        ("--goal-specs-budget-scale=inf", "--goal-specs-budget-scale: expected a finite number > 0, got 'inf'"),
        (
            "--goal-specs-checkpoints=0",
            "--goal-specs-checkpoints: expected an integer >= 1 (1: train every run's whole budget), got '0'",
        ),
        ("--goal-specs-checkpoints=2.5", "--goal-specs-checkpoints: expected an integer >= 1*got '2.5'"),
        (
            "--goal-specs-workers=none",
            "--goal-specs-workers: expected an integer >= 1 (or 'auto': one per usable core), got 'none'",
        ),
        ("--goal-specs-workers=05", "--goal-specs-workers: expected an integer >= 1 (or 'auto'*), got '05'"),
        ("--goal-specs-compare=nosuch", "--goal-specs-compare: baseline '*nosuch.json' does not exist*"),
        ("--goal-specs-compare-seeds=0", "--goal-specs-compare-seeds: expected an integer >= 1, got '0'"),
    ],
)
def test_bad_option_values_are_usage_errors(pytester, option, message):
    write(pytester, PASS_AND_XFAIL)
    result = pytester.runpytest("-p", "no:cacheprovider", "--goal-specs", option)
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines([f"ERROR: {message}"])


def test_corrupt_baseline_is_a_usage_error(pytester):
    write(pytester, PASS_AND_XFAIL)
    (pytester.path / "b").mkdir()
    (pytester.path / "b" / "main.json").write_text("{oops")
    result = pytester.runpytest(
        "-p", "no:cacheprovider", "--goal-specs", "--goal-specs-compare=main", "--goal-specs-baseline-dir=b"
    )
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines(["ERROR: --goal-specs-compare: baseline 'b/main.json' is corrupt*"])


def test_ini_settings_enable_and_scale(pytester):
    pytester.makepyfile(
        test_specs=HEADER
        + textwrap.dedent(
            """
            def test_ini(goal_spec_result, pendulum, tree):
                assert goal_spec_result(tiny(pendulum, tree)).runs[0].timesteps == 64
            """
        )
    )
    pytester.makeini("[pytest]\ngoal_specs = true\ngoal_specs_budget_scale = 0.5\ngoal_specs_workers = 1\n")
    run(pytester).assert_outcomes(passed=1)


def test_plain_pytest_does_not_import_heavy_modules(pytester):
    pytester.makepyfile(
        test_plain="""
        import sys

        def test_light():
            heavy = {"torch", "stable_baselines3", "scipy.stats", "gymnasium"} & set(sys.modules)
            assert not heavy, heavy
        """
    )
    pytester.runpytest_subprocess("-p", "no:cacheprovider").assert_outcomes(passed=1)


BROKEN_ENV = """
import gymnasium as gym


class Boom(gym.Wrapper):
    def step(self, action):
        raise RuntimeError("the env broke")


@sg.goal_spec(expect={"stabilization": 0.0})
def test_broken(tree):
    initial = sg.InitialEnv(lambda: Boom(gym.make("Pendulum-v1")), features=("x", "y", "omega"))
    budget = sg.Budget(timesteps=64, min_seeds=1, eval_episodes=2)
    return sg.Spec(initial, tree, budget=budget, trainer=sg.SB3(hyperparameters=TINY))
"""


def test_a_worker_error_is_one_clean_message_with_its_traceback_only_under_verbose(pytester):
    write(pytester, BROKEN_ENV)
    quiet = run(pytester, "--goal-specs", "--goal-specs-no-cache")
    quiet.assert_outcomes(failed=1)
    quiet.stdout.fnmatch_lines(
        ["*seed 0 failed: Spec 'pendulum', seed 0, training step 0: the environment raised RuntimeError: the env broke"]
    )
    text = quiet.stdout.str()
    assert "Traceback" not in text and "_RemoteTraceback" not in text and "During handling" not in text
    verbose = run(pytester, "--goal-specs", "--goal-specs-no-cache", "-v")
    verbose.stdout.fnmatch_lines(["*worker traceback (seed 0):*", "Traceback (most recent call last):*"])


def test_a_crashed_run_fails_a_goal_expected_to_miss_rather_than_xfailing_it(pytester):
    # A run that never finished says nothing of the goal: an xfail mark expects a miss, not a crash.
    write(
        pytester,
        BROKEN_ENV.replace('expect={"stabilization": 0.0}', 'expect={"stabilization": 0.9}, xfail=["stabilization"]'),
    )
    result = run(pytester, "--goal-specs", "--goal-specs-no-cache")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*runs crashed (a crash is not a miss, even for a goal expected to miss)*"])


TRAJECTORY = """
def test_the_trained_agent(goal_spec_result, pendulum, tree):
    result = goal_spec_result(tiny(pendulum, tree))
    model = sg.load_model(result, 0)
    assert type(model).__name__ == "PPO"
    episodes = sg.rollout(result, 0, episodes=2)
    assert len(episodes) == 2
    last = episodes[0][-1]
    assert last["truncated"] and len(episodes[0]) == 200  # Pendulum's time limit: never upright in 128 steps
    assert set(last["info"]["goals"]) == {"pendulum", "pendulum/position", "pendulum/stabilization"}
    assert model.predict(episodes[0][0]["obs"], deterministic=True)[0] == episodes[0][0]["action"]
"""


def test_the_trained_agent_is_at_hand(pytester):
    write(pytester, TRAJECTORY)
    run(pytester, "--goal-specs").assert_outcomes(passed=1)


def test_baselines_live_beside_the_cache_dir_by_default(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect={"stabilization": 0.0})
        def test_gate(pendulum, tree):
            return tiny(pendulum, tree)
        """,
    )
    run(pytester, "--goal-specs", "--goal-specs-save", "main", "--goal-specs-compare-seeds=2").assert_outcomes(passed=1)
    assert (pytester.path / "baselines" / "main.json").is_file()  # run() puts the cache at ./cache
    assert not (pytester.path / ".specguard").exists()


def test_a_spec_error_inside_the_goal_spec_function_fails_its_item_in_one_line(pytester):
    write(
        pytester,
        """
        @sg.goal_spec(expect=0.5)
        def test_builds_a_bad_goal(pendulum):
            return sg.Spec(pendulum, sg.Goal("empty", x=(2.0, 1.0)))  # lo > hi: an InvalidSpec, raised here

        @sg.goal_spec(expect=0.0)
        def test_fine(pendulum, tree):
            return tiny(pendulum, tree)
        """,
    )
    out = run(pytester, "--goal-specs", "-p", "no:randomly")
    out.assert_outcomes(passed=1, failed=1)
    text = out.stdout.str()
    assert "test_specs.py::test_builds_a_bad_goal[root]: Goal 'empty', feature 'x': expected lo <= hi" in text
    assert "During handling" not in text and "Traceback" not in text and "specguard/tree/" not in text


PASSING = """
@sg.goal_spec(expect={"stabilization": 0.0})
def test_a(pendulum, tree):
    return tiny(pendulum, tree)
"""


def test_a_report_destination_that_cannot_be_written_is_a_warning_and_the_outcome_is_kept(pytester):
    write(pytester, PASSING)
    afile = pytester.path / "afile"
    afile.write_text("not a folder")
    for destination, reason in [(afile, "File exists"), (afile / "sub", "Not a directory")]:
        result = run(pytester, "--goal-specs", f"--goal-specs-report={destination}")
        assert result.ret == 0, result.stdout.str()
        result.assert_outcomes(passed=1)
        result.stdout.fnmatch_lines(
            [f"specguard: warning: the report was not written to '{destination}': *{reason}*", "*= 1 passed in *"]
        )
        assert "Traceback" not in result.stdout.str() + result.stderr.str()
    assert afile.read_text() == "not a folder"


def test_a_baseline_that_cannot_be_saved_is_a_warning_and_the_outcome_is_kept(pytester):
    write(pytester, PASSING)
    afile = pytester.path / "afile"
    afile.write_text("not a folder")
    report = pytester.path / "report"
    result = run(
        pytester,
        "--goal-specs",
        "--goal-specs-save=main",
        f"--goal-specs-baseline-dir={afile}",
        "--goal-specs-compare-seeds=1",
        f"--goal-specs-report={report}",
    )
    assert result.ret == 0, result.stdout.str()
    result.assert_outcomes(passed=1)
    result.stdout.fnmatch_lines(
        [f"specguard: warning: baseline 'main' was not saved to '{afile / 'main.json'}': *", "*= 1 passed in *"]
    )
    assert (report / "goal-specs.json").is_file()  # the other output is still written


def test_a_subset_save_keeps_the_other_specs_and_says_what_it_replaced(pytester):
    write(pytester, PASSING + PASSING.replace("test_a", "test_b"))
    opts = ["--goal-specs", "--goal-specs-save=main", "--goal-specs-compare-seeds=1"]
    path = pytester.path / "baselines" / "main.json"
    full = run(pytester, *opts)
    full.assert_outcomes(passed=2)
    full.stdout.fnmatch_lines(
        [f"specguard: wrote baseline {path}: replaced none, added 2 specs (test_specs.py::test_a, *test_b), kept none"]
    )
    subset = run(pytester, *opts, "-k", "test_b")
    subset.assert_outcomes(passed=1)
    subset.stdout.fnmatch_lines(
        [f"specguard: wrote baseline {path}: replaced 1 spec (test_specs.py::test_b), added none, kept 1 other"]
    )
    stored = json.loads(path.read_text())["goals"]
    assert sorted(stored) == [f"test_specs.py::test_{x}::pendulum/stabilization" for x in "ab"]


FALLS = """
import gymnasium as gym
import numpy as np


class Hopper(gym.Env):
    # Tall (x = 1) at every state, and the env ends each episode at step 3: a fall the goal does not see.
    observation_space = gym.spaces.Box(-2.0, 2.0, (1,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return np.ones(1, np.float32), {}

    def step(self, action):
        self.t += 1
        return np.ones(1, np.float32), 0.0, self.t >= 3, False, {}


@sg.goal_spec(expect=0.5)
def test_stay_tall():
    initial = sg.InitialEnv(lambda: gym.wrappers.TimeLimit(Hopper(), 10), features=("z",))
    tree = sg.Always(sg.Goal("tall", z=(0.5, None)), name="stay")
    budget = sg.Budget(timesteps=64, min_seeds=1, eval_episodes=4)
    return sg.Spec(initial, tree, budget=budget, trainer=sg.SB3(hyperparameters=TINY))
"""


def test_the_table_and_the_failure_say_how_many_episodes_the_env_ended_before_the_horizon(pytester):
    # The facts `specguard run` prints under its table (SpecResult.notes) show at this door too.
    write(pytester, FALLS)
    result = run(pytester, "--goal-specs", "--goal-specs-no-cache")
    result.assert_outcomes(failed=1)  # tall at every state, and fallen: not kept (it passed every episode before)
    text = result.stdout.str()
    episodes = int(text.split("per seed: seed 0: 0/")[1].split(" ")[0])
    note = f"{episodes} of {episodes} evaluation episodes were ended by termination before their horizon*"
    result.stdout.fnmatch_lines([f"*{note}", "*hint: the env ended every evaluation episode before the horizon*"])
    result.stdout.fnmatch_lines(
        ["*= specguard goal specs =*", "*stay*0% (0/*failed*", f"test_specs.py::test_stay_tall: {note}"]
    )
