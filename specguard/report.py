"""Reports of a ``pytest --goal-specs`` session: terminal table, JSON, Markdown, PNG.

Every function takes *rows*: the plain dicts of :meth:`specguard.gate.GoalCheck.to_row`
plus ``"verdict"`` (what pytest reported: passed, failed, xfailed, xpassed,
undecided) and optionally ``"comparison"`` and ``"curves"``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["markdown", "plot_curves", "table_lines", "write_reports"]

Row = dict[str, Any]


def _cells(row: Row) -> list[str]:
    lo, hi = row["interval"]
    cells = [
        row["group"],
        row["goal"],
        f"{row['success']:.0%} ({row['successes']}/{row['episodes']})",
        f"[{lo:.2f}, {hi:.2f}]",
        f">= {row['threshold']:g}",
        f"{row['runs_met']}/{row['runs']}",
        row["verdict"],
        f"{row['train_seconds']:.1f}s",
        "yes" if row["cached"] else "no",
    ]
    if row.get("comparison"):
        cells.append(row["comparison"])
    return cells


HEADER = ["spec", "goal", "success", "interval", "threshold", "runs met", "verdict", "training", "cached"]


def table_lines(rows: Sequence[Row]) -> list[str]:
    """The terminal summary: spec x goal -> success, interval, threshold, verdict, training time, cached."""
    compared = any(r.get("comparison") for r in rows)
    header = HEADER + (["vs baseline"] if compared else [])
    body = [_cells(r) + ([""] if compared and not r.get("comparison") else []) for r in rows]
    widths = [max(len(c[i]) for c in [header, *body]) for i in range(len(header))]
    out = ["  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip()]
    out.append("  ".join("-" * w for w in widths))
    out += ["  ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip() for cells in body]
    return out


def markdown(rows: Sequence[Row]) -> str:
    """A Markdown summary ready to paste into a pull request."""
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
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    for r in rows:
        cells = _cells(r) + ([""] if compared and not r.get("comparison") else [])
        cells[1] = f"`{cells[1]}`"
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    failing = [r for r in rows if r["verdict"] in ("failed", "undecided")]
    if failing:
        lines += ["", "### Failing goals", ""]
        for r in failing:
            lines.append(f"- `{r['group']}` / `{r['goal']}`" + (f": {r['hint']}" if r.get("hint") else ""))
    return "\n".join(lines) + "\n"


def plot_curves(rows: Sequence[Row], path: Path) -> bool:
    """Per-goal success over training, one panel per spec, one line per goal (the paper's Figure 4 layout).

    Success is the share of training episodes ending in the goal, averaged over
    seeds. Returns False (and writes nothing) when no row carries curves.
    """
    specs: dict[str, list[list[dict[str, Any]]]] = {}
    for r in rows:
        if r.get("curves"):
            specs.setdefault(r["group"], r["curves"])
    if not specs:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    ncols = min(4, len(specs))
    nrows = -(-len(specs) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.2 * ncols, 3.2 * nrows), squeeze=False, sharey=True)
    flat = [ax for row in axes for ax in row]
    for ax in flat[len(specs) :]:
        ax.set_visible(False)
    for ax, (group, curves) in zip(flat, specs.items()):
        goals = sorted({g for run in curves for point in run for g in point["success"]})
        for goal in goals:
            by_step: dict[int, list[float]] = {}
            for run in curves:
                for point in run:
                    if goal in point["success"]:
                        by_step.setdefault(point["timesteps"], []).append(point["success"][goal])
            steps = sorted(by_step)
            ax.plot(steps, [sum(by_step[s]) / len(by_step[s]) for s in steps], label=goal, marker=".")
        ax.set_title(group.split("::", 1)[-1], fontsize=9)
        ax.set_xlabel("training steps")
        ax.xaxis.set_major_locator(MaxNLocator(4))
        ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
        if goals:
            ax.legend(fontsize=7)
    for row in axes:
        row[0].set_ylabel("success (training episodes)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def write_reports(directory: Path, rows: Sequence[Row]) -> list[Path]:
    """Write ``goal-specs.json``, ``goal-specs.md`` and ``goal-specs.png`` (if there are curves)."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    data = directory / "goal-specs.json"
    data.write_text(json.dumps({"goals": list(rows)}, indent=1))
    written.append(data)
    md = directory / "goal-specs.md"
    md.write_text(markdown(rows))
    written.append(md)
    png = directory / "goal-specs.png"
    if plot_curves(rows, png):
        written.append(png)
    return written
