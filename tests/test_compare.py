"""Baselines and the two-sample comparison."""

from __future__ import annotations

import pytest

from specguard.compare import Baseline, BaselineError, compare, load_baseline, save_baseline


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
