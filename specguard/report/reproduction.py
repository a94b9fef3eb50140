"""The reproduction document: per case, a table beside the paper's figures, and one plot per case.

The Markdown table has, per case and variant: the root goal's mean success
over the seeds' evaluation episodes with its interval, the runs met (each
run's verdict, as every door judges it) out of the seeds, the paper's figure, and
the budget trained. The plots follow the paper's Figures 4 and 5: one PNG per
case, one panel per spec, success per goal over training (each seed thin,
their mean bold), thresholds as dashed lines.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from specguard.engine.reproduce import CaseStudy, Reproduction
from specguard.engine.spec_result import SpecResult
from specguard.error import SpecError
from specguard.report.plots import plot_curves
from specguard.stats.intervals import success_interval
from specguard.stats.verdicts import RunVerdict
from specguard.utils.atomic import write_atomic
from specguard.utils.text import interval_text, markdown_table, per_seed_text

__all__ = [
    "case_section",
    "replot",
    "reproduction_markdown",
    "rows_for_plots",
    "sections",
    "write_markdown",
    "write_plots",
]


def _steps(n: int) -> str:
    """``128``, ``30k``, ``1.016M``: steps as read in a table."""
    if n >= 1_000_000:
        return f"{n / 1_000_000:g}M"
    return f"{n / 1000:g}k" if n >= 1000 else str(n)


def _root_row(case: CaseStudy, key: str, result: SpecResult, seeds: int) -> tuple[str, ...]:
    spec = case.specs[key]
    path = next(iter(spec.tree.walk()))[0]  # the root comes first
    k, n = result.success(path) if result.runs else (0, 0)
    mean = f"{k / n:.0%} ({k}/{n})" if n else "-"
    interval = interval_text(success_interval(k, n, spec.confidence)) if n else "-"
    threshold = spec.thresholds.get(path)
    reached = "-"
    if threshold is not None and path in result.goals:  # the engine's verdict of each run, as every door judges
        met = result.goals[path].runs.count(RunVerdict.MET)
        reached = f"{met}/{seeds} (>= {threshold:g})"
    if result.errors:
        reached += f"; {len(result.errors)} seeds failed"
    budget = "/".join(_steps(s) for s in sorted({r.timesteps for r in result.runs})) or "-"
    return (key, mean, interval, reached, case.paper.get(key, "-"), budget)


TITLE = "# Reproducing the paper's case studies"
INTRO = [
    "Every spec trained on its section's number of seeds at its whole budget (no anytime verdicts: the curves "
    "need every step), times its case's budget scale, each seed evaluated on its own deterministic episodes "
    "(seeds disjoint from training). Each case names the command, machine, date and specguard version that "
    "made it: `specguard reproduce` rewrites the sections of the cases it is given and keeps the others, so a "
    "long case can be remade on its own.",
    "",
    "Columns: the root goal's success pooled over every seed's evaluation episodes, with its 95% interval; "
    "the runs met: runs whose own root-goal success interval lies at or above the spec's threshold, as "
    "`specguard run` and `pytest --goal-specs` judge a run (sections under the earlier heading 'runs reaching "
    "the threshold' counted a run whose point estimate reached it); the paper's reported figure "
    "(10 runs at its budgets); the steps each run trained.",
]
HEADER = ("spec", "root success", "95% interval", "runs met", "paper", "steps per run")


def case_section(reproduction: Reproduction, case: CaseStudy, images: Mapping[str, str]) -> str:
    """One case's section: how it was made, its table, its adapted weights, the hint of each goal that did not pass
    (:attr:`SpecResult.hints <specguard.engine.spec_result.SpecResult.hints>`, as every door prints them) and its
    plot."""
    r = reproduction
    lines = [
        f"## {case.name}",
        "",
        f"Made with `{r.command}` on {r.date}, on {r.machine}, specguard {r.version}. "
        f"{r.seeds} seeds per spec, budget scale {r.scales[case.name]:g}x.",
        "",
    ]
    rows = [_root_row(case, key, r.results[case.name][key], r.seeds) for key in case.specs]
    lines += markdown_table(HEADER, rows)
    for key in case.specs:
        seeds = per_seed_text((run.seed, run.weights) for run in r.results[case.name][key].runs)
        if seeds:
            lines += ["", f"Adapted weights of ({key}) when training ended: {seeds}."]
    for key in case.specs:
        for path, hint in r.results[case.name][key].hints.items():
            lines += ["", f"Hint for ({key}) `{path}`: {hint}"]
    if case.name in images:
        lines += ["", f"![{case.name}: success per goal over training]({images[case.name]})"]
    return "\n".join(lines) + "\n"


def sections(text: str) -> dict[str, str]:
    """The case sections of a reproduction document, by case name, in document order.

    A section runs from its ``## name`` line to the next one (or the end).

    Example:
        >>> list(sections("# T\\n\\nintro\\n## a\\n\\nrow\\n## b\\n"))
        ['a', 'b']
    """
    found: dict[str, list[str]] = {}
    current: list[str] | None = None
    for line in text.splitlines():
        if line.startswith("## "):
            current = found.setdefault(line[3:].strip(), [])
        if current is not None:
            current.append(line)
    return {name: "\n".join(lines).rstrip("\n") + "\n" for name, lines in found.items()}


def reproduction_markdown(reproduction: Reproduction, images: Mapping[str, str], previous: str = "") -> str:
    """The reproduction document: the reproduced cases' sections, and ``previous``'s sections of other cases.

    A case keeps its place in ``previous``; cases new to it come after.
    """
    merged = sections(previous)
    for case in reproduction.cases:
        merged[case.name] = case_section(reproduction, case, images)
    return "\n".join([TITLE, "", *INTRO, "", *merged.values()])


def rows_for_plots(case: CaseStudy, results: Mapping[str, SpecResult]) -> list[dict[str, Any]]:
    """Report rows (:mod:`specguard.report.session_report`) of every goal of every spec of a case, with their curves."""
    rows = []
    for key, spec in case.specs.items():
        result = results[key]
        if not result.runs:
            continue
        for path in result.runs[0].successes:
            rows.append(
                {
                    "group": f"{case.name} ({key})",
                    "goal": path,
                    "threshold": spec.thresholds.get(path),
                    "curves": [run.curve for run in result.runs],
                    "per_seed": [{"seed": run.seed} for run in result.runs],
                }
            )
    return rows


def write_plots(reproduction: Reproduction, folder: Path) -> dict[str, str]:
    """One PNG per case in ``folder``, drawn from its curve data written beside it as JSON.

    The JSON (``reproduction-<case>.json``: every goal's per-run curves and
    threshold) is small and committed with the PNG, so :func:`replot` redraws a
    figure after a change to the plotting without training anything again.
    Returns each case's image path relative to ``folder.parent``.
    """
    folder.mkdir(parents=True, exist_ok=True)
    images = {}
    for case in reproduction.cases:
        rows = [_plotted(row) for row in rows_for_plots(case, reproduction.results[case.name])]
        data = folder / f"reproduction-{case.name}.json"
        write_atomic(data, json.dumps(rows, sort_keys=True) + "\n")  # the figure is drawn from exactly this
        if plot_curves(rows, data.with_suffix(".png")):
            images[case.name] = f"{folder.name}/{data.with_suffix('.png').name}"
    return images


def _plotted(row: dict[str, Any]) -> dict[str, Any]:
    """A plot row with only what its figure draws: its own goal's success per curve point, to 4 decimals."""
    goal = row["goal"]

    def point(p: dict[str, Any]) -> dict[str, Any]:
        kept: dict[str, Any] = {"timesteps": p["timesteps"], "success": {}}
        for part in ("success", "evaluation"):
            if goal in (p.get(part) or {}):
                kept[part] = {goal: round(p[part][goal], 4)}
        return kept

    return {**row, "curves": [[point(p) for p in curve] for curve in row["curves"]]}


def replot(folder: Path) -> list[Path]:
    """Redraw every ``reproduction-<case>.png`` in ``folder`` from the curve data beside it; returns the PNGs.

    Raises:
        SpecError: a curve file that is not the JSON :func:`write_plots` writes.
    """
    drawn = []
    for data in sorted(folder.glob("reproduction-*.json")):
        try:
            rows = json.loads(data.read_text(encoding="utf-8"))
        except (OSError, ValueError) as e:
            raise SpecError(f"{data}: cannot read the curve data ({e})") from None
        if not isinstance(rows, list) or not all(isinstance(r, dict) and "curves" in r for r in rows):
            raise SpecError(f"{data}: expected a list of rows with curves, as specguard reproduce writes")
        if plot_curves(rows, data.with_suffix(".png")):
            drawn.append(data.with_suffix(".png"))
    return drawn


def write_markdown(reproduction: Reproduction, out: Path) -> Path:
    """Write the plots beside ``out`` (in ``images/``) and the Markdown tables to ``out``.

    Sections of cases not reproduced this time, already in ``out``, are kept (:func:`reproduction_markdown`).
    """
    out.parent.mkdir(parents=True, exist_ok=True)
    images = write_plots(reproduction, out.parent / "images")
    previous = out.read_text() if out.exists() else ""
    write_atomic(out, reproduction_markdown(reproduction, images, previous))
    return out
