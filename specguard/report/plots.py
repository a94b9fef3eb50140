"""Figures of learning curves: success per goal over training, one panel per spec, seeds thin and their mean bold."""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from specguard.tree.keys import label
from specguard.utils.atomic import write_atomic

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["curves_figure", "plot_curves"]

Row = dict[str, Any]


def _goals(rows: Sequence[Row]) -> dict[str, dict[str, Any]]:
    """Per spec (group), in order of appearance: its curves, their seeds and the thresholds of its asserted goals;
    a group that trained nothing (an agent trained elsewhere, ``"agent"``; curves without a point) has no panel."""
    specs: dict[str, dict[str, Any]] = {}
    for r in rows:
        if r.get("agent") or not any(r.get("curves") or ()):
            continue
        entry = specs.setdefault(group := r["group"], {"curves": r["curves"], "seeds": None, "thresholds": {}})
        if entry["seeds"] is None:
            seeds = [s["seed"] for s in r.get("per_seed") or []]  # per_seed and curves follow the runs' order
            entry["seeds"] = list(seeds) if len(seeds) == len(r["curves"]) else list(range(len(r["curves"])))
        specs[group]["thresholds"][r["goal"]] = r["threshold"]
    return specs


def curves_figure(rows: Sequence[Row]) -> Figure | None:
    """The success plot as a matplotlib ``Figure`` (no pyplot, no backend switch); ``None`` without curves.

    One panel per spec that trained (the paper's Figure 4 layout); an agent trained elsewhere has none.
    Per asserted goal, in one colour: each seed's success over its training episodes as a thin line
    labelled with the seed, the seeds' mean in bold (drawn only at steps where
    every seed has a point: up to where the first seed stopped), the goal's threshold as a
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
    fig = Figure(figsize=(4.6 * ncols, 4.2 * nrows))
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
            # The mean only where every seed has a point: a seed that stopped early (anytime verdicts) would
            # otherwise leave the mean to the seeds still training.
            plotted = sum(1 for run in curves if any(goal in p["success"] for p in run))
            steps = sorted(s for s, ys in by_step.items() if len(ys) == plotted)
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
        seeds_text = "seeds (s<n>)" if len(labelled) == len(ends) else "seeds"
        labels.append(f"{seeds_text}; bold: mean while every seed trains")
        if evaluated:
            handles.append(Line2D([], [], color="grey", linestyle="none", marker="o", markerfacecolor="white"))
            labels.append("evaluation")
        # Below the axes, never over the curves.
        ax.legend(handles, labels, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=2, frameon=False)
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
    image = io.BytesIO()
    fig.savefig(image, format="png", dpi=110)
    write_atomic(path, image.getvalue())
    return True
