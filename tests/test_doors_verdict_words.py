"""One word per verdict at every door: ``specguard run`` says what ``pytest --goal-specs`` says for the same runs.

One tiny spec file, trained once by ``specguard run`` and read back from the
same cache by ``pytest --goal-specs``: a goal the spec declares in ``xfail``
that passes is ``xpassed``, one that misses is ``xfailed``, and a goal whose
runs stayed undecided is ``undecided`` in both tables.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest

# Imported before any test: pytester's fixture drops the modules a test imported when it ends, and these
# (numpy's C extensions under scipy.stats) cannot be imported twice.
import scipy.stats  # noqa: F401

from specguard.cli.main import main
from specguard.stats.verdicts import VERDICT_WORDS, GoalOutcome, verdict_word

SPEC_FILE = """
import specguard as sg

pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
tree = sg.All(
    sg.Goal("anywhere", x=(-1.0, 1.0)),  # every state: met
    sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)),  # upright: never within 128 steps
    name="pendulum",
)
tiny = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
budget = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=8, checkpoints=1)
expected = sg.Spec(
    pendulum,
    tree,
    budget=budget,
    trainer=sg.SB3(hyperparameters=tiny),
    expect={"anywhere": 0.3, "position": 0.9},
    xfail={"anywhere": "the paper says it misses", "position": "the paper says it misses"},
)
# Two evaluation episodes never place a run's interval on one side of 0.5: the goal stays undecided.
unsure = sg.Spec(
    pendulum,
    tree,
    budget=sg.Budget(timesteps=128, min_seeds=1, eval_episodes=2, max_eval_episodes=2, checkpoints=1),
    trainer=sg.SB3(hyperparameters=tiny),
    expect={"anywhere": 0.5},
)
"""

WORDS = {
    ("expected", "pendulum/anywhere"): "xpassed",
    ("expected", "pendulum/position"): "xfailed",
    ("unsure", "pendulum/anywhere"): "undecided",
}


def cli_words(out: str) -> tuple[dict[tuple[str, str], str], dict[str, str]]:
    """Per (spec, goal), the table's verdict word; per spec, the word of its ``== name:`` line."""
    words, lines, spec = {}, {}, ""
    for line in out.splitlines():
        if line.startswith("== "):
            spec, _, rest = line.removeprefix("== ").partition(": ")
            lines[spec] = rest.rsplit(" (", 1)[0]
        elif line.startswith("pendulum/") and not line.endswith(" -"):  # "-": measured, no threshold
            cells = line.split()
            words[spec, cells[0]] = cells[-1]
    return words, lines


def test_specguard_run_and_pytest_say_the_same_words(tmp_path: Path, pytester: pytest.Pytester, capsys):
    spec_file = tmp_path / "word_specs.py"
    spec_file.write_text(textwrap.dedent(SPEC_FILE))
    cache = tmp_path / "cache"

    argv = ["run", str(spec_file), "--workers", "1", "--cache-dir", str(cache), "--quiet"]
    assert main(argv) == 1  # the undecided goal counts as failed (Spec.undecided: fail)
    words, lines = cli_words(capsys.readouterr().out)
    assert words == WORDS
    assert lines == {"expected": "xfailed", "unsure": "undecided, counted as failed"}

    pytester.makepyfile(word_specs=spec_file.read_text())
    pytester.makepyfile(
        test_words="import specguard as sg\nimport word_specs\n\n"
        "test_words = sg.goal_specs({'expected': word_specs.expected, 'unsure': word_specs.unsure})\n"
    )
    report = tmp_path / "report"
    run = pytester.runpytest_subprocess(
        "-p",
        "no:cacheprovider",
        "--goal-specs",
        "--goal-specs-workers=1",
        f"--goal-specs-cache-dir={cache}",
        f"--goal-specs-report={report}",
    )
    run.assert_outcomes(xpassed=1, xfailed=1, failed=1)
    rows = json.loads((report / "goal-specs.json").read_text())["goals"]
    plugin = {(row["group"].rpartition("[")[2].rstrip("]"), row["goal"]): row["verdict"] for row in rows}
    assert plugin == WORDS
    assert all(row["cached"] for row in rows)  # the same runs as specguard run's


@pytest.mark.parametrize(
    ("counted", "outcome", "expected_miss", "word"),
    [
        ("passed", GoalOutcome.PASSED, False, "passed"),
        ("passed", GoalOutcome.PASSED, True, "xpassed"),
        ("failed", GoalOutcome.FAILED, False, "failed"),
        ("xfailed", GoalOutcome.FAILED, True, "xfailed"),
        ("failed", GoalOutcome.UNDECIDED, False, "undecided"),  # Spec.undecided = "fail"
        ("passed", GoalOutcome.UNDECIDED, False, "undecided"),  # "pass"
        ("xfailed", GoalOutcome.UNDECIDED, False, "xfailed"),  # "xfail": pytest xfails it
        ("passed", GoalOutcome.UNDECIDED, True, "xpassed"),  # declared xfail, passed by "pass": pytest XPASS
    ],
)
def test_verdict_word_follows_pytest(counted, outcome, expected_miss, word):
    assert verdict_word(counted, outcome, expected_miss=expected_miss) == word
    assert word in VERDICT_WORDS
