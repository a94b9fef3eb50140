"""The command line: show and run on spec files, and its errors."""

from __future__ import annotations

import json
import sys
import textwrap
from pathlib import Path

import pytest

from specguard.cli.main import main
from specguard.error import SpecError
from specguard.spec.loading import load_objects
from specguard.utils.atomic import write_atomic

SPEC_FILE = textwrap.dedent(
    """
    import specguard as sg

    pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    tree = sg.All(
        sg.Goal("position", x=(0.966, 1.0)).annotate(sg.Distance(lambda s: abs(s.x - 1.0), scale=2.0)),
        sg.Goal("stabilization", omega=(-0.25, 0.25)),
        name="pendulum",
    )
    budget = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=2, checkpoints=1)  # judged once
    tiny = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
    trainer = sg.SB3(hyperparameters=tiny)
    easy = sg.Spec(pendulum, tree, budget=budget, expect={"stabilization": 0.0}, trainer=trainer)
    specs = {"hard": sg.Spec(pendulum, tree, budget=budget, expect={"pendulum": 0.99}, trainer=trainer)}
    """
)


@pytest.fixture
def spec_file(tmp_path):
    path = tmp_path / "my_specs.py"
    path.write_text(SPEC_FILE)
    return path


def test_show_prints_tree_and_formula(spec_file, capsys):
    assert main(["show", f"{spec_file}::easy"]) == 0
    out = capsys.readouterr().out
    assert "== easy" in out
    assert "R = 0.5*(0.5*R[position] + 0.5*D[position]) + 0.5*R[stabilization]" in out
    assert "expect: pendulum/stabilization >= 0" in out


def test_show_lists_everything_without_a_name(spec_file, capsys):
    assert main(["show", str(spec_file)]) == 0
    out = capsys.readouterr().out
    assert "== easy" in out and "== hard" in out and "== tree" in out


@pytest.mark.slow
def test_run_passes_and_fails_with_exit_status(spec_file, tmp_path, capsys):
    report = tmp_path / "out.json"
    args = ["--workers", "1", "--cache-dir", str(tmp_path / "cache"), "--quiet"]
    assert main(["run", f"{spec_file}::easy", *args, "--json", str(report)]) == 0
    out = capsys.readouterr().out
    assert "== easy: passed" in out and "pendulum/stabilization" in out
    assert json.loads(report.read_text())["easy"]["passed"] is True
    assert main(["run", f"{spec_file}::hard", *args]) == 1
    assert "== hard: FAILED" in capsys.readouterr().out


TWO_SPECS = textwrap.dedent(
    """
    import specguard as sg

    pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    calm = sg.Always(sg.Goal("calm", omega=(-8, 8)), name="calm")
    tiny = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}


    def spec(steps):
        budget = sg.Budget(timesteps=steps, min_seeds=2, eval_episodes=2, checkpoints=1)
        return sg.Spec(pendulum, calm, budget=budget, expect=0.5, trainer=sg.SB3(hyperparameters=tiny))


    short, long = spec(128), spec(192)
    """
)


@pytest.mark.slow
def test_run_over_several_specs_trains_them_ahead_on_shared_slots(tmp_path, capsys, monkeypatch):
    """Several specs on the local executor with the cache: one pool of slots, every spec planned ahead (the longest
    first), each run handed to its own spec and reported trained; the weights those of a run without the cache."""
    from specguard.engine.ahead import TrainAhead

    path = tmp_path / "two.py"
    path.write_text(TWO_SPECS)
    planned, taken = [], []
    plan, take = TrainAhead.plan, TrainAhead.take
    monkeypatch.setattr(TrainAhead, "plan", lambda self, specs: (planned.extend(specs), plan(self, specs))[1])
    monkeypatch.setattr(TrainAhead, "take", lambda self, key: (taken.append(key), take(self, key))[1])
    report = tmp_path / "ahead.json"
    args = ["--workers", "2", "--quiet", "--json"]
    assert main(["run", str(path), "--cache-dir", str(tmp_path / "cache"), *args, str(report)]) == 0
    assert [s.budget.timesteps for s in planned] == [128, 192] and len(taken) == 4
    ahead = json.loads(report.read_text())
    assert all(not any(r["cached"].values()) for r in ahead.values()), "a run trained ahead is reported as cached"

    planned.clear()
    alone = tmp_path / "alone.json"
    assert main(["run", str(path), "--no-cache", *args, str(alone)]) == 0
    assert planned == [], "no cache: nothing is planned ahead"
    capsys.readouterr()
    digests = {name: [run["weights_digest"] for run in r["runs"]] for name, r in ahead.items()}
    assert digests == {
        name: [run["weights_digest"] for run in r["runs"]] for name, r in json.loads(alone.read_text()).items()
    }


@pytest.mark.slow
def test_run_reports_safety_rates_in_the_table_and_the_json(tmp_path, capsys):
    path = tmp_path / "safe_specs.py"
    path.write_text(
        SPEC_FILE
        + textwrap.dedent(
            """
            spin = sg.Constraint(lambda s, a: abs(s.omega) > 8.5, name="spin")  # |omega| <= 8: never violated
            trainer = sg.SB3(hyperparameters=tiny)
            safe = sg.Spec(pendulum, tree.annotate(spin), budget=budget, expect={"spin": 0.3}, trainer=trainer)
            """
        )
    )
    report = tmp_path / "out.json"
    assert main(["show", f"{path}::safe"]) == 0
    assert "expect: pendulum:spin >= 0.3" in capsys.readouterr().out
    args = ["--workers", "1", "--no-cache", "--quiet", "--json", str(report)]
    assert main(["run", f"{path}::safe", *args]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()]
    goals = [row[0] for row in rows if row and row[0].startswith("pendulum")]
    assert goals == ["pendulum", "pendulum/position", "pendulum/stabilization", "pendulum:spin"]
    (spin,) = [row for row in rows if row and row[0] == "pendulum:spin"]
    assert spin[1:4] == ["(safe)", "100%", "(4/4)"] and spin[-1] == "passed"  # undecided at 2 episodes, met at 4
    data = json.loads(report.read_text())["safe"]
    assert data["passed"] is True
    assert data["goals"]["pendulum:spin"]["kind"] == "safety"
    assert (data["goals"]["pendulum:spin"]["successes"], data["goals"]["pendulum:spin"]["episodes"]) == (4, 4)
    assert data["runs"][0]["successes"]["pendulum:spin"] == 4


@pytest.mark.slow
def test_run_prints_progress_lines(spec_file, tmp_path, capsys):
    main(["run", f"{spec_file}::easy", "--workers", "1", "--no-cache", "--budget-scale", "2"])
    err = capsys.readouterr().err
    assert "[specguard] pendulum seed 0: training, 256 steps" in err
    assert "[specguard] pendulum seed 0: done, 256/256 steps in " in err
    assert "[specguard] pendulum seed 0:  25/256 steps " in err  # a line per tenth of the budget


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["show", "nowhere.py"], "nowhere.py: no such file"),
        (["show", "{file}::nope"], "nothing named 'nope'; it defines: easy, hard, tree"),
    ],
)
def test_errors_name_the_file_and_spec(spec_file, capsys, argv, message):
    argv = [a.replace("{file}", str(spec_file)) for a in argv]
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_a_file_that_raises_on_import(tmp_path, capsys):
    bad = tmp_path / "bad.py"
    bad.write_text("import specguard as sg\nsg.Goal('g', x=(2, 1))\n")
    assert main(["show", str(bad)]) == 2
    assert "Goal 'g', feature 'x': expected lo <= hi" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--workers", "0"], "argument --workers: expected an integer >= 1 (or 'auto': one per usable core), got '0'"),
        (["--budget-scale", "-1"], "argument --budget-scale: expected a finite number > 0, got '-1'"),
        # each option reaches its shared rule (utils.options.parse_count, utils.options.parse_positive)
        (["--workers", "05"], "argument --workers: expected an integer >= 1 (or 'auto': one per usable core), got '05"),
        (["--checkpoints", "05"], "argument --checkpoints: expected an integer >= 1 (1: train every run's whole"),
        (["--budget-scale", "inf"], "argument --budget-scale: expected a finite number > 0, got 'inf'"),
    ],
)
def test_bad_option_values_are_usage_errors(spec_file, option, message, capsys):
    with pytest.raises(SystemExit) as exit_info:  # --no-cache: were the option taken, nothing is written here
        main(["run", str(spec_file), "--no-cache", "--quiet", *option])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--seeds", "05"], "argument --seeds: expected an integer >= 1, got '05'"),
        (["--budget-scale", "nan"], "argument --budget-scale: expected a finite number > 0, got 'nan'"),
        (["--case-scale", "pendulum=inf"], "argument --case-scale: expected a finite number > 0, got 'inf'"),
    ],
)
def test_bad_reproduce_options_are_usage_errors(spec_file, option, message, capsys, tmp_path):
    out = ["--out", str(tmp_path / "r.md"), "--cache-dir", str(tmp_path / "cache"), "--quiet"]  # were it taken
    with pytest.raises(SystemExit) as exit_info:
        main(["reproduce", str(spec_file), *out, *option])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


@pytest.fixture
def no_training(monkeypatch):
    """Replace training by a stub that records what it was asked, and stops the run."""
    import specguard.engine.run_spec

    calls = []

    def run_with(spec, options):
        calls.append(spec)
        raise SpecError("stub: no training in this test")

    monkeypatch.setattr(specguard.engine.run_spec, "run_with", run_with)
    return calls


def test_json_parent_directories_are_created_before_training(spec_file, tmp_path, no_training, capsys):
    report = tmp_path / "out" / "missing" / "dir" / "r.json"
    assert main(["run", f"{spec_file}::easy", "--no-cache", "--quiet", "--json", str(report)]) == 2
    assert report.parent.is_dir() and not report.exists()
    assert len(no_training) == 1  # the directory was there before training was asked for


def test_json_path_that_cannot_be_written_fails_before_training(spec_file, tmp_path, no_training, capsys):
    blocker = tmp_path / "out"
    blocker.write_text("a file, not a directory")
    report = blocker / "dir" / "r.json"
    assert main(["run", f"{spec_file}::easy", "--no-cache", "--json", str(report)]) == 2
    err = capsys.readouterr().err
    assert f"specguard: error: --json {report}: cannot create the directory {report.parent}" in err
    assert no_training == []
    assert main(["run", f"{spec_file}::easy", "--no-cache", "--json", str(tmp_path)]) == 2
    assert f"--json {tmp_path}: is a directory; expected a file name" in capsys.readouterr().err
    assert no_training == []


def test_a_spec_file_in_a_package_imports_its_package_by_name(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "path", list(sys.path))
    monkeypatch.setattr(sys, "modules", dict(sys.modules))
    package = tmp_path / "cases"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "base.py").write_text("import specguard as sg\nTREE = sg.Goal('up', x=(0.5, None))\n")
    (package / "more.py").write_text(
        "import specguard as sg\nfrom cases import base\n"
        "spec = sg.Spec(sg.InitialEnv('Pendulum-v1', features=('x', 'y', 'omega')), base.TREE, sg.Budget(64))\n"
    )
    assert list(load_objects(str(package / "more.py"))) == ["spec"]


def test_a_spec_file_that_exits_at_import_is_one_line_naming_it(tmp_path, capsys):
    path = tmp_path / "exits.py"
    path.write_text("import sys\nsys.exit(3)\n")
    for command in ("run", "show"):
        assert main([command, str(path), "--no-cache"] if command == "run" else [command, str(path)]) == 2
        err = capsys.readouterr().err
        assert f"specguard: error: {path}: importing it called sys.exit(3)" in err and "Traceback" not in err


@pytest.mark.slow
def test_falsify_searches_each_run_and_prints_the_failure_rate(spec_file, tmp_path, capsys):
    argv = ["falsify", f"{spec_file}::easy", "--cache-dir", str(tmp_path / "c"), "--examples", "5", "--uniform", "4"]
    code = main([*argv, "--starts", "theta=-0.5:0.5", "--quiet"])
    out = capsys.readouterr().out
    assert code in (0, 1) and "== easy seed 0: " in out
    assert "starts set by state over theta, omega" in out and "uniform draws), interval [" in out
    assert ("COUNTEREXAMPLE" in out) == (code == 1)


@pytest.mark.slow
def test_falsify_searches_the_spec_s_own_start_space_and_checks_it_before_training(tmp_path, capsys):
    path = tmp_path / "own.py"
    path.write_text(SPEC_FILE + "import dataclasses\nown = dataclasses.replace(easy, starts={'speed': (0.0, 1.0)})\n")
    code = main(["falsify", f"{path}::own", "--cache-dir", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code == 2 and "'speed', which its setter does not know" in err and not (tmp_path / "c").exists()
    # --starts replaces the spec's own: this one is searched.
    argv = ["falsify", f"{path}::own", "--cache-dir", str(tmp_path / "c"), "--examples", "2", "--uniform", "0"]
    assert main([*argv, "--starts", "theta=-0.5:0.5", "--quiet"]) in (0, 1)


def test_falsify_refuses_negative_uniform_draws(spec_file, capsys):
    with pytest.raises(SystemExit):
        main(["falsify", f"{spec_file}::easy", "--uniform", "-1"])
    assert "expected an integer >= 0 (uniform draws), got '-1'" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("starts", "message"),
    [
        ("speed=0:1", "'speed', which its setter does not know; known: theta, omega"),
        ("omega=-9:9", "outside its bounds"),
    ],
)
def test_falsify_refuses_a_bad_start_space_before_training(spec_file, tmp_path, capsys, starts, message):
    code = main(["falsify", f"{spec_file}::easy", "--cache-dir", str(tmp_path / "c"), "--starts", starts])
    assert code == 2 and message in capsys.readouterr().err and not (tmp_path / "c").exists()


# -- first touch: help, version, bad input ----------------------------------------------------------

SUBCOMMANDS = ("show", "plan", "run", "reproduce", "falsify", "check")


def _python(*args: str, cwd=None, env=None):
    import subprocess

    return subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=300)


@pytest.mark.slow
def test_pytest_help_works_with_the_plugin_loaded(tmp_path):
    import os

    env = {**os.environ, "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1"}  # the plugin loaded by -p, this checkout's own
    done = _python("-m", "pytest", "-p", "specguard.pytest_plugin.plugin", "--help", cwd=tmp_path, env=env)
    assert done.returncode == 0, done.stderr[-2000:]
    for option in ("--goal-specs-compare", "--goal-specs-report", "--goal-specs-undecided", "--goal-specs-plan"):
        assert option in done.stdout
    assert "family-wise 5%" in done.stdout


@pytest.mark.slow
@pytest.mark.parametrize("argv", [["--help"], *[[command, "--help"] for command in SUBCOMMANDS]])
def test_every_command_s_help_works(argv):
    done = _python("-m", "specguard", *argv)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "usage: specguard" in done.stdout and done.stderr == ""


def test_the_help_names_every_command_and_the_version_is_printed(capsys):
    from specguard.cli.main import build_parser
    from specguard.version import __version__

    text = build_parser().format_help()
    assert "show and run" not in text
    assert all(command in text for command in SUBCOMMANDS)
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"specguard {__version__}"


def _one_error_line(err: str) -> str:
    """The one line naming the culprit (a ``Hint:`` line may follow it), with no traceback."""
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line and not line.startswith("Hint: ")]
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("command", ["show", "plan", "run"])
@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("notes.txt", "notes.txt: not a Python file (expected a .py file of specs)"),
        ("folder", "folder: is a directory; expected a Python file of specs, e.g. folder/specs.py"),
        ("/dev/null", "/dev/null: not a regular file; expected a Python file of specs"),
        ("::tiny", "'::tiny': no file named before '::'; expected PATH[::NAME]"),
        ("nowhere.py", "nowhere.py: no such file"),
    ],
)
def test_a_target_that_is_no_spec_file_is_one_line_naming_it(tmp_path, monkeypatch, capsys, command, target, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "notes.txt").write_text("spec = 1\n")
    (tmp_path / "folder").mkdir()
    assert main([command, target]) == 2
    assert _one_error_line(capsys.readouterr().err) == f"specguard: error: {message}"


@pytest.mark.slow
@pytest.mark.parametrize("exit_call", ["os._exit(0)", "os._exit(3)", "sys.exit()", "raise SystemExit('bye')"])
def test_a_spec_file_that_ends_the_process_at_import_is_an_error_naming_it(tmp_path, exit_call):
    path = tmp_path / "quits.py"
    path.write_text(f"import os, sys\n{exit_call}\n")
    done = _python("-m", "specguard", "plan", str(path))
    assert done.returncode == 2, (done.returncode, done.stdout, done.stderr)
    line = _one_error_line(done.stderr)
    assert line.startswith(f"specguard: error: {path}: importing it called ") and "exit" in line


@pytest.mark.slow
def test_a_json_write_that_fails_at_the_end_warns_and_keeps_the_results(spec_file, tmp_path, monkeypatch, capsys):
    import specguard.cli.arguments as cli

    report = tmp_path / "out.json"

    def refuse(path, text, *args, **kwargs):
        if Path(path) == report:
            raise PermissionError(13, "Permission denied", str(path))
        return write_atomic(path, text, *args, **kwargs)

    monkeypatch.setattr(cli, "write_atomic", refuse)
    argv = ["run", f"{spec_file}::easy", "--workers", "1", "--no-cache", "--quiet", "--json", str(report)]
    assert main(argv) == 0  # the verdicts' exit status, kept
    captured = capsys.readouterr()
    assert "== easy: passed" in captured.out
    warning = _one_error_line(captured.err)
    head = f"specguard: warning: --json {report}: could not write it (Permission denied); the results are in "
    assert warning.startswith(head) and not report.exists()
    fallback = Path(warning.removeprefix(head))
    assert json.loads(fallback.read_text())["easy"]["passed"] is True
    fallback.unlink()


@pytest.mark.slow
def test_a_json_write_that_fails_twice_prints_the_results(spec_file, tmp_path, monkeypatch, capsys):
    import specguard.cli.arguments as cli

    def refuse(path, text, *args, **kwargs):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(cli, "write_atomic", refuse)
    monkeypatch.setattr(cli.tempfile, "mkstemp", lambda *a, **k: refuse("tmp", ""))
    report = tmp_path / "out.json"
    argv = ["run", f"{spec_file}::hard", "--workers", "1", "--no-cache", "--quiet", "--json", str(report)]
    assert main(argv) == 1  # the verdicts' exit status, kept
    captured = capsys.readouterr()
    warning = _one_error_line(captured.err)
    reason = "could not write it (No space left on device)"
    assert warning == f"specguard: warning: --json {report}: {reason}; the results follow on stdout"
    assert json.loads(captured.out[captured.out.index("{\n") :])["hard"]["passed"] is False
