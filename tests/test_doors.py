"""One spec, one verdict: ``run_spec``, ``specguard run`` and ``pytest --goal-specs`` judge a spec the same way.

Each door trains the same small spec afresh (a cache of its own), by the
spec's own budget: the same seeds, the same steps trained (anytime verdicts
at the one default of checkpoints), the same evaluation figures, the same
verdict per goal.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest

import specguard as sg
from specguard.cli.main import main
from specguard.engine.specfiles import load_objects

SPEC_FILE = """
import specguard as sg

pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
tree = sg.All(
    sg.Goal("anywhere", x=(-1.0, 1.0)),  # every state: met at the first checkpoint
    sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)),
    name="pendulum",
)
spec = sg.Spec(
    pendulum,
    tree,
    budget=sg.Budget(timesteps=640, min_seeds=2, eval_episodes=10),
    hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1},
    expect={"anywhere": 0.3},
)
"""


Figures = dict[str, tuple[list[tuple[int, int, int, int]], bool]]  # goal -> per seed (seed, steps, k, n), passed


def by_goal(runs: list[dict], verdicts: dict[str, bool]) -> Figures:
    """Per goal: each seed's (seed, steps trained, successes, episodes), and whether the goal passed."""
    return {
        goal: ([(r["seed"], r["timesteps"], r["successes"][goal], r["episodes"]) for r in runs], passed)
        for goal, passed in verdicts.items()
    }


@pytest.fixture(scope="module")
def spec_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("doors") / "door_spec.py"
    path.write_text(textwrap.dedent(SPEC_FILE))
    return path


def test_every_door_gives_the_same_figures_and_verdicts(spec_file: Path, tmp_path: Path, pytester: pytest.Pytester):
    spec = load_objects(f"{spec_file}::spec")["spec"]
    assert spec.budget.checkpoints > 1  # the one default: anytime verdicts, at every door

    # run_spec, the API.
    result = sg.run_spec(spec, workers=2, cache_dir=tmp_path / "api", progress=None)
    api = by_goal(
        [r.to_dict() for r in result.runs], {goal: v.verdict.value == "passed" for goal, v in result.goals.items()}
    )

    # specguard run, the CLI.
    out = tmp_path / "cli.json"
    argv = ["run", f"{spec_file}::spec", "--workers", "2", "--cache-dir", str(tmp_path / "cli"), "--quiet"]
    code = main([*argv, "--json", str(out)])
    data = json.loads(out.read_text())["spec"]
    cli = by_goal(data["runs"], {goal: g["verdict"] == "passed" for goal, g in data["goals"].items()})

    # pytest --goal-specs, the plugin: one item per goal, its figures in the report.
    pytester.makepyfile(door_spec=spec_file.read_text())
    pytester.makepyfile(
        test_door="import specguard as sg\nfrom door_spec import spec\n\ntest_door = sg.goal_specs({'s': spec})\n"
    )
    report = tmp_path / "report"
    outcome = pytester.runpytest_subprocess(
        "-p",
        "no:cacheprovider",
        "--goal-specs",
        "--goal-specs-workers=2",
        f"--goal-specs-cache-dir={tmp_path / 'plugin'}",
        f"--goal-specs-report={report}",
    )
    rows = json.loads((report / "goal-specs.json").read_text())["goals"]
    plugin = {
        row["goal"]: (
            [(s["seed"], s["timesteps"], s["successes"], s["episodes"]) for s in row["per_seed"]],
            row["outcome"] == "passed",
        )
        for row in rows
    }

    assert api == cli == plugin, (api, cli, plugin)
    # Judged at checkpoints, as every door does by default: met at the first one, training stopped there.
    assert all(steps < spec.budget.timesteps for figures, _ in api.values() for _, steps, _, _ in figures)
    assert code == (0 if result.passed else 1)
    passed = sum(1 for _, ok in api.values() if ok)
    outcome.assert_outcomes(passed=passed, failed=len(api) - passed)
