"""``specguard reproduce``: every case and variant at a chosen size, a table beside the paper's figures, plots.

Each file given is a case study (e.g. ``example_specs/pendulum.py``): its
specs are its module-level ``Spec`` objects and dicts of specs (as for
``specguard run``), and its optional ``PAPER`` dict gives the paper's reported
figure per spec key. Every spec is trained on ``seeds`` seeds at its whole
budget times ``budget_scale`` (no anytime verdicts: learning curves need the
whole budget), through the run cache, so an interrupted reproduction resumes
where it stopped. Specs train side by side, one process each, ``workers`` at
a time, so every core given is busy. An interruption (Ctrl-C) drops the specs
not started and stops the running ones at once: their unfinished seeds store
nothing, every finished run stays cached.

The Markdown table has, per case and variant: the root goal's mean success
over the seeds' evaluation episodes with its interval, the runs whose root
success reached the spec's threshold out of the seeds, the paper's figure, and
the budget trained. The plots follow the paper's Figures 4 and 5: one PNG per
case, one panel per spec, success per goal over training (each seed thin,
their mean bold), thresholds as dashed lines.
"""

from __future__ import annotations

import dataclasses
import datetime
import os
import platform
import threading
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from specguard.engine.budget import Budget
from specguard.engine.fingerprint import versions
from specguard.engine.progress import ProgressEvent
from specguard.engine.run import SpecResult, run_spec
from specguard.engine.spec import Spec
from specguard.engine.specfiles import import_file, load_objects
from specguard.engine.workers import resolve_workers, stopping_all_tasks
from specguard.error import SpecError
from specguard.stats.intervals import success_interval
from specguard.utils.text import per_seed_text

__all__ = ["Case", "Reproduction", "load_case", "reproduce", "write_markdown", "write_plots"]


@dataclass(frozen=True)
class Case:
    """A case study: its specs by key and the paper's figure per key."""

    name: str
    specs: dict[str, Spec]
    paper: dict[str, str]


@dataclass
class Reproduction:
    """What a reproduction measured: per case, per spec key, the result."""

    cases: list[Case]
    results: dict[str, dict[str, SpecResult]]
    seeds: int
    scales: dict[str, float]  # per case: the factor its budgets were trained at
    command: str
    date: str
    machine: str
    version: str  # specguard's version and source digest (every run key holds it)


def load_case(path: str) -> Case:
    """The case study a file defines: its specs (``specguard run``'s rule) and its ``PAPER`` figures.

    Raises:
        SpecError: the file cannot be imported or defines no specs.
    """

    specs = load_objects(path)
    paper = getattr(import_file(Path(path)), "PAPER", {})
    if not isinstance(paper, Mapping):
        raise SpecError(f"{path}: PAPER must be a dict {{spec key: the paper's figure}}, got {type(paper).__name__}")
    return Case(Path(path).stem, dict(specs), {str(k): str(v) for k, v in paper.items()})


def sized(spec: Spec, seeds: int, budget_scale: float) -> Spec:
    """The spec at the reproduction's size: ``seeds`` runs, the whole (scaled) budget, no quorum to meet early."""
    scaled = spec.scaled(budget_scale, checkpoints=1)
    budget = dataclasses.replace(scaled.budget, min_seeds=seeds, max_seeds=seeds)
    assert isinstance(budget, Budget)
    return dataclasses.replace(scaled, budget=budget, quorum=None)


def reproduce(
    cases: Sequence[Case],
    *,
    seeds: int = 5,
    budget_scale: float = 1.0,
    case_scales: Mapping[str, float] | None = None,
    workers: int | str = 2,
    cache_dir: str | Path | None = ".specguard/cache",
    progress: Callable[[ProgressEvent], None] | None = None,
    command: str = "",
) -> Reproduction:
    """Train every spec of every case at ``seeds`` seeds, ``workers`` specs at a time.

    ``case_scales`` (``{case name: factor}``) replaces ``budget_scale`` for
    some cases, e.g. a long case at half its budget. Every spec runs (no stop
    at the first miss); a spec whose seeds fail keeps its errors in its result.

    Raises:
        SpecError: ``case_scales`` names a case that is not given, or ``workers`` is
            not a worker count (:func:`specguard.engine.workers.resolve_workers`).
    """
    workers = resolve_workers(workers)
    names = [case.name for case in cases]
    unknown = sorted(set(case_scales or {}) - set(names))
    if unknown:
        raise SpecError(f"case scale: no case named {', '.join(map(repr, unknown))}; the cases are {names}")
    scales = {name: float((case_scales or {}).get(name, budget_scale)) for name in names}
    say = progress or (lambda event: None)
    lock = threading.Lock()

    def tell(event: ProgressEvent) -> None:
        with lock:
            say(event)

    jobs = [(case, key, sized(spec, seeds, scales[case.name])) for case in cases for key, spec in case.specs.items()]
    results: dict[str, dict[str, SpecResult]] = {case.name: {} for case in cases}
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        futures = {
            (case.name, key): pool.submit(run_spec, spec, workers=1, cache_dir=cache_dir, progress=tell)
            for case, key, spec in jobs
        }
        for (name, key), future in futures.items():
            results[name][key] = future.result()
    except BaseException:
        # Ctrl-C reaches only this thread: drop the specs not started, stop the running ones (their
        # seeds' processes end and nothing partial is cached; finished runs are) and wait for them.
        pool.shutdown(wait=False, cancel_futures=True)
        with stopping_all_tasks():
            pool.shutdown(wait=True)
        raise
    pool.shutdown(wait=True)
    return Reproduction(
        cases=list(cases),
        results=results,
        seeds=seeds,
        scales=scales,
        command=command,
        date=datetime.date.today().isoformat(),
        machine=machine(workers),
        version=versions()["specguard"],
    )


def machine(workers: int) -> str:
    """The machine in words: CPU, cores, and the workers used."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{cpu}, {cores} cores, {workers} training processes, {platform.system()} {platform.release()}"


def _steps(n: int) -> str:
    """``128``, ``30k``, ``1.016M``: steps as read in a table."""
    if n >= 1_000_000:
        return f"{n / 1_000_000:g}M"
    return f"{n / 1000:g}k" if n >= 1000 else str(n)


def _root_row(case: Case, key: str, result: SpecResult, seeds: int) -> tuple[str, ...]:
    spec = case.specs[key]
    path = next(iter(spec.tree.walk()))[0]  # the root comes first
    k, n = result.success(path) if result.runs else (0, 0)
    mean = f"{k / n:.0%} ({k}/{n})" if n else "-"
    interval = "[{:.2f}, {:.2f}]".format(*success_interval(k, n, spec.confidence)) if n else "-"
    threshold = spec.thresholds.get(path)
    reached = "-"
    if threshold is not None:
        met = sum(1 for r in result.runs if r.successes[path] >= threshold * r.episodes)
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
    "the runs whose own root-goal success reached the spec's threshold; the paper's reported figure "
    "(10 runs at its budgets); the steps each run trained.",
]
HEADER = ("spec", "root success", "95% interval", "runs reaching the threshold", "paper", "steps per run")


def case_section(reproduction: Reproduction, case: Case, images: Mapping[str, str]) -> str:
    """One case's section: how it was made, its table, its adapted weights and its plot."""
    r = reproduction
    lines = [
        f"## {case.name}",
        "",
        f"Made with `{r.command}` on {r.date}, on {r.machine}, specguard {r.version}. "
        f"{r.seeds} seeds per spec, budget scale {r.scales[case.name]:g}x.",
        "",
    ]
    rows = [_root_row(case, key, r.results[case.name][key], r.seeds) for key in case.specs]
    lines += ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    for key in case.specs:
        seeds = per_seed_text((run.seed, run.weights) for run in r.results[case.name][key].runs)
        if seeds:
            lines += ["", f"Adapted weights of ({key}) when training ended: {seeds}."]
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


def markdown(reproduction: Reproduction, images: Mapping[str, str], previous: str = "") -> str:
    """The reproduction document: the reproduced cases' sections, and ``previous``'s sections of other cases.

    A case keeps its place in ``previous``; cases new to it come after.
    """
    merged = sections(previous)
    for case in reproduction.cases:
        merged[case.name] = case_section(reproduction, case, images)
    return "\n".join([TITLE, "", *INTRO, "", *merged.values()])


def rows_for_plots(case: Case, results: Mapping[str, SpecResult]) -> list[dict[str, Any]]:
    """Report rows (:mod:`specguard.report.session`) of every goal of every spec of a case, with their curves."""
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
    """One PNG per case in ``folder``; returns each case's image path relative to ``folder.parent``."""
    from specguard.report.session import plot_curves

    folder.mkdir(parents=True, exist_ok=True)
    images = {}
    for case in reproduction.cases:
        png = folder / f"reproduction-{case.name}.png"
        if plot_curves(rows_for_plots(case, reproduction.results[case.name]), png):
            images[case.name] = f"{folder.name}/{png.name}"
    return images


def write_markdown(reproduction: Reproduction, out: Path) -> Path:
    """Write the plots beside ``out`` (in ``images/``) and the Markdown tables to ``out``.

    Sections of cases not reproduced this time, already in ``out``, are kept (:func:`markdown`).
    """
    out.parent.mkdir(parents=True, exist_ok=True)
    images = write_plots(reproduction, out.parent / "images")
    previous = out.read_text() if out.exists() else ""
    out.write_text(markdown(reproduction, images, previous))
    return out
