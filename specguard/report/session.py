"""Reports of a ``pytest --goal-specs`` session: terminal table, JSON, Markdown, PNG.

Every function takes *rows*: the plain dicts of :meth:`specguard.pytest_plugin.gate.GoalCheck.to_row`
plus ``"verdict"`` (what pytest reported: passed, failed, xfailed, xpassed,
undecided) and optionally ``"comparison"`` and ``"curves"`` (one curve per run,
in the order of ``"per_seed"``). The Markdown links the PNG and the rollout
GIFs of :mod:`specguard.engine.rollout` written beside it.

A row whose goal is a safety key ``path:name`` (its ``"kind"`` is
``"safety"``) is a safety rate: tables label it ``path:name (safe)`` and list
it after its spec's goals.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any
from urllib.parse import quote

from specguard.utils.text import interval_text, markdown_table

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from specguard.report.gifs import Gif

from specguard.tree.keys import is_safety_key, label
from specguard.utils.text import render_table

__all__ = ["curves_figure", "markdown", "plot_curves", "table_lines", "write_reports"]

Row = dict[str, Any]


def _per_seed(row: Row) -> str:
    """Per-seed successes, compactly: ``29/30, 27/30`` (a seed that crashed: ``error``)."""
    cells = [f"{s['successes']}/{s['episodes']}" for s in row.get("per_seed") or []]
    cells += ["error"] * len(row.get("errors") or {})
    return ", ".join(cells) or "-"


def _ordered(rows: Sequence[Row]) -> list[Row]:
    """Rows by spec in order of first appearance, each spec's goals before its safety rates (otherwise stable)."""
    first: dict[str, int] = {}
    for r in rows:
        first.setdefault(r["group"], len(first))
    return sorted(rows, key=lambda r: (first[r["group"]], is_safety_key(r["goal"])))


def _cells(row: Row) -> list[str]:
    lo, hi = row["interval"]
    cells = [
        row["group"],
        label(row["goal"]),
        f"{row['success']:.0%} ({row['successes']}/{row['episodes']})",
        interval_text((lo, hi)),
        f">= {row['threshold']:g}",
        f"{row['runs_met']}/{row['runs']}",
        _per_seed(row),
        row["verdict"],
        "cached" if row["cached"] else f"{row['train_seconds']:.1f}s",
    ]
    if row.get("comparison"):
        cells.append(row["comparison"])
    return cells


HEADER = ["spec", "goal", "success", "interval", "threshold", "runs met", "per seed", "verdict", "training"]


def table_lines(rows: Sequence[Row]) -> list[str]:
    """The terminal summary: spec x goal -> success, interval, threshold, runs met, per-seed successes, verdict,
    and training time (``cached`` for a row whose runs all came from the cache).

    Safety rates follow their spec's goals, labelled ``path:name (safe)``; their
    success is the share of episodes without a violation."""
    compared = any(r.get("comparison") for r in rows)
    header = HEADER + (["vs baseline"] if compared else [])
    body = [_cells(r) + ([""] if compared and not r.get("comparison") else []) for r in _ordered(rows)]
    out = render_table(header, body)
    return out


def _first_seed(rows: Sequence[Row], group: str) -> int | None:
    for r in rows:
        if r["group"] == group and r.get("per_seed"):
            return int(r["per_seed"][0]["seed"])
    return None


def markdown(rows: Sequence[Row], *, plot: str | None = None, gifs: Mapping[str, Gif] | None = None) -> str:
    """A Markdown summary ready to paste into a pull request.

    Args:
        plot: the file name of the success plot written beside the Markdown, linked as an image.
        gifs: per spec (group), its rollout GIF (linked by file name, so it must lie beside the
            Markdown) with its caption, or the note saying why there is none.
    """
    compared = any(r.get("comparison") for r in rows)
    header = HEADER + (["vs baseline"] if compared else [])
    counts: dict[str, int] = {}
    for r in rows:
        counts[r["verdict"]] = counts.get(r["verdict"], 0) + 1
    lines = [
        "## specguard goal specs",
        "",
        ", ".join(f"{n} {v}" for v, n in sorted(counts.items())) + f" ({len(rows)} goals)",
        "",
    ]
    table = []
    for r in _ordered(rows):
        cells = _cells(r) + ([""] if compared and not r.get("comparison") else [])
        cells[1] = f"`{r['goal']}` (safe)" if is_safety_key(r["goal"]) else f"`{cells[1]}`"
        table.append(cells)
    lines += markdown_table(header, table)
    failing = [r for r in _ordered(rows) if r["verdict"] in ("failed", "undecided")]
    if failing:
        lines += ["", "### Failing goals", ""]
        for r in failing:
            safe = " (safety rate)" if is_safety_key(r["goal"]) else ""
            lines.append(f"- `{r['group']}` / `{r['goal']}`{safe}" + (f": {r['hint']}" if r.get("hint") else ""))
    adapted = _adapted_weights(rows)
    if adapted:
        lines += ["", "### Adapted weights", "", 'Weights of `All(weights="auto")` nodes when training ended:', ""]
        lines += [f"- `{group}`: {text}" for group, text in adapted.items()]
    if plot or gifs:
        lines += ["", "### Figures", ""]
    if plot:
        lines += [f"![success per goal over training, one panel per spec]({quote(plot)})", ""]
    for group, gif in (gifs or {}).items():
        seed = _first_seed(rows, group)
        if gif.path is not None:
            lines += [
                f"**`{group}`**, seed {seed}, one evaluation episode: {gif.text}",
                "",
                f"![rollout of {group}]({quote(gif.path.name)})",
                "",
            ]
        else:
            lines += [f"**`{group}`**: {gif.text}", ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def _adapted_weights(rows: Sequence[Row]) -> dict[str, str]:
    """Per spec (group) with adapted weights, each seed's, as text (:func:`~specguard.utils.text.per_seed_text`)."""
    from specguard.utils.text import per_seed_text

    out: dict[str, str] = {}
    for r in _ordered(rows):
        text = per_seed_text((s["seed"], s.get("weights") or {}) for s in r.get("per_seed") or [])
        if text and r["group"] not in out:
            out[r["group"]] = text
    return out


def _goals(rows: Sequence[Row]) -> dict[str, dict[str, Any]]:
    """Per spec (group), in order of appearance: its curves, their seeds and the thresholds of its asserted goals."""
    specs: dict[str, dict[str, Any]] = {}
    for r in rows:
        if not r.get("curves"):
            continue
        entry = specs.setdefault(group := r["group"], {"curves": r["curves"], "seeds": None, "thresholds": {}})
        if entry["seeds"] is None:
            seeds = [s["seed"] for s in r.get("per_seed") or []]  # per_seed and curves follow the runs' order
            entry["seeds"] = list(seeds) if len(seeds) == len(r["curves"]) else list(range(len(r["curves"])))
        specs[group]["thresholds"][r["goal"]] = r["threshold"]
    return specs


def curves_figure(rows: Sequence[Row]) -> Figure | None:
    """The success plot as a matplotlib ``Figure`` (no pyplot, no backend switch); ``None`` without curves.

    One panel per spec (the paper's Figure 4 layout). Per asserted goal, in one
    colour: each seed's success over its training episodes as a thin line
    labelled with the seed, the seeds' mean in bold, the goal's threshold as a
    dashed horizontal line and, where curve points carry ``"evaluation"``, the
    seeds' mean evaluation success as markers. Every artist has a ``gid``:
    ``"<goal>:seed <n>"``, ``"<goal>:mean"``, ``"<goal>:threshold"``, ``"<goal>:evaluation"``.
    """
    specs = _goals(rows)
    if not specs:
        return None
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    ncols = min(4, len(specs))
    nrows = -(-len(specs) // ncols)
    fig = Figure(figsize=(4.6 * ncols, 3.4 * nrows))
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey=True)
    flat = [ax for row in axes for ax in row]
    for ax in flat[len(specs) :]:
        ax.set_visible(False)
    for ax, (group, entry) in zip(flat, specs.items()):
        curves, seeds, thresholds = entry["curves"], entry["seeds"], entry["thresholds"]
        goals = sorted(thresholds)
        right = 0
        evaluated = False
        ends: list[tuple[float, int, str, str, str]] = []  # each seed's number at its curve's end
        for i, goal in enumerate(goals):
            colour = f"C{i % 10}"
            by_step: dict[int, list[float]] = {}
            evals: dict[int, list[float]] = {}
            for seed, run in zip(seeds, curves):
                points = [p for p in run if goal in p["success"]]
                xs = [p["timesteps"] for p in points]
                ys = [p["success"][goal] for p in points]
                for p in run:
                    if goal in (p.get("evaluation") or {}):
                        evals.setdefault(p["timesteps"], []).append(p["evaluation"][goal])
                for x, y in zip(xs, ys):
                    by_step.setdefault(x, []).append(y)
                if not xs:
                    continue
                right = max(right, xs[-1])
                ax.plot(xs, ys, color=colour, linewidth=0.8, alpha=0.45, gid=f"{goal}:seed {seed}")
                ends.append((ys[-1], xs[-1], f"s{seed}", colour, f"{goal}:seed {seed}:label"))
            steps = sorted(by_step)
            if steps:
                mean = [sum(by_step[s]) / len(by_step[s]) for s in steps]
                ax.plot(steps, mean, color=colour, linewidth=2.2, label=label(goal), gid=f"{goal}:mean")
            if thresholds[goal] is not None:  # a goal plotted without a threshold (specguard reproduce)
                ax.axhline(thresholds[goal], color=colour, linestyle="--", linewidth=1.0, gid=f"{goal}:threshold")
            if evals:
                evaluated = True
                xs = sorted(evals)
                ax.plot(
                    xs,
                    [sum(evals[x]) / len(evals[x]) for x in xs],
                    linestyle="none",
                    marker="o",
                    markersize=5,
                    markerfacecolor="white",
                    color=colour,
                    gid=f"{goal}:evaluation",
                )
        labelled = _label_heights([y for y, *_ in sorted(ends, reverse=True)])
        for (_, x, text, colour, gid), y in zip(sorted(ends, reverse=True), labelled):
            ax.text(x, y, f" {text}", fontsize=6, color=colour, va="center", ha="left", gid=gid)
        ax.set_title(group.split("::", 1)[-1], fontsize=9)
        ax.set_xlabel("training steps")
        ax.xaxis.set_major_locator(MaxNLocator(4))
        if right:
            ax.set_xlim(0, right * 1.1)  # room for the seed labels
        ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        handles.append(Line2D([], [], color="grey", linestyle="--", linewidth=1.0))
        labels.append("threshold")
        handles.append(Line2D([], [], color="grey", linewidth=0.8, alpha=0.6))
        labels.append("seeds (s<n>); bold: mean" if len(labelled) == len(ends) else "seeds; bold: mean")
        if evaluated:
            handles.append(Line2D([], [], color="grey", linestyle="none", marker="o", markerfacecolor="white"))
            labels.append("evaluation")
        ax.legend(handles, labels, fontsize=7)
    for row in axes:
        row[0].set_ylabel("success (training episodes)")
    fig.tight_layout()
    return fig


LABEL_GAP = 0.045  # the height of one seed label, in success units


def _label_heights(ends: Sequence[float], bottom: float = -0.05) -> list[float]:
    """Heights for seed labels at curve ends given from the highest down, or ``[]`` when they do not all fit.

    Labels of curves ending together stack down instead of overlapping; when the
    stack would leave the axes (many goals times many seeds), the seeds go
    unlabelled rather than piling up below the plot.

    Example:
        >>> [round(y, 3) for y in _label_heights([1.0, 1.0, 0.5])]
        [1.0, 0.955, 0.5]
        >>> _label_heights([0.0] * 3)
        []
    """
    heights: list[float] = []
    ceiling = 2.0
    for y in ends:
        ceiling = min(y, ceiling - LABEL_GAP)
        heights.append(ceiling)
    return heights if not heights or heights[-1] >= bottom else []


def plot_curves(rows: Sequence[Row], path: Path) -> bool:
    """Write :func:`curves_figure` as a PNG to ``path``; returns False (and writes nothing) when no row has curves.

    Uses the Agg canvas directly, so the user's matplotlib backend is left as it was.
    """
    fig = curves_figure(rows)
    if fig is None:
        return False
    fig.savefig(path, dpi=110)
    return True


def write_reports(directory: Path, rows: Sequence[Row], *, gifs: Mapping[str, Gif] | None = None) -> list[Path]:
    """Write ``goal-specs.json``, ``goal-specs.md`` and ``goal-specs.png`` (if there are curves).

    Args:
        gifs: per spec, its rollout GIF (already written into ``directory``) or a
            note (:func:`specguard.engine.rollout.report_gifs`); the Markdown links them.
    """
    directory.mkdir(parents=True, exist_ok=True)
    data = directory / "goal-specs.json"
    data.write_text(json.dumps({"goals": list(rows)}, indent=1))
    png = directory / "goal-specs.png"
    plotted = plot_curves(rows, png)
    md = directory / "goal-specs.md"
    md.write_text(markdown(rows, plot=png.name if plotted else None, gifs=gifs))
    return [data, md] + ([png] if plotted else [])
