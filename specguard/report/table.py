"""A spec result as the table ``specguard run`` prints: per goal, its success, interval, threshold, runs and word.

:func:`table` reads a :class:`~specguard.engine.spec_result.SpecResult` and
nothing else, so a result read back from JSON
(:meth:`~specguard.engine.spec_result.SpecResult.from_dict`) prints the same
table as the one just run.

Example:
    >>> from specguard.engine.spec_result import GoalVerdict, SpecResult
    >>> from specguard.stats.verdicts import QuorumVerdict, RunVerdict
    >>> from specguard.training.result import RunResult
    >>> run = RunResult(spec="p", seed=0, timesteps=64, episodes=10, successes={"p": 9}, train_seconds=1.0)
    >>> goal = GoalVerdict("p", 0.5, 1, [RunVerdict.MET], QuorumVerdict.PASSED, 9, 10, (0.555, 0.997))
    >>> print(table(SpecResult(spec="p", runs=[run], goals={"p": goal})))
    goal  success     95% interval  threshold  runs met      verdict
    ----  ----------  ------------  ---------  ------------  -------
    p     90% (9/10)  [0.55, 1.00]  >= 0.5     1/1 (need 1)  passed
"""

from __future__ import annotations

from specguard.engine.spec_result import SpecResult
from specguard.stats.intervals import success_interval
from specguard.stats.verdicts import RunVerdict
from specguard.tree.keys import GOAL, kind, label
from specguard.utils.text import digests_text, interval_text, numerics_text, render_table, weights_text

__all__ = ["table"]


def table(result: SpecResult) -> str:
    """A per-goal table of ``result``: pooled success with interval, threshold, runs met, verdict word (no runs met
    for an agent's result: its episodes are one run that trained nothing).

    Goals first, then the safety rates, labelled ``path:name (safe)``; a measured goal without a
    threshold shows ``-`` for what it lacks. Under the table: the result's notes (the episodes that
    started inside the root goal, or ended before their horizon, how many), the weights each run
    adapted, each run's weights digest (its first 12 hex digits: ``weights seed 0: 3c61144ad8e8; seed 1: ...``,
    :attr:`RunResult.weights_digest <specguard.training.result.RunResult>`), the seeds that failed, and last what
    to try for each goal that did not pass (:attr:`SpecResult.hints`, the hint of the pytest item's failure).
    """
    paths = [p for r in result.runs[:1] for p in r.successes] or list(result.goals)
    paths.sort(key=lambda p: kind(p) != GOAL)  # stable: each kind keeps its order
    header: tuple[str, ...] = (
        "goal",
        "success",
        f"{result.confidence:.0%} interval",
        "threshold",
        "runs met",
        "verdict",
    )
    agent = result.agent is not None  # one agent's episodes: no runs to count
    rows: list[tuple[str, ...]] = []
    for p in paths:
        g = result.goals.get(p)
        k, n = result.success(p) if result.runs else (g.successes, g.episodes) if g is not None else (0, 0)
        rate = f"{k / n:.0%} ({k}/{n})" if n else "-"
        iv = "-" if not n else interval_text(success_interval(k, n, result.confidence))
        met = "-" if g is None else f"{g.runs.count(RunVerdict.MET)}/{len(g.runs)} (need {g.required})"
        threshold = "-" if g is None else f">= {g.threshold:g}"
        rows.append((label(p), rate, iv, threshold, met, "-" if g is None else str(result.word(p))))
    if agent:
        header = header[:4] + header[5:]
        rows = [row[:4] + row[5:] for row in rows]
    lines = render_table(header, rows) + result.notes
    for run in result.runs:
        if run.weights:
            lines.append(f"seed {run.seed} adapted weights: {weights_text(run.weights)}")
    digests = digests_text((run.seed, run.weights_digest) for run in result.runs)
    computed = numerics_text(run.numerics for run in result.runs)
    if digests:
        lines.append(f"weights {digests}" + (f" ({computed})" if computed else ""))
    for seed, message in result.errors.items():
        lines.append(f"seed {seed} failed: {message}")
    lines += [f"hint for {p!r}: {hint}" for p, hint in result.hints.items()]
    return "\n".join(lines)
