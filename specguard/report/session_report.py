"""Reports of a ``pytest --goal-specs`` session: terminal table, JSON, Markdown, PNG.

Every function takes *rows*: the plain dicts of :meth:`specguard.pytest_plugin.judge.GoalCheck.to_row`
plus ``"verdict"`` (what pytest reported: passed, failed, xfailed, xpassed,
undecided) and optionally ``"comparison"`` and ``"curves"`` (one curve per run,
in the order of ``"per_seed"``). The Markdown links the PNG and the rollout
GIFs of :mod:`specguard.evaluation.rollout` written beside it.

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

from specguard.falsify.assertion import rule_text
from specguard.falsify.search import start_text
from specguard.stats.verdicts import FAILING_WORDS
from specguard.utils.atomic import write_atomic
from specguard.utils.text import interval_text, markdown_table

if TYPE_CHECKING:
    from specguard.report.gifs import Gif

from specguard.report.plots import plot_curves
from specguard.tree.keys import is_safety_key, label
from specguard.utils.text import render_table

__all__ = ["counterexample_lines", "family_lines", "session_markdown", "table_lines", "write_reports"]

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
    agent = row.get("agent") is not None  # an agent trained elsewhere: one run of its episodes, no training
    cells = [
        row["group"],
        label(row["goal"]),
        f"{row['success']:.0%} ({row['successes']}/{row['episodes']})",
        interval_text((lo, hi)),
        f">= {row['threshold']:g}",
        f"agent: {row['episodes']} episodes" if agent else f"{row['runs_met']}/{row['runs']}",
        _per_seed(row),
        row["verdict"],
        "-" if agent else "cached" if row["cached"] else f"{row['train_seconds']:.1f}s",
    ]
    if row.get("comparison"):
        cells.append(row["comparison"])
    return cells


HEADER = ["spec", "goal", "success", "interval", "threshold", "runs met", "per seed", "verdict", "training"]


def table_lines(rows: Sequence[Row]) -> list[str]:
    """The terminal summary: spec x goal -> success, interval, threshold, runs met, per-seed successes, verdict,
    and training time (``cached`` for a row whose runs all came from the cache); an agent's row (trained elsewhere)
    says ``agent: N episodes`` for its runs and ``-`` for its training.

    Safety rates follow their spec's goals, labelled ``path:name (safe)``; their
    success is the share of episodes without a violation. Each spec's notes follow the table, once
    (episodes that started inside the root goal, or ended before their horizon)."""
    compared = any(r.get("comparison") for r in rows)
    header = HEADER + (["vs baseline"] if compared else [])
    body = [_cells(r) + ([""] if compared and not r.get("comparison") else []) for r in _ordered(rows)]
    out = render_table(header, body)
    noted: dict[str, None] = {}  # each spec's notes once, in order (every row of a spec carries them)
    for r in _ordered(rows):
        noted.update(dict.fromkeys(f"{r['group']}: {note}" for note in r.get("notes") or ()))
    return out + list(noted)


def family_lines(rows: Sequence[Row]) -> list[str]:
    """The comparison with a baseline in words: the family-wise procedure and its level, what it flagged, the
    seeds the comparisons trained and the saved episodes agents were paired on (none without a comparison)."""
    from specguard.stats.family import procedure_text
    from specguard.stats.sequential import DEFAULT_ALPHA

    compared = [r for r in _ordered(rows) if r.get("gate")]
    if not compared:
        return []
    flagged = [f"{r['group']}::{r['goal']}" for r in compared if r["gate"].get("holm") is not None]
    specs: dict[str, tuple[int, int]] = {}  # per spec: seeds compared, seeds of its own
    agents: dict[str, int] = {}  # per agent test: the saved episodes it was paired on
    for r in compared:
        if "episodes" in r["gate"]:  # an agent's, on paired episodes (specguard.gate.saved_agent)
            agents.setdefault(r["group"], r["gate"]["episodes"])
        else:
            specs.setdefault(r["group"], (len(r["gate"]["seeds"]), len(r.get("per_seed") or [])))
    extra = sum(max(0, seeds - own) for seeds, own in specs.values())
    level = compared[0]["gate"]["level"]
    stored = round(DEFAULT_ALPHA / level)
    lines = [
        f"{procedure_text(DEFAULT_ALPHA, len(compared))}; each comparison was judged at {level:.2g}"
        f"{' while its seeds trained' if specs else ''} (Holm's first step over the {stored} goal"
        f"{'s' if stored != 1 else ''} and safety rate{'s' if stored != 1 else ''} of the baseline)",
        f"dropped: {', '.join(flagged) if flagged else 'none'}",
    ]
    if specs:
        lines.append(
            "seeds compared per spec: "
            + ", ".join(f"{group} {seeds}" for group, (seeds, _) in specs.items())
            + f" ({extra} beyond the specs' own)"
        )
    if agents:
        lines.append("saved episodes paired per agent: " + ", ".join(f"{group} {n}" for group, n in agents.items()))
    return lines


def _first_seed(rows: Sequence[Row], group: str) -> int | None:
    for r in rows:
        if r["group"] == group and r.get("per_seed"):
            return int(r["per_seed"][0]["seed"])
    return None


def session_markdown(
    rows: Sequence[Row],
    *,
    plot: str | None = None,
    gifs: Mapping[str, Gif] | None = None,
    counterexamples: Sequence[Row] = (),
    interrupted: str | None = None,
) -> str:
    """A Markdown summary ready to paste into a pull request.

    Args:
        plot: the file name of the success plot written beside the Markdown, linked as an image.
        gifs: per spec (group), its rollout GIF (linked by file name, so it must lie beside the
            Markdown) with its caption, or the note saying why there is none.
        counterexamples: the falsify items' runs (:func:`counterexample_lines`), their GIFs beside the Markdown.
        interrupted: why the session stopped before its last item, said under the counts
            (:func:`specguard.pytest_plugin.recorder.interruption`).
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
        *([f"**Incomplete**: {interrupted}; these are the goals of the items that ran.", ""] if interrupted else []),
    ]
    table = []
    for r in _ordered(rows):
        cells = _cells(r) + ([""] if compared and not r.get("comparison") else [])
        cells[1] = f"`{r['goal']}` (safe)" if is_safety_key(r["goal"]) else f"`{cells[1]}`"
        table.append(cells)
    lines += markdown_table(header, table)
    family = family_lines(rows)
    if family:
        lines += ["", "### Compared with the baseline", ""] + [f"- {line}" for line in family]
    failing = [r for r in _ordered(rows) if r["verdict"] in FAILING_WORDS]
    if failing:
        lines += ["", "### Failing goals", ""]
        for r in failing:
            safe = " (safety rate)" if is_safety_key(r["goal"]) else ""
            lines.append(f"- `{r['group']}` / `{r['goal']}`{safe}" + (f": {r['hint']}" if r.get("hint") else ""))
    adapted = _adapted_weights(rows)
    if adapted:
        lines += ["", "### Adapted weights", "", 'Weights of `All(weights="auto")` nodes when training ended:', ""]
        lines += [f"- `{group}`: {text}" for group, text in adapted.items()]
    if counterexamples:
        lines += ["", "### Counterexamples", "", *counterexample_lines(counterexamples)]
    if plot or gifs:
        lines += ["", "### Figures", ""]
    if plot:
        lines += [f"![success per goal over training, one panel per spec]({quote(plot)})", ""]
    agents = {r["group"]: r["agent"] for r in rows if r.get("agent")}
    for group, gif in (gifs or {}).items():
        seed = _first_seed(rows, group)
        head = f"**`{group}`**, seed {seed}"
        if group in agents:  # no training panel in the plot; the GIF is the agent's own episode
            head = f"**`{group}`**, agent {agents[group]!r} (no training: an agent trained elsewhere), seed {seed}"
        if gif.path is not None:
            lines += [
                f"{head}, one evaluation episode: {gif.text}",
                "",
                f"![rollout of {group}]({quote(gif.path.name)})",
                "",
            ]
        else:
            lines += [f"**`{group}`**: {gif.text}", ""]
    return "\n".join(lines).rstrip("\n") + "\n"


def counterexample_lines(runs: Sequence[Row]) -> list[str]:
    """Markdown for the falsify items' runs: per run, its verdict, shrunk start, goals missed, episode, failure
    rate, and its counterexample's GIF (linked by file name, beside the Markdown).

    Example:
        >>> run = {"group": "t.py::up", "seed": 0, "verdict": "missed", "max_rate": None, "start": {"x": 0.5},
        ...        "missed": ["up"], "origin": "found after 3 episodes", "episode": "9 steps", "rate": "",
        ...        "guided": 3, "gif": "t.py__up-falsify-seed0.gif", "gif_text": "up, 9 steps"}
        >>> print("\\n".join(counterexample_lines([run])))
        - **`t.py::up`**, seed 0: missed (a counterexample found): `x=0.5`, found after 3 episodes; missed `up`; 9 steps
        <BLANKLINE>
          ![counterexample of t.py::up, seed 0](t.py__up-falsify-seed0.gif)
        <BLANKLINE>
    """
    lines: list[str] = []
    for run in runs:
        rule = rule_text(run["max_rate"], run["start"] is not None)
        head = f"- **`{run['group']}`**, seed {run['seed']}: {run['verdict']} ({rule})"
        if run["start"] is None:
            head += f": no counterexample in {run['guided']} guided episodes"
        else:
            missed = ", ".join(f"`{m}`" for m in run["missed"])
            head += f": `{start_text(run['start'])}`, {run['origin']}; missed {missed}; {run['episode']}"
        if run["rate"]:
            head += f"; failure rate over the start space {run['rate']}"
        lines.append(head)
        if run.get("gif"):
            alt = f"counterexample of {run['group']}, seed {run['seed']}"
            lines += ["", f"  ![{alt}]({quote(run['gif'])})", ""]
        elif run["start"] is not None and run.get("gif_text"):
            lines.append(f"  ({run['gif_text']})")
    return lines


def _adapted_weights(rows: Sequence[Row]) -> dict[str, str]:
    """Per spec (group) with adapted weights, each seed's, as text (:func:`~specguard.utils.text.per_seed_text`)."""
    from specguard.utils.text import per_seed_text

    out: dict[str, str] = {}
    for r in _ordered(rows):
        text = per_seed_text((s["seed"], s.get("weights") or {}) for s in r.get("per_seed") or [])
        if text and r["group"] not in out:
            out[r["group"]] = text
    return out


def write_reports(
    directory: Path,
    rows: Sequence[Row],
    *,
    gifs: Mapping[str, Gif] | None = None,
    counterexamples: Sequence[Row] = (),
    interrupted: str | None = None,
) -> list[Path]:
    """Write ``goal-specs.json``, ``goal-specs.md`` and ``goal-specs.png`` (if there are curves).

    Args:
        gifs: per spec, its rollout GIF (already written into ``directory``) or a
            note (:func:`specguard.evaluation.rollout.report_gifs`); the Markdown links them.
        counterexamples: the falsify items' runs; the JSON lists them and the Markdown shows them with their GIFs.
        interrupted: why the session stopped before its last item (both files say it; the JSON's ``"interrupted"``
            is ``null`` for a session that ran every item).
    """
    directory.mkdir(parents=True, exist_ok=True)
    data = directory / "goal-specs.json"
    report = {"goals": list(rows), "counterexamples": list(counterexamples), "interrupted": interrupted}
    write_atomic(data, json.dumps(report, indent=1))
    png = directory / "goal-specs.png"
    plotted = plot_curves(rows, png)
    md = directory / "goal-specs.md"
    write_atomic(
        md,
        session_markdown(
            rows,
            plot=png.name if plotted else None,
            gifs=gifs,
            counterexamples=counterexamples,
            interrupted=interrupted,
        ),
    )
    return [data, md] + ([png] if plotted else [])
