"""What a gate can see: `specguard plan` on every example spec, `pytest --goal-specs-plan`, and the plan's figures."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

import specguard as sg
from example_specs import lunar_lander, pendulum
from specguard.cli.main import main
from specguard.gate.plan import plan_spec
from specguard.report.plan_lines import plan_lines
from specguard.stats.power import chance_met

EXAMPLES = Path(__file__).resolve().parents[1] / "example_specs"
SPEC_FILES = ["pendulum", "acrobot", "mountain_car", "lunar_lander", "cartpole", "weights"]


def test_a_plan_judges_each_threshold_around_it_and_the_drops_a_comparison_sees():
    plan = plan_spec(pendulum.specs["w"], family=15)
    root = plan.goals[0]
    assert root.path == "pendulum" and list(root.met) == [0.7, 0.75, 0.8, 0.85, 0.9, 0.95]
    spec = pendulum.specs["w"]
    stages = spec.budget.evaluation_stages
    assert root.met[0.9] == chance_met(0.9, threshold=0.8, stages=stages, confidence=spec.verdict_confidence)
    assert root.passed[0.9] == pytest.approx(root.met[0.9] ** 2)  # both seeds must meet it
    assert root.met[0.8] < 0.025  # at the threshold itself, a run is called met at most (1 - 0.95) / 2 of the time
    assert plan.level == pytest.approx(0.05 / 15) and plan.ceiling == 8 and plan.baseline_seeds["pendulum"] == 8
    assert root.at_start is None  # 2 seeds against 8 cannot reach 0.0033: extra seeds are the only way
    assert root.with_extra is not None and 0.15 < root.with_extra < 0.3
    assert not root.estimated and root.success == 0.9 and root.spread == 0.05


def test_a_baseline_gives_the_success_and_spread_of_its_seeds():
    runs = [(30, 30), (29, 30), (30, 30), (30, 30), (28, 30), (30, 30), (29, 30), (30, 30)]
    plan = plan_spec(pendulum.specs["w"], family=15, baseline={"pendulum": runs})
    root, position = plan.goals
    assert root.estimated and root.success == pytest.approx(236 / 240) and root.spread < 0.02
    assert root.with_extra is not None and root.with_extra < position.with_extra  # near 100%, with no spread
    assert not position.estimated and plan.baseline_seeds == {"pendulum": 8, "pendulum/position": 8}


def test_a_comparison_that_cannot_see_a_20_point_drop_says_so():
    plan = plan_spec(lunar_lander.specs["w"], family=15, spread=0.15)
    (lander,) = plan.goals
    assert lander.blind
    text = "\n".join(plan_lines(plan))
    assert "cannot detect a 20-point drop" in text
    assert "  lander  >= 0.05    -       0.00: 0% (0%)" in text  # no success below 0


@pytest.mark.parametrize("name", SPEC_FILES)
def test_specguard_plan_works_on_every_example_spec(name, capsys):
    assert main(["plan", str(EXAMPLES / f"{name}.py")]) == 0
    out = capsys.readouterr().out
    assert out.count("== ") >= 1 and "drop seen (80% power), 2 seeds" in out
    assert all(line == line.rstrip() for line in out.splitlines())


def test_specguard_plan_options(capsys):
    assert main(["plan", f"{EXAMPLES / 'pendulum.py'}::w", "--spread", "0.15", "--comparisons", "1"]) == 0
    out = capsys.readouterr().out
    assert "each judged at 0.05 (5% over 1 comparison, Holm" in out and "spread 0.15 (assumed)" in out
    with pytest.raises(SystemExit):
        main(["plan", str(EXAMPLES / "pendulum.py"), "--spread", "0.7"])
    assert "expected a standard deviation of success below 0.5, got '0.7'" in capsys.readouterr().err


def test_a_spec_without_thresholds_has_nothing_to_plan(tmp_path, capsys):
    path = tmp_path / "bare.py"
    path.write_text(
        "import specguard as sg\n"
        "env = sg.InitialEnv('CartPole-v1', features=('x', 'v', 'theta', 'omega'))\n"
        "bare = sg.Spec(env, sg.Goal('right', x=(0.5, 1.5)), budget=sg.Budget(timesteps=10))\n"
    )
    assert main(["plan", str(path)]) == 0
    assert capsys.readouterr().out.startswith("== bare: no thresholds, nothing to judge or compare")


PYTEST_SPECS = """
import pytest
import specguard as sg


@sg.goal_spec(expect={"balance": 0.8, "right": 0.9})
def test_balance():
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    tree = sg.All(sg.Goal("right", x=(0.5, 1.5)), sg.Goal("upright", theta=(-0.05, 0.05)), name="balance")
    return sg.Spec(cartpole, tree, budget=sg.Budget(timesteps=512))
"""


OWN_THRESHOLDS = """
import specguard as sg


@sg.goal_spec(falsify=True)
def test_balance():
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    tree = sg.All(sg.Goal("right", x=(0.5, 1.5)), sg.Goal("upright", theta=(-0.05, 0.05)), name="balance")
    expect = {"balance": 0.8, "right": 0.9, "upright": 0.9}
    return sg.Spec(cartpole, tree, expect=expect, budget=sg.Budget(timesteps=512))
"""


def test_goal_specs_plan_counts_the_thresholds_of_an_item_asserting_a_whole_spec_and_no_falsify_item(pytester):
    pytester.makepyfile(test_plan_specs=OWN_THRESHOLDS)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--goal-specs", "--goal-specs-plan")
    result.assert_outcomes(skipped=2)  # [spec] and [falsify]
    assert "each judged at 0.017 (5% over 3 comparisons, Holm's first step)" in result.stdout.str()


def test_goal_specs_plan_prints_each_spec_once_and_trains_nothing(pytester):
    pytester.makepyfile(test_plan_specs=PYTEST_SPECS)
    cache = pytester.path / "cache"
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", f"--goal-specs-cache-dir={cache}", "--goal-specs", "--goal-specs-plan"
    )
    result.assert_outcomes(skipped=2)
    out = result.stdout.str()
    assert out.count("== test_plan_specs.py::test_balance: 2 seeds") == 1
    assert "each judged at 0.025 (5% over 2 comparisons, Holm's first step)" in out  # two goal items collected
    assert not cache.exists()
    # With a baseline, its seeds give the success and the spread, and its size the family.
    baselines = pytester.path / "baselines"
    baselines.mkdir()
    key = "test_plan_specs.py::test_balance::balance"
    goals = {
        key: {"runs": [[30, 30], [20, 30], [29, 30]], "spec": None, "seeds": [0, 1, 2]},
        "other::g": {"runs": [[1, 2]], "spec": None},
        "third::g": {"runs": [[1, 2]], "spec": None},
    }
    (baselines / "main.json").write_text(json.dumps({"format": 3, "goals": goals}))
    result = pytester.runpytest_subprocess(
        "-p",
        "no:cacheprovider",
        "--goal-specs",
        "--goal-specs-plan",
        f"--goal-specs-baseline-dir={baselines}",
        "--goal-specs-compare",
        "main",
    )
    out = result.stdout.str()
    assert "each judged at 0.017 (5% over 3 comparisons" in out
    assert "3 seeds at 88%, spread 0.18 (from its 3 seeds)" in out


def test_specguard_plan_on_a_pytest_goal_spec_file(pytester):
    path = pytester.makepyfile(test_plan_specs=PYTEST_SPECS)
    result = pytester.run(sys.executable, "-m", "specguard", "plan", str(path))
    assert result.ret == 0, result.stdout.str() + result.stderr.str()
    assert "== test_plan_specs.py::test_balance: 2 seeds" in result.stdout.str()


def test_the_case_studies_file_is_a_goal_spec_file():
    from specguard.report.show import has_goal_specs

    assert has_goal_specs(EXAMPLES / "test_case_studies.py") and not has_goal_specs(EXAMPLES / "pendulum.py")
    assert sg.goal_specs  # what the file calls
