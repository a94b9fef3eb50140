"""Terminal table, Markdown and plots from plain rows."""

from __future__ import annotations

from specguard.report import markdown, table_lines, write_reports

ROW = {
    "group": "t.py::test_w",
    "goal": "pendulum",
    "success": 0.9,
    "successes": 27,
    "episodes": 30,
    "interval": [0.73, 0.98],
    "threshold": 0.8,
    "runs_met": 2,
    "runs": 2,
    "verdict": "passed",
    "train_seconds": 80.0,
    "cached": True,
    "hint": None,
    "curves": [[{"timesteps": 10, "episodes": 3, "success": {"pendulum": 0.5}}]],
}
FAILED = {
    **ROW,
    "goal": "pendulum/position",
    "verdict": "failed",
    "hint": "consider a Distance",
    "comparison": "dropped",
}


def test_table_lines():
    lines = table_lines([ROW])
    assert lines[0].split() == [
        "spec",
        "goal",
        "success",
        "interval",
        "threshold",
        "runs",
        "met",
        "verdict",
        "training",
        "cached",
    ]
    assert lines[2].split() == [
        "t.py::test_w",
        "pendulum",
        "90%",
        "(27/30)",
        "[0.73,",
        "0.98]",
        ">=",
        "0.8",
        "2/2",
        "passed",
        "80.0s",
        "yes",
    ]


def test_markdown_lists_failing_goals_and_comparisons():
    text = markdown([ROW, FAILED])
    assert "1 failed, 1 passed (2 goals)" in text
    assert "| vs baseline |" in text
    assert "- `t.py::test_w` / `pendulum/position`: consider a Distance" in text


def test_write_reports(tmp_path):
    written = write_reports(tmp_path / "r", [ROW, FAILED])
    assert [p.name for p in written] == ["goal-specs.json", "goal-specs.md", "goal-specs.png"]
    assert write_reports(tmp_path / "s", [{**ROW, "curves": None}])[-1].name == "goal-specs.md"
