"""Judging one goal of a SpecResult, without pytest."""

from __future__ import annotations

import pytest

import specguard as sg
from example_specs import pendulum
from specguard.engine.judging import judged
from specguard.gate.baseline import Baseline
from specguard.pytest_plugin.judge import judge_goal
from specguard.stats.intervals import success_interval
from specguard.stats.verdicts import GoalOutcome
from specguard.training.result import RunResult
from specguard.tree.keys import ROOT
from specguard.utils.text import interval_text


def result_of(spec, per_seed, errors=None):
    runs = [
        RunResult(
            spec=spec.label,
            seed=i,
            timesteps=10,
            episodes=n,
            successes={p: k for p, _ in spec.tree.walk()},
            train_seconds=1.0,
        )
        for i, (k, n) in enumerate(per_seed)
    ]
    return judged(spec, runs, errors=errors)  # the judge every door uses: verdicts, notes and hints


def spec(tree="b", expect=None, **budget):
    return sg.Spec(
        pendulum.initial_env,
        pendulum.trees[tree],
        budget=sg.Budget(timesteps=10, **budget),
        expect=expect or {"pendulum": 0.8},
    )


def test_passed():
    s = spec()
    check = judge_goal(result_of(s, [(30, 30), (30, 30)]), s, "pendulum", "g")
    assert check.outcome == "passed" and check.hint is None
    assert check.message().startswith("goal 'pendulum' of spec 'pendulum' met its threshold")


def test_failed_sparse_goal_hints_at_a_distance():
    s = spec()
    check = judge_goal(result_of(s, [(0, 30), (30, 30)]), s, "pendulum", "g")
    assert check.outcome == "failed"
    assert check.hint == "sparse goal never reached in 1/2 seeds: consider a Distance annotation on 'pendulum'"
    assert "per seed: seed 0: 0/30 (missed), seed 1: 30/30 (met)" in check.message()


def test_shaped_goal_gets_another_hint():
    s = spec("c", expect={"position": 0.8})
    check = judge_goal(result_of(s, [(0, 30), (30, 30)]), s, "pendulum/position", "g")
    assert check.hint.startswith("goal never reached in 1/2 seeds")


def test_undecided_runs_leave_the_goal_undecided():
    s = spec(max_eval_episodes=30)
    check = judge_goal(result_of(s, [(25, 30), (30, 30)]), s, "pendulum", "g")
    assert check.outcome is GoalOutcome.UNDECIDED
    assert "could not be decided" in check.message()
    assert check.hint.startswith("runs stayed undecided after 30 evaluation episodes")
    # The interval the verdict used, not the table's 95% one: seed 0's, at the corrected confidence.
    lo, hi = success_interval(25, 30, s.verdict_confidence)
    assert lo < s.thresholds["pendulum"] < hi
    assert f"these intervals contain the threshold 0.8: seed 0 {interval_text((lo, hi))}" in check.hint
    assert "seed 1" not in check.hint  # 30/30 met


def test_crashed_seeds_fail_and_are_listed():
    s = spec()
    check = judge_goal(result_of(s, [(30, 30)], errors={1: "seed 1 exploded"}), s, "pendulum", "g")
    assert check.outcome == "failed" and check.runs == 2
    assert "seed 1 failed: seed 1 exploded" in check.message()
    assert check.to_row()["errors"] == {"1": "seed 1 exploded"}


def test_competing_subgoals_hint_at_weights():
    s = spec()
    runs = [
        RunResult(
            spec="pendulum",
            seed=i,
            timesteps=10,
            episodes=30,
            train_seconds=1.0,
            successes={"pendulum": 10, "pendulum/position": 10, "pendulum/stabilization": 30},
        )
        for i in range(2)
    ]
    result = judged(s, runs)
    check = judge_goal(result, s, "pendulum", "g")
    assert check.hint == (
        "subgoals compete: 'pendulum/stabilization' is reached in 100% of episodes, 'pendulum/position' in 33%; "
        "consider a Distance on 'pendulum/position' or a larger weight for it"
    )


def test_with_thresholds_resolves_decorator_goals():
    from specguard.pytest_plugin.judge import with_thresholds

    s, paths = with_thresholds(spec(), {ROOT: 0.5, "position": 0.7}, "position")
    assert s.thresholds == {"pendulum": 0.5, "pendulum/position": 0.7} and paths == ["pendulum/position"]
    assert with_thresholds(spec(), None, None)[1] == ["pendulum"]
    with pytest.raises(
        sg.error.InvalidSpec, match=r"expected at least one threshold, got \{\}: there is nothing to assert"
    ):
        with_thresholds(sg.Spec(pendulum.initial_env, pendulum.trees["b"], budget=sg.Budget(10)), None, None)


def test_check_item_fails_a_passing_goal_that_dropped_against_the_baseline():
    from specguard.pytest_plugin.judge import check_item

    s = spec(expect={"pendulum": 0.3}, max_seeds=4)
    result = result_of(s, [(20, 30), (21, 30), (19, 30), (22, 30)])
    key = "g::pendulum"
    dropped = check_item(result, s, ["pendulum"], "g", baseline=(Baseline({key: [(30, 30)] * 8}, {}), "main"))[0]
    assert dropped.outcome == "failed"
    assert dropped.hint.startswith("success dropped: 100% -> 68% (p = 0.002 <= 0.05; 4 seeds vs 8 in the baseline)")
    assert dropped.hint.endswith("against baseline 'main'")
    assert dropped.gate["state"] == "dropped" and dropped.gate["seeds"] == [0, 1, 2, 3]
    # Two seeds against two cannot show a drop at 5% (every split of 4 seeds is 1 in 6): undecided, not failed.
    two = spec(expect={"pendulum": 0.3})
    few = result_of(two, [(20, 30), (21, 30)])
    open_ = check_item(few, two, ["pendulum"], "g", baseline=(Baseline({key: [(30, 30)] * 2}, {}), "main"))[0]
    assert open_.outcome == "passed" and open_.comparison.startswith("undecided: 100% -> 68% (p = 0.17 > 0.05")
    like = Baseline({key: [(20, 30), (21, 30)] * 4}, {})
    same = check_item(result, s, ["pendulum"], "g", baseline=(like, "main"))[0]
    assert same.outcome == "passed"
    assert same.comparison.startswith("unchanged within chance: 68% -> 68% (a drop of 12 points at most, under the")
    assert "spec changed" not in same.comparison
    result.spec_key = "new"
    changed = Baseline({key: [(20, 30), (21, 30)]}, {key: "old"})
    moved = check_item(result, s, ["pendulum"], "g", baseline=(changed, "main"))[0]
    assert moved.comparison.endswith("(the spec changed since baseline 'main')")
    assert dict(same.junit_properties())["interval"].startswith("[0.")


def test_a_spec_whose_identity_and_runs_are_the_baselines_own_is_not_compared():
    from specguard.pytest_plugin.judge import check_item

    s = spec(expect={"pendulum": 0.3})
    result = result_of(s, [(20, 30), (21, 30)])
    result.spec_key = "same"
    key = "g::pendulum"
    own = Baseline({key: [(20, 30), (21, 30), (25, 30)]}, {key: "same"}, {key: [0, 1, 2]})
    check = check_item(result, s, ["pendulum"], "g", baseline=(own, "main"))[0]
    assert check.comparison == "unchanged: the same spec and runs as baseline 'main' (seeds 0, 1); not compared"
    assert check.gate is None and check.outcome == "passed"
    other = Baseline({key: [(20, 30), (22, 30)]}, {key: "same"}, {key: [0, 1]})  # same identity, another result
    assert check_item(result, s, ["pendulum"], "g", baseline=(other, "main"))[0].gate is not None


def test_never_reached_suggests_a_distance_only_for_a_reachable_goal():
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    budget = sg.Budget(timesteps=10)
    inside = sg.Spec(cartpole, sg.Goal("edge_zone", x=(4.0, 4.5)), budget=budget, expect=0.5)
    from specguard.error import UnreachableGoal

    with pytest.raises(UnreachableGoal):  # an impossible goal never reaches training ...
        sg.make_env(cartpole, sg.Goal("far", x=(10, None)))
    hint = judge_goal(result_of(inside, [(0, 30), (0, 30)]), inside, "edge_zone", "g").hint
    assert hint == "sparse goal never reached in 2/2 seeds: consider a Distance annotation on 'edge_zone'"
    # ... and should a result for one arrive (an old cache), the hint says impossible, not "add a Distance".
    far = sg.Spec(cartpole, sg.Goal("far", x=(10, None)), budget=budget, expect=0.5)
    hint = judge_goal(result_of(far, [(0, 30), (0, 30)]), far, "far", "g").hint
    assert hint.startswith("goal impossible, not just never reached: goal box x in [10, inf] lies outside")
    assert "Distance" not in hint


# -- safety rates ---------------------------------------------------------------------------------------------

FAST = sg.Constraint(lambda s, a: abs(s.omega) > 7.5, name="fast")


def safety_spec(expect, **budget):
    tree = sg.All(*pendulum.trees["b"].children, name="pendulum").annotate(FAST)
    return sg.Spec(pendulum.initial_env, tree, budget=sg.Budget(timesteps=10, **budget), expect=expect)


def safety_result(spec, safe_per_seed, episodes=30):
    runs = [
        RunResult(
            spec=spec.label,
            seed=i,
            timesteps=10,
            episodes=episodes,
            successes={**{p: episodes for p, _ in spec.tree.walk()}, "pendulum:fast": k},
            train_seconds=1.0,
        )
        for i, k in enumerate(safe_per_seed)
    ]
    return judged(spec, runs)


def test_a_missed_safety_threshold_speaks_of_violations():
    s = safety_spec({"fast": 0.8})
    check = judge_goal(safety_result(s, [0, 10]), s, "pendulum:fast", "g")
    assert check.outcome == "failed" and check.kind == "safety"
    assert check.hint == (
        "'pendulum:fast' was violated in 83% of evaluation episodes; in every episode of 1/2 seeds (an episode with "
        "any violation counts as unsafe, whatever the annotation's budget): consider a larger weight for its "
        "penalty, or a larger training budget"
    )
    message = check.message()
    assert message.startswith("safety rate 'pendulum:fast' of spec 'pendulum' missed its threshold\n")
    assert "  safe (no violation) in 17% (10/60), interval [0.08, 0.29], threshold >= 0.8" in message
    assert "per seed: seed 0: 0/30 (missed), seed 1: 10/30 (missed)" in message
    assert check.to_row()["kind"] == "safety"
    assert dict(check.junit_properties())["kind"] == "safety"


def test_a_passing_or_undecided_safety_rate():
    s = safety_spec({"pendulum:fast": 0.8, "pendulum": 0.5}, max_eval_episodes=30)
    passed = judge_goal(safety_result(s, [30, 30]), s, "pendulum:fast", "g")
    assert passed.outcome == "passed" and passed.hint is None
    assert passed.message().startswith("safety rate 'pendulum:fast' of spec 'pendulum' met its threshold")
    undecided = judge_goal(safety_result(s, [26, 30]), s, "pendulum:fast", "g")
    assert undecided.outcome is GoalOutcome.UNDECIDED
    assert undecided.hint.startswith("runs stayed undecided after 30 evaluation episodes")
    goal = judge_goal(safety_result(s, [30, 30]), s, "pendulum", "g")
    assert goal.kind == "goal" and dict(goal.junit_properties())["kind"] == "goal"


def test_old_baselines_without_a_safety_rate_are_noted_not_compared():
    from specguard.pytest_plugin.judge import check_item

    s = safety_spec({"pendulum": 0.3, "fast": 0.3})
    result = safety_result(s, [20, 21])
    old = Baseline({"g::pendulum": [(30, 30), (30, 30)]}, {})  # stored before safety rates were measured
    goal, safety = check_item(result, s, ["pendulum", "pendulum:fast"], "g", baseline=(old, "main"))
    assert goal.comparison.startswith("unchanged within chance")
    assert safety.outcome == "passed" and safety.comparison == "not compared: baseline 'main' has no figures for it"
    s = safety_spec({"pendulum": 0.3, "fast": 0.3}, max_seeds=4)
    result = safety_result(s, [20, 21, 19, 22])
    dropped = Baseline({"g::pendulum:fast": [(30, 30)] * 8}, {})
    safety = check_item(result, s, ["pendulum:fast"], "g", baseline=(dropped, "main"))[0]
    assert safety.outcome == "failed"
    assert safety.hint.startswith("safety rate dropped: 100% -> 68%") and safety.hint.endswith("baseline 'main'")


def compared_row(goal, p_drop, state="open", verdict="passed", seeds=(0, 1, 2, 3)):
    return {
        "group": "f.py::test",
        "goal": goal,
        "verdict": verdict,
        "per_seed": [{"seed": 0}, {"seed": 1}],
        "comparison": f"undecided: ({goal})",
        "gate": {"p_drop": p_drop, "state": state, "level": 0.05 / 3, "seeds": list(seeds)},
    }


def test_holm_over_the_session_flags_what_the_items_first_step_could_not():
    from specguard.pytest_plugin.recorder import apply_family
    from specguard.report.session_report import family_lines

    rows = [
        compared_row("a", 0.001, state="dropped", verdict="failed"),
        compared_row("b", 0.02),
        compared_row("c", 0.5),
    ]
    assert apply_family(rows)  # b: 0.02 <= 0.05 / 2 at Holm's second step, though above the first step's 0.0167
    assert rows[1]["verdict"] == "failed" and rows[1]["comparison"].startswith("dropped by Holm's step 2 (p = 0.02 <=")
    assert [r["gate"]["holm"] for r in rows] == [1, 2, None] and rows[2]["verdict"] == "passed"
    assert family_lines(rows) == [
        "Holm's step-down procedure over 3 comparisons at family-wise 5%; each comparison was judged at 0.017 while "
        "its seeds trained (Holm's first step over the 3 goals and safety rates of the baseline)",
        "dropped: f.py::test::a, f.py::test::b",
        "seeds compared per spec: f.py::test 4 (2 beyond the specs' own)",
    ]


def test_holm_leaves_expected_misses_and_a_quiet_session_alone():
    from specguard.pytest_plugin.recorder import apply_family
    from specguard.report.session_report import family_lines

    xfailed = [compared_row("a", 0.001, verdict="xfailed")]
    assert not apply_family(xfailed) and xfailed[0]["verdict"] == "xfailed"
    quiet = [compared_row("a", 0.4), compared_row("b", 0.9)]
    assert not apply_family(quiet) and family_lines(quiet)[1] == "dropped: none"
    assert not apply_family([{"group": "g", "goal": "x", "verdict": "passed"}]) and family_lines([]) == []


@pytest.mark.parametrize(
    "tree, goal",
    [
        (sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance"), "balance"),  # the env ends it: a fall
        (sg.Goal("far", x=(2.0, None)), "far"),  # never reached
    ],
)
def test_an_agents_failing_goal_hints_at_its_behaviour_not_at_training(tree, goal):
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    s = sg.Spec(cartpole, tree, budget=sg.Budget(timesteps=1), expect=0.5)

    def lean(obs):
        return int(obs[2] > 0)

    result = sg.check_agent(s, lean, episodes=10, max_episodes=10, cache_dir=None)
    check = judge_goal(result, s, goal, "g")
    assert check.outcome == "failed" and check.hint is not None
    assert "agent 'lean'" in check.hint
    for training in ("learn", "train", "Distance", "budget", "weight"):
        assert training not in check.hint, check.hint
