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

# Imported before any test: pytester's fixture drops the modules a test imported when it ends, and these
# (numpy's C extensions under scipy.stats, the engine's pickled functions) cannot be imported twice.
import scipy.stats  # noqa: F401
from bad_modules import CASES, write_bad_modules

import specguard as sg
import specguard.cache.versions
import specguard.engine.run_spec
import specguard.engine.worker_task
from specguard.cli.main import main
from specguard.spec.loading import load_objects
from specguard.stats.verdicts import GoalOutcome

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
    trainer=sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1}),
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
    # The same weights judged at every door: each seed's digest, in the API's runs, the CLI's JSON, the plugin's rows.
    digests = [r.weights_digest for r in result.runs]
    assert all(digests) and len(set(digests)) == len(digests)
    assert [r["weights_digest"] for r in data["runs"]] == digests
    assert all([s["weights_digest"] for s in row["per_seed"]] == digests for row in rows), rows
    # each seed's own training time (the main job's benchmark sums each spec's slower seed)
    assert all(s["train_seconds"] > 0 for row in rows for s in row["per_seed"]), rows
    # Judged at checkpoints, as every door does by default: met at the first one, training stopped there.
    assert all(steps < spec.budget.timesteps for figures, _ in api.values() for _, steps, _, _ in figures)
    assert code == (0 if result.passed else 1)
    passed = sum(1 for _, ok in api.values() if ok)
    outcome.assert_outcomes(passed=passed, failed=len(api) - passed)


UNDECIDED_FILE = """
import specguard as sg

pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
tree = sg.All(sg.Goal("anywhere", x=(-1.0, 1.0)), sg.Goal("position", x=(0.966, 1.0)), name="pendulum")
# Two evaluation episodes never place a run's interval on one side of 0.5: the goal stays undecided.
budget = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=2, max_eval_episodes=2)
spec = sg.Spec(
    pendulum,
    tree,
    budget=budget,
    trainer=sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1}),
    expect={"anywhere": 0.5},
    undecided=UNDECIDED,
)
tiny = sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1})
measured = sg.Spec(pendulum, tree, budget=budget, trainer=tiny)
"""

# What an undecided goal counts as: exit status of `specguard run`, pytest outcome.
COUNTS_AS = {"fail": (1, "failed"), "xfail": (0, "xfailed"), "pass": (0, "passed")}


@pytest.mark.parametrize("undecided", list(COUNTS_AS))
def test_every_door_counts_an_undecided_goal_as_the_spec_says(
    undecided: str, tmp_path: Path, pytester: pytest.Pytester
):
    source = textwrap.dedent(UNDECIDED_FILE).replace("UNDECIDED", repr(undecided))
    spec_file = tmp_path / "undecided_spec.py"
    spec_file.write_text(source)
    spec = load_objects(f"{spec_file}::spec")["spec"]

    result = sg.run_spec(spec, workers=1, cache_dir=tmp_path / "api", progress=None)
    assert result.outcome("pendulum/anywhere") is GoalOutcome.UNDECIDED
    assert result.counted("pendulum/anywhere") == COUNTS_AS[undecided][1]
    assert (result.passed, result.as_expected) == (undecided == "pass", undecided != "fail")

    argv = ["run", f"{spec_file}::spec", "--workers", "1", "--cache-dir", str(tmp_path / "cli"), "--quiet"]
    assert main(argv) == COUNTS_AS[undecided][0]

    pytester.makepyfile(undecided_spec=source)
    pytester.makepyfile(
        test_u="import specguard as sg\nfrom undecided_spec import spec\n\ntest_u = sg.goal_specs({'s': spec})\n"
    )
    run = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", "--goal-specs", "--goal-specs-workers=1", f"--goal-specs-cache-dir={tmp_path / 'p'}"
    )
    # Warnings: a passed undecided goal's, and (once, not again by the cache key's probes) the SpecWarning that the
    # root goal holds at 3 of the 32 seeded starts (Pendulum upright within 15 degrees).
    run.assert_outcomes(**{COUNTS_AS[undecided][1]: 1}, **({"warnings": 2} if undecided == "pass" else {}))


def test_the_doors_options_override_the_specs_undecided_the_same_way(tmp_path: Path, pytester: pytest.Pytester):
    source = textwrap.dedent(UNDECIDED_FILE).replace("UNDECIDED", repr("fail"))
    spec_file = tmp_path / "undecided_spec.py"
    spec_file.write_text(source)
    argv = ["run", f"{spec_file}::spec", "--workers", "1", "--cache-dir", str(tmp_path / "cli"), "--quiet"]
    assert main([*argv, "--undecided", "xfail"]) == 0

    pytester.makepyfile(undecided_spec=source)
    pytester.makepyfile(
        test_u="import specguard as sg\nfrom undecided_spec import spec\n\ntest_u = sg.goal_specs({'s': spec})\n"
    )
    run = pytester.runpytest_subprocess(
        "-p",
        "no:cacheprovider",
        "--goal-specs",
        "--goal-specs-workers=1",
        f"--goal-specs-cache-dir={tmp_path / 'p'}",
        "--goal-specs-undecided=xfail",
    )
    run.assert_outcomes(xfailed=1)


SPARSE_FILE = """
import specguard as sg

pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
# Upright and still within a hair: no episode of a policy trained 128 steps ends there, and nothing shapes it.
tree = sg.Goal("balanced", x=(0.9999, 1.0), y=(-0.01, 0.01), omega=(-0.01, 0.01))
spec = sg.Spec(
    pendulum,
    tree,
    budget=sg.Budget(timesteps=128, min_seeds=1, eval_episodes=4),
    trainer=sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1}),
    expect=0.9,
)
"""


def test_every_door_prints_the_same_hint_under_a_failed_goal(
    tmp_path: Path, pytester: pytest.Pytester, capsys: pytest.CaptureFixture[str]
):
    spec_file = tmp_path / "sparse_spec.py"
    spec_file.write_text(textwrap.dedent(SPARSE_FILE))
    spec = load_objects(f"{spec_file}::spec")["spec"]

    result = sg.run_spec(spec, workers=1, cache_dir=tmp_path / "api", progress=None)
    hint = result.hints["balanced"]
    assert hint.startswith("sparse goal never reached in 1/1 seeds"), hint

    out = tmp_path / "cli.json"
    argv = ["run", f"{spec_file}::spec", "--workers", "1", "--cache-dir", str(tmp_path / "cli"), "--quiet"]
    assert main([*argv, "--json", str(out)]) == 1
    assert f"hint for 'balanced': {hint}" in capsys.readouterr().out.splitlines()
    assert json.loads(out.read_text())["spec"]["hints"] == {"balanced": hint}

    pytester.makepyfile(sparse_spec=spec_file.read_text())
    pytester.makepyfile(
        test_sparse="import specguard as sg\nfrom sparse_spec import spec\n\ntest_sparse = sg.goal_specs({'s': spec})\n"
    )
    run = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", "--goal-specs", "--goal-specs-workers=1", f"--goal-specs-cache-dir={tmp_path / 'p'}"
    )
    run.assert_outcomes(failed=1)
    assert f"  hint: {hint}" in run.outlines


def test_a_spec_with_nothing_to_assert_is_refused_at_every_door_before_training(
    tmp_path: Path, pytester: pytest.Pytester, capsys: pytest.CaptureFixture[str]
):
    source = textwrap.dedent(UNDECIDED_FILE).replace("UNDECIDED", repr("fail"))
    spec_file = tmp_path / "undecided_spec.py"
    spec_file.write_text(source)
    cache = tmp_path / "cli"
    assert main(["run", f"{spec_file}::measured", "--workers", "1", "--cache-dir", str(cache), "--quiet"]) == 2
    assert "nothing to assert" in capsys.readouterr().err
    assert not cache.exists()  # refused before anything trained

    pytester.makepyfile(undecided_spec=source)
    test = "import specguard as sg\nfrom undecided_spec import measured\n\ntest_m = sg.goal_specs({'m': measured})\n"
    pytester.makepyfile(test_m=test)
    run = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--goal-specs", "--goal-specs-workers=1")
    assert run.ret != 0
    run.stdout.fnmatch_lines(["*nothing to assert*"])


BAD_IMPORT = """
import specguard as sg

cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "angle", "w"))
tree = sg.Goal("upright", angle=(0.15, 0.2))
budget = sg.Budget(timesteps=64)
"""


def bad_import_specs() -> list[tuple[str, str, str]]:
    """``(name, the Spec's source, what its error says)``: an algorithm and an env of each module that cannot import."""
    cases = []
    for i, (module, says) in enumerate(CASES):
        cases.append(
            (f"algorithm_{i}", f'sg.Spec(cartpole, tree, budget, trainer=sg.SB3(algorithm="{module}:PPO"))', says)
        )
        cases.append(
            (f"env_{i}", f'sg.Spec(sg.InitialEnv("{module}:CartPole-v1", features=("x",)), tree, budget)', says)
        )
    return cases


@pytest.mark.parametrize(("name", "source", "says"), bad_import_specs(), ids=[n for n, _, _ in bad_import_specs()])
def test_a_module_string_that_cannot_be_imported_is_one_line_from_the_cli(name, source, says, tmp_path, capsys):
    write_bad_modules(tmp_path)  # beside the spec file: on its path
    spec_file = tmp_path / "bad_import.py"
    spec_file.write_text(textwrap.dedent(BAD_IMPORT) + f"spec = {source}\n")
    assert main(["show", str(spec_file)]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line and not line.startswith("Hint: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("specguard: error: ") and says in lines[0], err
    assert "importing it" not in lines[0]  # the spec file imported fine: the string is at fault, not the file


def test_a_module_string_that_cannot_be_imported_fails_its_goal_spec_in_one_line(pytester: pytest.Pytester):
    write_bad_modules(pytester.path)
    tests = "".join(
        f"\n\n@sg.goal_spec(expect=0.5)\ndef test_{name}():\n    return {source}\n"
        for name, source, _ in bad_import_specs()
    )
    pytester.makepyfile(test_bad_imports=textwrap.dedent(BAD_IMPORT) + tests)
    run = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--goal-specs", "--goal-specs-workers=1")
    run.assert_outcomes(failed=len(bad_import_specs()))
    text = run.stdout.str()
    assert "Traceback" not in text and "specguard/spec/" not in text and "specguard/construction/" not in text, text
    for name, _, says in bad_import_specs():
        run.stdout.fnmatch_lines([f"*test_bad_imports.py::test_{name}[[]root[]]: *cannot import*{says}*"])
