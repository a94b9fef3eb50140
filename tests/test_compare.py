"""Baselines and the two-sample comparison."""

from __future__ import annotations

import pytest

from specguard.stats.compare import Baseline, BaselineError, compare, load_baseline, save_baseline


def test_clear_drop_across_seeds():
    c = compare([(29, 30), (30, 30), (28, 30)], [(10, 30), (12, 30), (9, 30)])
    assert c.dropped and not c.improved
    assert c.method.startswith("Welch t-test over 3 vs 3 seeds")
    assert c.describe().startswith("dropped: 97% -> 34%")


def test_noise_is_not_a_drop():
    c = compare([(20, 30), (25, 30)], [(24, 30), (19, 30)])
    assert not c.dropped and not c.improved
    assert "unchanged within chance" in c.describe()


def test_identical_seeds_fall_back_to_fisher():
    c = compare([(30, 30), (30, 30)], [(0, 30), (0, 30)])
    assert c.dropped and c.method == "Fisher exact test over 60 vs 60 episodes"
    assert compare([(0, 30)], [(30, 30)]).improved


def test_needs_runs():
    with pytest.raises(ValueError):
        compare([], [(1, 2)])


def test_save_and_load_round_trip(tmp_path):
    path = tmp_path / "b" / "main.json"
    save_baseline(path, {"f.py::test::goal": [(3, 4), (4, 4)]}, {"f.py::test::goal": "abc"})
    baseline = load_baseline(path)
    assert baseline.runs == {"f.py::test::goal": [(3, 4), (4, 4)]}
    assert baseline.spec_changed("f.py::test::goal", "abd") and not baseline.spec_changed("f.py::test::goal", "abc")
    assert not baseline.spec_changed("other", "abc")


def test_format_1_baselines_still_load(tmp_path):
    path = tmp_path / "old.json"
    path.write_text('{"format": 1, "goals": {"k": [[3, 4]]}}')
    assert load_baseline(path) == Baseline({"k": [(3, 4)]}, {})


@pytest.mark.parametrize(
    "content",
    [
        "{oops",
        '{"format": 3, "goals": {}}',
        '{"format": 2, "goals": {"k": {"runs": [[1, 2]], "spec": 5}}}',
        '{"format": 1, "goals": {"k": [[5, 4]]}}',
        '{"format": 1, "goals": {"k": "x"}}',
    ],
)
def test_corrupt_baselines_name_the_file(tmp_path, content):
    path = tmp_path / "main.json"
    path.write_text(content)
    with pytest.raises(BaselineError, match=r"baseline '.*main.json' is corrupt"):
        load_baseline(path)


def test_missing_baseline(tmp_path):
    with pytest.raises(BaselineError, match="does not exist; store one first with --goal-specs-save"):
        load_baseline(tmp_path / "none.json")


def test_safety_rates_round_trip_and_old_baselines_without_them_are_noted(tmp_path):
    import specguard as sg
    from example_specs import pendulum
    from specguard.engine.judging import judge as _judge
    from specguard.engine.results import RunResult
    from specguard.engine.spec_result import SpecResult
    from specguard.pytest_plugin.gate import check_item

    old = tmp_path / "old.json"  # saved before safety rates were measured: goals only
    old.write_text('{"format": 2, "goals": {"g::pendulum": {"runs": [[30, 30], [29, 30]], "spec": null}}}')
    new = tmp_path / "new.json"
    save_baseline(new, {"g::pendulum": [(30, 30)], "g::pendulum:fast": [(28, 30), (30, 30)]})
    assert load_baseline(new).runs["g::pendulum:fast"] == [(28, 30), (30, 30)]

    fast = sg.Constraint(lambda s, a: abs(s.omega) > 7.5, name="fast")
    tree = sg.All(*pendulum.trees["b"].children, name="pendulum").annotate(fast)
    spec = sg.Spec(pendulum.initial_env, tree, budget=sg.Budget(10), expect={"pendulum": 0.5, "fast": 0.5})
    counts = {"pendulum": 30, "pendulum/position": 30, "pendulum/stabilization": 30, "pendulum:fast": 29}
    runs = [
        RunResult(spec="pendulum", seed=i, timesteps=10, episodes=30, successes=counts, train_seconds=1.0)
        for i in (0, 1)
    ]
    result = SpecResult(spec="pendulum", runs=runs, goals=_judge(spec, runs, 0))
    paths = ["pendulum", "pendulum:fast"]
    goal, safety = check_item(result, spec, paths, "g", baseline=(load_baseline(old), "old"))
    assert goal.comparison.startswith("unchanged within chance")
    assert safety.comparison == "not compared: baseline 'old' has no figures for it" and safety.outcome == "passed"
    _, safety = check_item(result, spec, paths, "g", baseline=(load_baseline(new), "new"))
    assert safety.comparison.startswith("unchanged within chance: 97% -> 97%")
