"""Recording goal items' figures as reports arrive (on the xdist controller too), and writing them out.

The terminal table, the ``--goal-specs-report`` files, the ``--goal-specs-save``
baseline, and the session's family-wise procedure over its comparisons with a
baseline (:func:`apply_family`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pytest

from specguard.pytest_plugin.falsify_item import COUNTEREXAMPLES
from specguard.pytest_plugin.items import PROPERTY
from specguard.pytest_plugin.session import GoalSpecSession

__all__ = ["Recorder", "apply_family", "interruption", "unsigned_cache_note", "write_outputs"]

WARNING = "specguard: warning:"  # a line saying an output was not written


def _verdict(report: pytest.TestReport, outcome: str) -> str:
    """A goal row's word (:func:`~specguard.stats.verdicts.verdict_word`, as ``specguard run`` shows it)
    from its item's pytest report and the goal's own outcome (passed, failed, undecided)."""
    from specguard.stats.verdicts import pytest_counted, verdict_word

    expected_miss = hasattr(report, "wasxfail")
    counts_as = pytest_counted(report.outcome, expected_miss=expected_miss)
    return str(verdict_word(counts_as, outcome, expected_miss=expected_miss))


class Recorder:
    """Collects the figures of goal items as reports arrive (on the xdist controller too) and reports them."""

    def __init__(self, config: pytest.Config, state: GoalSpecSession) -> None:
        self.config = config
        self.state = state

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        if report.when == "teardown":
            self.state.ran.add(report.nodeid)
        if report.when != "call":
            return
        for key, value in report.user_properties:
            if key == COUNTEREXAMPLES:
                self.state.counterexamples.extend(json.loads(str(value)))
            if key != PROPERTY:
                continue
            row = json.loads(str(value))
            row["verdict"] = _verdict(report, row["outcome"])
            self.state.rows.append(row)

    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        """Holm's procedure over the session's comparisons: a drop it flags beyond the items' own fails the session."""
        if hasattr(self.config, "workerinput"):  # an xdist worker: the controller has every row
            return
        self.state.interrupted = interruption(session, len(self.state.ran))
        if apply_family(self.state.rows):
            session.exitstatus = pytest.ExitCode.TESTS_FAILED

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        if not self.state.rows and not self.state.counterexamples:
            return
        from specguard.report.session_report import family_lines, table_lines

        terminalreporter.write_sep("=", "specguard goal specs")
        for line in table_lines(self.state.rows) if self.state.rows else []:
            terminalreporter.write_line(line)
        for line in family_lines(self.state.rows):
            terminalreporter.write_line(f"specguard: {line}")
        for line in write_outputs(self.config, self.state):
            terminalreporter.write_line(line, yellow=line.startswith(WARNING))
        note = unsigned_cache_note(self.state.rows, os.environ)
        if note:
            terminalreporter.write_line(note)


def interruption(session: pytest.Session, ran: int) -> str | None:
    """Why ``session`` stopped before its last item (a KeyboardInterrupt, ``-x``, ``--maxfail``), with how many of
    its items ran; ``None`` for a session that ran them all."""
    stopped = session.exitstatus == pytest.ExitCode.INTERRUPTED or bool(session.shouldstop)
    if not stopped or ran >= session.testscollected:
        return None
    why = f"stopped early ({session.shouldstop})" if isinstance(session.shouldstop, str) else "was interrupted"
    return f"the session {why} after {ran} of {session.testscollected} items ran"


def unsigned_cache_note(rows: list[dict[str, Any]], environ: Mapping[str, str]) -> str | None:
    """One line when CI trusted cached runs whose entries nobody signed, with the setting that signs them.

    A cache restored in CI (``CI`` set) may come from a run anyone could write to
    (a pull request's job); without ``SPECGUARD_CACHE_KEY`` its entries are checked
    but not authenticated, so a forged one would be trusted.

    Example:
        >>> unsigned_cache_note([{"cached": True}], {"CI": "true"}) is not None
        True
        >>> unsigned_cache_note([{"cached": True}], {"CI": "true", "SPECGUARD_CACHE_KEY": "k"}) is None
        True
    """
    from specguard.cache.store import SECRET_ENV

    if not environ.get("CI") or environ.get(SECRET_ENV) or not any(row.get("cached") for row in rows):
        return None
    return (
        f"specguard: cached runs were trusted without {SECRET_ENV}: entries are checked but not authenticated, "
        f"so a restored cache could carry forged ones; set {SECRET_ENV} from a CI secret (e.g. "
        f"`{SECRET_ENV}: ${{{{ secrets.SPECGUARD_CACHE_KEY }}}}` in the job's env) to sign and verify them"
    )


def write_outputs(config: pytest.Config, state: GoalSpecSession) -> list[str]:
    """Write the reports and the baseline this session asked for; a line for each file written or note.

    A destination that cannot be written (a file where a folder should be, no
    permission, a corrupt or locked baseline) is a warning line naming it and the
    reason: the session keeps its outcome and exit status, and the other outputs
    are still written.
    """
    if hasattr(config, "workerinput"):  # an xdist worker: the controller writes
        return []
    lines: list[str] = []
    if state.options.report_dir is not None:
        lines += _write_report(state, state.options.report_dir)
    if state.options.save:
        lines.append(_save_baseline(state, state.options.save))
    return lines


def _reason(error: OSError) -> str:
    """Why a write failed, without repeating the destination: ``NotADirectoryError: Not a directory``."""
    return f"{type(error).__name__}: {error.strerror or error}"


def _write_report(state: GoalSpecSession, directory: Path) -> list[str]:
    """The ``--goal-specs-report`` files and GIFs: a line per file written and per spec without a GIF."""
    from specguard.report.gifs import report_gifs
    from specguard.report.session_report import write_reports

    try:
        directory.mkdir(parents=True, exist_ok=True)  # before the GIFs: one warning, not one note per spec
        gifs = report_gifs(directory, state.rows, state.specs, state.options.cache_dir, state.agent_checks)
        written = write_reports(
            directory, state.rows, gifs=gifs, counterexamples=state.counterexamples, interrupted=state.interrupted
        )
    except OSError as e:
        return [f"{WARNING} the report was not written to {str(directory)!r}: {_reason(e)}"]
    written += [gif.path for gif in gifs.values() if gif.path is not None]
    notes = [f"specguard: {group}: {gif.text}" for group, gif in gifs.items() if gif.path is None]
    return [f"specguard: wrote {path}" for path in written] + notes


def _save_baseline(state: GoalSpecSession, name: str) -> str:
    """Merge the session's runs (and its agents' episodes) into baseline ``name``: the line saying what it replaced,
    or why it was not saved."""
    from specguard.error import BaselineError
    from specguard.gate.baseline import AgentEntry, save_baseline

    path = state.options.baseline_dir / f"{name}.json"
    rows = [r for r in state.rows if r.get("baseline_runs")]
    key = "{0[group]}::{0[goal]}".format
    agents = {r["group"]: r["agent_baseline"] for r in state.rows if r.get("agent_baseline")}  # one per test
    try:
        saved = save_baseline(
            path,
            {key(r): [(k, n) for _, k, n in r["baseline_runs"]] for r in rows},
            {key(r): r["spec_key"] for r in rows if r.get("spec_key")},
            {key(r): [seed for seed, _, _ in r["baseline_runs"]] for r in rows},
            {group: AgentEntry.from_dict(group, entry) for group, entry in agents.items()},
        )
    except BaselineError as e:
        return f"{WARNING} baseline {name!r} was not saved: {e}"
    except OSError as e:
        return f"{WARNING} baseline {name!r} was not saved to {str(path)!r}: {_reason(e)}"
    return f"specguard: wrote baseline {path}: {saved.text()}"


def apply_family(rows: list[dict[str, Any]]) -> bool:
    """Holm's procedure over the rows compared with a baseline; True when it flags a drop no item failed for.

    Each item judged its own comparison at Holm's first step (the family-wise level over
    the baseline's comparisons), so it failed already for any drop that step flags; later
    steps can flag more. Those rows are marked failed, with the step in their comparison,
    and the session fails. Every compared row gets ``gate["holm"]``: the step that flags it, or None.
    """
    from specguard.stats.family import holm, step_level
    from specguard.stats.sequential import DEFAULT_ALPHA
    from specguard.stats.verdicts import Word

    compared = {f"{r['group']}::{r['goal']}": r for r in rows if r.get("gate")}
    if not compared:
        return False
    steps = holm({key: r["gate"]["p_drop"] for key, r in compared.items()}, DEFAULT_ALPHA)
    beyond = False
    for key, row in compared.items():
        step = row["gate"]["holm"] = steps[key]
        if step is not None and row["gate"]["state"] != "dropped":
            level = step_level(DEFAULT_ALPHA, len(compared), step)
            row["comparison"] = (
                f"dropped by Holm's step {step} (p = {row['gate']['p_drop']:.2g} <= {level:.2g}): "
                + str(row.get("comparison") or "")
            )
            if row.get("verdict") == Word.PASSED:  # an item that failed or was expected to miss keeps its verdict
                row["verdict"] = str(Word.FAILED)
                row["hint"] = row["comparison"]
                beyond = True
    return beyond
