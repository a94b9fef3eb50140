"""``specguard reproduce``: every spec of case-study files on N seeds, a table beside the paper, plots."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

import specguard as sg
from example_specs import pendulum
from specguard.cache.versions import versions
from specguard.cli.main import main
from specguard.engine.reproduce import sized
from specguard.report.reproduction import TITLE, sections

REPO = Path(__file__).resolve().parents[1]

CASE = """
import specguard as sg

initial_env = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
budget = sg.Budget(timesteps=128, eval_episodes=4, checkpoints=10)
trainer = sg.SB3(hyperparameters=TINY)
tree = sg.All(sg.Goal("position", x=(0.966, 1.0)), sg.Goal("stabilization", omega=(-0.25, 0.25)), name="p")
specs = {
    "b": sg.Spec(initial_env, tree, budget=budget, trainer=trainer, expect={"stabilization": 0.0}),
    "baseline": sg.Spec(initial_env, tree, budget=budget, trainer=trainer, expect=0.5, baseline=True),
    "auto": sg.Spec(
        initial_env,
        sg.All(*tree.children, name="p", weights="auto"),
        budget=budget,
        trainer=sg.SB3(hyperparameters=TINY),
        expect={"stabilization": 0.0},
    ),
}
PAPER = {"b": "half the runs"}
"""


def test_sized_trains_every_seed_its_whole_scaled_budget():
    spec = sg.Spec(
        pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(timesteps=1000, checkpoints=10), quorum=1
    )
    out = sized(spec, seeds=5, budget_scale=0.5)
    assert (out.budget.timesteps, out.budget.checkpoints) == (500, 1)
    assert (out.budget.min_seeds, out.budget.max_seeds, out.required_runs) == (5, 5, 5)


@pytest.mark.slow
def test_reproduce_writes_a_table_beside_the_paper_and_a_plot_per_case(tmp_path, capsys):
    case = tmp_path / "tiny_case.py"
    case.write_text(textwrap.dedent(CASE))
    out = tmp_path / "docs" / "reproduction.md"
    argv = ["reproduce", str(case), "--seeds", "2", "--workers", "2", "--quiet"]
    argv += ["--cache-dir", str(tmp_path / "cache"), "--out", str(out)]
    assert main(argv) == 0
    text = out.read_text()
    assert f"Made with `specguard {' '.join(argv)}`" in text
    assert "| spec | root success | 95% interval | runs met | paper | steps per run |" in text
    b_row = next(line for line in text.splitlines() if line.startswith("| b |"))
    # 8 episodes pooled; the root has no threshold in b; 128 steps: the whole budget, no checkpoint stopped it.
    assert "/8)" in b_row and b_row.endswith("| - | half the runs | 128 |")
    baseline_row = next(line for line in text.splitlines() if line.startswith("| baseline |"))
    assert "/2 (>= 0.5)" in baseline_row and baseline_row.split(" | ")[4] == "-"
    assert (tmp_path / "docs" / "images" / "reproduction-tiny_case.png").stat().st_size > 0
    assert "![tiny_case: success per goal over training](images/reproduction-tiny_case.png)" in text
    assert "specguard " + versions()["specguard"] + ". 2 seeds per spec, budget scale 1x." in text
    # 128 steps finish no Pendulum episode, so the weights stay where "auto" starts.
    assert "Adapted weights of (auto) when training ended: seed 0 p (0.50, 0.50), seed 1 p (0.50, 0.50)." in text
    # The hint of each goal that did not pass, as the table of `specguard run` and the pytest item print it.
    hints = [line for line in text.splitlines() if line.startswith("Hint for (")]
    assert hints and all(line.count(": ") >= 1 for line in hints), text
    # Resumable: a second call trains nothing, every run comes from the cache.
    assert main(argv) == 0
    assert out.read_text() == text
    # The plot is drawn from curve data written beside it: --replot redraws it, training nothing.
    png = tmp_path / "docs" / "images" / "reproduction-tiny_case.png"
    drawn = png.read_bytes()
    data = json.loads(png.with_suffix(".json").read_text())
    assert {row["group"] for row in data} == {"tiny_case (b)", "tiny_case (auto)", "tiny_case (baseline)"}
    assert all(len(row["curves"]) == 2 for row in data)  # both seeds' curves
    png.unlink()
    assert main(["reproduce", "--replot", "--out", str(out)]) == 0
    assert png.read_bytes() == drawn


@pytest.mark.slow
def test_a_reproduction_rewrites_its_own_cases_and_keeps_the_sections_of_others(tmp_path):
    case = tmp_path / "tiny_case.py"
    case.write_text(textwrap.dedent(CASE))
    out = tmp_path / "reproduction.md"
    before = "## first\n\nMade earlier.\n\n## tiny_case\n\nstale table\n\n## last\n\nMade later.\n"
    out.write_text("# an older title\n\nolder intro\n\n" + before)
    argv = ["reproduce", str(case), "--seeds", "1", "--quiet", "--out", str(out)]
    assert main([*argv, "--cache-dir", str(tmp_path / "cache")]) == 0
    text = out.read_text()
    assert text.startswith(TITLE) and "older" not in text and "stale table" not in text
    assert [line for line in text.splitlines() if line.startswith("## ")] == ["## first", "## tiny_case", "## last"]
    assert "## first\n\nMade earlier.\n\n## tiny_case\n\nMade with `specguard reproduce" in text
    assert text.endswith("## last\n\nMade later.\n")
    assert sections(text)["tiny_case"].count("| b |") == 1


def test_a_case_scale_names_a_given_case(tmp_path, capsys):
    case = tmp_path / "tiny_case.py"
    case.write_text(textwrap.dedent(CASE))
    argv = ["reproduce", str(case), "--case-scale", "lunar=0.5", "--out", str(tmp_path / "r.md")]
    assert main(argv) == 2
    assert "case scale: no case named 'lunar'; the cases are ['tiny_case']" in capsys.readouterr().err


@pytest.mark.slow
def test_a_case_scale_replaces_the_budget_scale_for_its_case(tmp_path):
    case = tmp_path / "tiny_case.py"
    case.write_text(textwrap.dedent(CASE))
    out = tmp_path / "r.md"
    argv = ["reproduce", str(case), "--seeds", "1", "--case-scale", "tiny_case=0.5", "--quiet", "--out", str(out)]
    assert main([*argv, "--cache-dir", str(tmp_path / "cache")]) == 0
    text = out.read_text()
    assert "budget scale 0.5x." in text and text.count("| 64 |") == 3  # 128 steps halved, for every spec


LONG_CASE = """
import specguard as sg

initial_env = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
budget = sg.Budget(timesteps=200_000, eval_episodes=4)
trainer = sg.SB3(hyperparameters=TINY)
specs = {  # three different trees: identical specs would share one training run
    name: sg.Spec(initial_env, sg.Goal(name, x=(low, 1.0)), budget=budget, trainer=trainer, expect=0.0)
    for name, low in (("first", 0.9), ("second", 0.95), ("third", 0.966))
}
"""


_EXEC_WITH_SIGINT = (
    "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
    "signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT}); os.execv(sys.argv[1], sys.argv[1:])"
)


def _signal_masks(pid: int) -> str:
    """The process's blocked, ignored and caught signal masks (Linux), for a failure's message."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except OSError as e:
        return f"no signal masks: {e}"
    return ", ".join(line.replace("\t", " ") for line in lines if line.startswith(("SigBlk", "SigIgn", "SigCgt")))


@pytest.mark.slow
def test_an_interruption_stops_the_running_specs_at_once_and_starts_no_other(tmp_path):
    case = tmp_path / "long_case.py"
    case.write_text(textwrap.dedent(LONG_CASE))
    cache = tmp_path / "cache"
    argv = ["reproduce", str(case), "--seeds", "1", "--workers", "2", "--cache-dir", str(cache)]
    # The process starts as a terminal's would: SIGINT neither ignored nor blocked. A child inherits both from the
    # test's process (an ignored SIGINT stays ignored: Python then installs no KeyboardInterrupt), which pytest and
    # its xdist workers do not promise; they are set in the process itself, which then becomes reproduce (exec).
    command = [sys.executable, "-m", "specguard", *argv, "--out", str(tmp_path / "r.md")]
    parent = subprocess.Popen(
        [sys.executable, "-c", _EXEC_WITH_SIGINT, *command],
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stderr=subprocess.PIPE,
        text=True,
    )
    assert parent.stderr is not None
    lines: list[str] = []
    training: set[str] = set()
    while len(training) < 2:  # both running specs have started their seed's process
        line = parent.stderr.readline()
        if not line:
            pytest.fail("reproduce ended before both specs started: " + "".join(lines))
        lines.append(line)
        if ": training, " in line:
            training.add(line.split()[1])
    parent.send_signal(signal.SIGINT)  # to the parent alone, as a SIGTERM would come: the children go on unless stopped
    start = time.monotonic()
    try:
        rest = parent.communicate(timeout=30)[1]  # 200k steps take minutes: only the stop ends it this soon
    except subprocess.TimeoutExpired:
        masks = _signal_masks(parent.pid)
        parent.kill()
        pytest.fail(f"reproduce did not stop within 30 s of SIGINT ({masks})")
    assert time.monotonic() - start < 30
    assert parent.returncode == 130, rest
    assert "interrupted; finished runs are cached, unfinished ones were not stored" in rest
    assert "third" not in "".join(lines) + rest  # it was still queued: it never started
    assert not list(cache.rglob("*.json"))  # unfinished runs store nothing
    assert not (tmp_path / "r.md").exists()


def test_a_run_counts_as_met_by_its_interval_as_every_door_judges_it():
    from specguard.engine.judging import judge
    from specguard.engine.reproduce import CaseStudy
    from specguard.engine.spec_result import SpecResult
    from specguard.report.reproduction import _root_row
    from specguard.training.result import RunResult

    spec = sized(
        sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(timesteps=100)), seeds=2, budget_scale=1
    )
    spec = dataclasses.replace(spec, expect={"pendulum": 0.5})
    # 20/30 reaches 0.5 by its point estimate, but its interval [0.47, 0.83] does not lie above it; 29/30 does.
    runs = [
        RunResult(spec="w", seed=s, timesteps=100, episodes=30, successes=dict.fromkeys(keys, k), train_seconds=0.0)
        for s, k in enumerate((20, 29))
        for keys in [[p for p, _ in spec.tree.walk()]]
    ]
    result = SpecResult(spec="w", runs=runs, goals=judge(spec, runs, failed_seeds=0), trained=spec)
    row = _root_row(CaseStudy("pendulum", {"w": spec}, {}), "w", result, seeds=2)
    assert row[3] == "1/2 (>= 0.5)"


def test_replot_refuses_curve_data_it_did_not_write(tmp_path, capsys):
    (tmp_path / "images").mkdir()
    (tmp_path / "images" / "reproduction-x.json").write_text('{"not": "rows"}')
    assert main(["reproduce", "--replot", "--out", str(tmp_path / "reproduction.md")]) == 2
    assert "expected a list of rows with curves" in capsys.readouterr().err


def test_reproduce_without_case_files_is_a_usage_error(capsys):
    assert main(["reproduce"]) == 2
    assert "expected at least one case-study file" in capsys.readouterr().err
