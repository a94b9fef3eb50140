"""Terminal table, Markdown and plots from plain rows."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import pytest

from specguard.report.gifs import Gif
from specguard.report.plots import curves_figure, plot_curves
from specguard.report.session_report import session_markdown as markdown
from specguard.report.session_report import table_lines, write_reports


def curve(*rates, evaluation=None):
    points = [{"timesteps": 10 * (i + 1), "episodes": 3, "success": {"pendulum": r}} for i, r in enumerate(rates)]
    if evaluation is not None:
        points[-1]["evaluation"] = {"pendulum": evaluation}
    return points


ROW = {
    "group": "t.py::test_w",
    "goal": "pendulum",
    "success": 0.9,
    "successes": 56,
    "episodes": 60,
    "interval": [0.73, 0.98],
    "threshold": 0.8,
    "runs_met": 2,
    "runs": 2,
    "per_seed": [
        {"seed": 0, "successes": 29, "episodes": 30, "verdict": "met"},
        {"seed": 1, "successes": 27, "episodes": 30, "verdict": "met"},
    ],
    "errors": {},
    "verdict": "passed",
    "train_seconds": 80.0,
    "cached": False,
    "hint": None,
    "curves": [curve(0.5, 0.9), curve(0.2, 0.8)],
}
CACHED = {**ROW, "goal": "pendulum/stabilization", "threshold": 0.5, "cached": True}
FAILED = {
    **ROW,
    "goal": "pendulum/position",
    "verdict": "failed",
    "hint": "consider a Distance",
    "comparison": "dropped",
}


def test_table_lines_show_per_seed_successes_and_training_time():
    lines = table_lines([ROW])
    assert lines[0].split() == [
        "spec",
        "goal",
        "success",
        "interval",
        "threshold",
        "runs",
        "met",
        "per",
        "seed",
        "verdict",
        "training",
    ]
    assert lines[2].split() == [
        "t.py::test_w",
        "pendulum",
        "90%",
        "(56/60)",
        "[0.73,",
        "0.98]",
        ">=",
        "0.8",
        "2/2",
        "29/30,",
        "27/30",
        "passed",
        "80.0s",
    ]


def test_cached_rows_say_cached_instead_of_old_training_seconds():
    lines = table_lines([ROW, CACHED])
    assert lines[2].endswith("80.0s")
    assert lines[3].endswith("cached") and "80.0s" not in lines[3]
    text = markdown([ROW, CACHED])
    assert "| 29/30, 27/30 | passed | 80.0s |" in text
    assert "| 29/30, 27/30 | passed | cached |" in text


def test_a_crashed_seed_shows_in_the_per_seed_column():
    row = {**ROW, "per_seed": ROW["per_seed"][:1], "errors": {"1": "boom"}, "runs_met": 1}
    assert "29/30, error" in table_lines([row])[2]


def test_markdown_lists_failing_goals_and_comparisons():
    text = markdown([ROW, FAILED])
    assert "1 failed, 1 passed (2 goals)" in text
    assert "| vs baseline |" in text
    assert "| per seed |" in text
    assert "- `t.py::test_w` / `pendulum/position`: consider a Distance" in text


def test_markdown_lists_the_adapted_weights_of_each_seed():
    seeds = [{**s, "weights": {"pendulum": [0.8, 0.2]}} for s in ROW["per_seed"]]
    text = markdown([{**ROW, "per_seed": seeds}, CACHED])
    assert "### Adapted weights" in text
    assert "- `t.py::test_w`: seed 0 pendulum (0.80, 0.20), seed 1 pendulum (0.80, 0.20)" in text
    assert "Adapted weights" not in markdown([ROW])


def test_markdown_links_the_figures_beside_it():
    gifs = {
        "t.py::test_w": Gif(Path("/r/t.py__test_w.gif"), "pendulum, 200 steps; goals met at the end: pendulum", 40),
        "t.py::test_x": Gif(None, "no rollout GIF: the run cache is off"),
    }
    text = markdown([ROW, {**ROW, "group": "t.py::test_x"}], plot="goal-specs.png", gifs=gifs)
    assert "](goal-specs.png)" in text
    assert "![rollout of t.py::test_w](t.py__test_w.gif)" in text
    assert "seed 0, one evaluation episode: pendulum, 200 steps; goals met at the end: pendulum" in text
    assert "**`t.py::test_x`**: no rollout GIF: the run cache is off" in text
    assert "### Figures" not in markdown([ROW])


def lines_of(fig, goal):
    return [line for ax in fig.axes for line in ax.get_lines() if (line.get_gid() or "").startswith(f"{goal}:")]


def test_figure_has_a_thin_line_per_seed_a_bold_mean_and_the_threshold():
    fig = curves_figure([ROW])
    lines = lines_of(fig, "pendulum")
    gids = sorted(line.get_gid() for line in lines)
    assert gids == ["pendulum:mean", "pendulum:seed 0", "pendulum:seed 1", "pendulum:threshold"]
    curves = [line for line in lines if not line.get_gid().endswith(":threshold")]
    assert len(curves) == len(ROW["curves"]) + 1  # N seeds + the mean
    by_gid = {line.get_gid(): line for line in lines}
    assert list(by_gid["pendulum:mean"].get_ydata()) == pytest.approx([0.35, 0.85])
    assert by_gid["pendulum:mean"].get_linewidth() > by_gid["pendulum:seed 0"].get_linewidth()
    threshold = by_gid["pendulum:threshold"]
    assert threshold.get_linestyle() == "--" and list(threshold.get_ydata()) == [0.8, 0.8]
    labels = [t.get_text().strip() for ax in fig.axes for t in ax.texts]
    assert sorted(labels) == ["s0", "s1"]  # each seed's number with its curve


def test_figure_has_one_panel_per_spec_and_only_asserted_goals():
    other = {**ROW, "group": "t.py::test_other", "curves": [curve(0.1, 0.2)], "per_seed": ROW["per_seed"][:1]}
    fig = curves_figure([ROW, CACHED, other])
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in visible] == ["test_w", "test_other"]
    # CACHED asserts pendulum/stabilization, which these curves do not carry: its threshold only
    assert [line.get_gid() for line in lines_of(fig, "pendulum/stabilization")] == ["pendulum/stabilization:threshold"]
    assert len([line for line in visible[1].get_lines() if line.get_gid() == "pendulum:seed 0"]) == 1


def test_evaluation_checkpoints_are_markers():
    row = {**ROW, "curves": [curve(0.5, 0.9, evaluation=1.0), curve(0.2, 0.8, evaluation=0.5)]}
    (marks,) = [line for line in lines_of(curves_figure([row]), "pendulum") if line.get_gid() == "pendulum:evaluation"]
    assert list(marks.get_xdata()) == [20] and list(marks.get_ydata()) == [0.75]
    assert marks.get_marker() == "o" and marks.get_linestyle() == "None"
    assert not [line for line in lines_of(curves_figure([ROW]), "pendulum") if "evaluation" in line.get_gid()]


def test_plotting_leaves_the_matplotlib_backend_alone(tmp_path):
    before = matplotlib.get_backend()
    matplotlib.use("svg")  # any backend but Agg: writing a report must not switch it
    try:
        assert plot_curves([ROW], tmp_path / "p.png")
        assert matplotlib.get_backend() == "svg"
    finally:
        matplotlib.use(before)
    assert (tmp_path / "p.png").read_bytes()[:4] == b"\x89PNG"


def test_write_reports(tmp_path):
    written = write_reports(tmp_path / "r", [ROW, FAILED])
    assert [p.name for p in written] == ["goal-specs.json", "goal-specs.md", "goal-specs.png"]
    assert "](goal-specs.png)" in (tmp_path / "r" / "goal-specs.md").read_text()
    assert write_reports(tmp_path / "s", [{**ROW, "curves": None}])[-1].name == "goal-specs.md"
    assert "goal-specs.png" not in (tmp_path / "s" / "goal-specs.md").read_text()


# -- safety rates -----------------------------------------------------------------------------------------------

SAFETY = {
    **ROW,
    "goal": "pendulum:fast",
    "kind": "safety",
    "threshold": 0.9,
    "verdict": "failed",
    "hint": "'pendulum:fast' was violated in 10% of evaluation episodes",
    "curves": [
        [{"timesteps": 10, "episodes": 3, "success": {"pendulum": 0.5, "pendulum:fast": 0.6}}],
        [{"timesteps": 10, "episodes": 3, "success": {"pendulum": 0.2, "pendulum:fast": 0.8}}],
    ],
}
OTHER = {**ROW, "group": "t.py::test_x"}


def test_safety_rows_are_labelled_and_follow_their_specs_goals():
    lines = table_lines([SAFETY, ROW, OTHER, CACHED])  # items in any order
    assert [line.split()[:3] for line in lines[2:]] == [
        ["t.py::test_w", "pendulum", "90%"],
        ["t.py::test_w", "pendulum/stabilization", "90%"],
        ["t.py::test_w", "pendulum:fast", "(safe)"],
        ["t.py::test_x", "pendulum", "90%"],
    ]
    assert lines[4].split()[3:9] == ["90%", "(56/60)", "[0.73,", "0.98]", ">=", "0.9"]


def test_markdown_shows_safety_rates_after_the_goals():
    text = markdown([SAFETY, ROW])
    body = [line for line in text.splitlines() if line.startswith("| t.py")]
    assert [line.split(" | ")[1] for line in body] == ["`pendulum`", "`pendulum:fast` (safe)"]
    assert "- `t.py::test_w` / `pendulum:fast` (safety rate): 'pendulum:fast' was violated in 10%" in text


def test_figure_labels_an_asserted_safety_rate_as_safety():
    fig = curves_figure([{**ROW, "curves": SAFETY["curves"]}, SAFETY])  # a spec's rows share its runs' curves
    (mean,) = [line for line in lines_of(fig, "pendulum:fast") if line.get_gid() == "pendulum:fast:mean"]
    assert mean.get_label() == "pendulum:fast (safe)" and list(mean.get_ydata()) == pytest.approx([0.7])
    assert [line.get_gid() for line in lines_of(fig, "pendulum:fast") if "threshold" in line.get_gid()] == [
        "pendulum:fast:threshold"
    ]


def seed_labels(fig):
    return [t for ax in fig.axes for t in ax.texts if (t.get_gid() or "").endswith(":label")]


def test_the_mean_is_drawn_only_where_every_seed_has_a_point():
    # Seed 0 stopped at a checkpoint after 20 steps (anytime verdicts); seed 1 trained on to 40.
    row = {**ROW, "curves": [curve(0.5, 0.9), curve(0.2, 0.8, 0.0, 0.9)]}
    (mean,) = [line for line in lines_of(curves_figure([row]), "pendulum") if line.get_gid() == "pendulum:mean"]
    assert list(mean.get_xdata()) == [10, 20]  # not seed 1 alone at 30 and 40, where the mean would dip to 0
    assert list(mean.get_ydata()) == pytest.approx([0.35, 0.85])


def test_seed_labels_stack_inside_the_axes_or_are_left_out():
    labelled = seed_labels(curves_figure([ROW]))
    assert sorted(t.get_text().strip() for t in labelled) == ["s0", "s1"]
    # Many seeds ending together at 0: their labels would pile up below the plot, so none is drawn.
    many = {**ROW, "per_seed": [{"seed": i} for i in range(30)], "curves": [curve(0.0, 0.0)] * 30}
    fig = curves_figure([many])
    assert seed_labels(fig) == []
    assert "seeds; bold: mean while every seed trains" in [t.get_text() for t in fig.axes[0].get_legend().get_texts()]


COLLIDING = [("t.py::a/b", "t.py::a b"), ("t.py::test_ü", "t.py::test_ö"), ("t.py::A", "t.py::a"), ("a::b", "a__b")]


@pytest.mark.parametrize("keys", COLLIDING)
def test_gif_names_are_unique_per_spec_and_stable(keys):
    from specguard.report.gifs import gif_stem

    one, other = (gif_stem(k) for k in keys)
    assert one != other and one.lower() != other.lower()  # distinct on a case-insensitive disk too
    assert gif_stem(keys[0]) == one  # stable: the same key, the same name
    assert all(ch.isascii() and (ch.isalnum() or ch in "_.-~") for ch in one + other)


def test_a_plain_key_keeps_its_readable_gif_name_and_a_long_one_is_bounded():
    from specguard.report.gifs import gif_stem

    assert gif_stem("t.py::test_cart") == "t.py__test_cart"
    assert gif_stem("test_specs.py::test_up") == "test_specs.py__test_up"
    long = gif_stem("t.py::test_" + "x" * 300)
    assert len(long) <= 100 and long.startswith("t.py__test_xxx")
    assert gif_stem("t.py::test_" + "x" * 300) != gif_stem("t.py::test_" + "x" * 299)
    # A spec's GIF name is never a counterexample GIF's, whatever the key.
    assert gif_stem("t.py::test_up-falsify-seed0") != gif_stem("t.py::test_up", falsify_seed=0)


def test_report_gifs_link_each_spec_to_its_own_file(tmp_path, monkeypatch):
    import specguard.report.gifs as gifs

    def fake_gif(model, spec, path, **_):
        Path(path).write_bytes(b"GIF89a")
        return Gif(Path(path), f"{spec}, 9 steps", 2)

    monkeypatch.setattr(gifs, "load_cached", lambda spec, seed, cache: (None, None))
    monkeypatch.setattr(gifs, "write_gif", fake_gif)
    groups = ["t.py::test_[a/b]", "t.py::test_[a b]", "t.py::test_ü", "t.py::test_ö"]
    rows = [{**ROW, "group": g, "per_seed": [{"seed": 0, "successes": 1, "episodes": 1}]} for g in groups]
    written = gifs.report_gifs(tmp_path, rows, {g: g for g in groups}, tmp_path / "cache")
    assert len({g.path for g in written.values()}) == 4 and len(list(tmp_path.glob("*.gif"))) == 4
    text = markdown(rows, gifs=written)
    links = [line for line in text.splitlines() if line.startswith("![rollout of")]
    assert len(links) == 4 and len({line.split("](")[1] for line in links}) == 4
