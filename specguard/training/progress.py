"""Progress events: what ``run_spec`` tells its ``progress`` sink, and the one way to print them.

``run_spec(progress=sink)`` calls ``sink(event)`` with a :class:`ProgressEvent`
for each thing that happens to a seed: it starts training (``"start"``), a
tenth of its budget is trained (``"update"``), it finishes (``"done"``), it
comes from the cache (``"cached"``), it fails (``"failed"``), or another
process is training it (``"waiting"``). Sinks decide what to show;
:func:`format_event` is the single layout, used by the CLI (stderr) and the
pytest plugin (its terminal reporter), so both look the same::

    [specguard] pendulum seed 0: training, 50000 steps
    [specguard] pendulum seed 0:  5000/50000 steps  10% | 4s elapsed, ~36s left | root goal 12% of 25 episodes
    [specguard] pendulum seed 0: done, 50000/50000 steps in 41s | root goal 85% of 20 episodes | pendulum 17/20, ...

How the numbers travel: a training worker (a process of its own, or a Dask
worker) already reports ``report(phase, step, line)`` to the parent over a
pipe, and the parent receives ``(seed, line)``. At each tenth of the budget
the worker sends ``line`` as a small JSON object made by :func:`encode_update`
(steps, budget, seconds since training began, root-goal success over the
training episodes of that tenth, and their count); the parent turns it back
into an event with :func:`decode_update` and adds the spec and the seed. The
elapsed time is the worker's own training clock, so time spent queueing for
a free worker does not skew the estimate of time left. Lines are produced
only in the parent process, one call per event, so two seeds' lines never
share a line. A line that is not such JSON (another reporter) is passed on as
an ``"update"`` event whose ``message`` is the line.

The estimate of time left is computed when formatting:
``elapsed * (budget - steps) / steps``, from the rate so far.

Example:
    >>> e = ProgressEvent("pendulum", 0, "update", steps=5000, budget=50000, elapsed_s=4.0, success=0.12, episodes=25)
    >>> format_event(e)
    '[specguard] pendulum seed 0:  5000/50000 steps  10% | 4s elapsed, ~36s left | root goal 12% of 25 episodes'
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from typing import Any, Literal

__all__ = ["Kind", "ProgressEvent", "decode_update", "encode_update", "format_duration", "format_event", "print_event"]

Kind = Literal["start", "update", "done", "cached", "failed", "waiting"]

FINISHED: frozenset[str] = frozenset({"done", "cached", "failed"})
"""Kinds that end a seed's run here: one line each even in a CI log."""


@dataclass(frozen=True)
class ProgressEvent:
    """One thing that happened to one seed of one spec.

    Attributes:
        spec: the spec's label.
        seed: the training seed.
        kind: ``"start"``, ``"update"``, ``"done"``, ``"cached"``, ``"failed"`` or ``"waiting"``.
        steps: environment steps trained so far (or in all, when done).
        budget: the steps the run is to train.
        elapsed_s: seconds of training so far (or in all, when done).
        success: the root goal's success rate: over the training episodes of
            the last tenth of the budget (``"update"``), or over the evaluation
            episodes (``"done"``, ``"cached"``); ``None`` when no episode ended.
        episodes: the episodes ``success`` is over.
        message: free text: per-goal figures, the failure, or a line from elsewhere.
    """

    spec: str
    seed: int
    kind: Kind
    steps: int | None = None
    budget: int | None = None
    elapsed_s: float | None = None
    success: float | None = None
    episodes: int | None = None
    message: str = ""

    @property
    def finished(self) -> bool:
        return self.kind in FINISHED

    @property
    def eta_s(self) -> float | None:
        """Seconds left at the rate so far; ``None`` before the first step or without a budget."""
        if self.kind != "update" or not self.steps or self.budget is None or self.elapsed_s is None:
            return None
        return max(0.0, self.elapsed_s * (self.budget - self.steps) / self.steps)

    def __str__(self) -> str:
        return format_event(self)

    def __contains__(self, text: str) -> bool:
        """``"seed 0: done" in event``: sinks that collect events can search them like lines."""
        return text in format_event(self)


def format_duration(seconds: float) -> str:
    """``7s``, ``2m05s``, ``1h03m``."""
    s = max(0, round(seconds))
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s // 3600}h{s % 3600 // 60:02d}m"


def _success(event: ProgressEvent) -> str:
    if event.success is None:
        return "root goal: no episode finished yet"
    of = "" if event.episodes is None else f" of {event.episodes} episodes"
    return f"root goal {event.success:.0%}{of}"


def format_event(event: ProgressEvent) -> str:
    """The one-line form of ``event``: ``[specguard] SPEC seed N: ...``, no newline in it."""
    head = f"[specguard] {event.spec} seed {event.seed}: "
    if event.kind == "start":
        body = "training" if event.budget is None else f"training, {event.budget} steps"
    elif event.kind == "update" and event.steps is not None and event.budget is not None:
        width = len(str(event.budget))
        pct = event.steps / event.budget if event.budget else 1.0
        body = f"{event.steps:>{width}}/{event.budget} steps {pct:4.0%}"
        if event.elapsed_s is not None:
            eta = event.eta_s
            body += f" | {format_duration(event.elapsed_s)} elapsed"
            body += "" if eta is None else f", ~{format_duration(eta)} left"
        body += f" | {_success(event)}"
    elif event.kind == "done":
        body = "done"
        if event.steps is not None:
            body += f", {event.steps}" + ("" if event.budget is None else f"/{event.budget}") + " steps"
        if event.elapsed_s is not None:
            body += f" in {format_duration(event.elapsed_s)}"
        body += f" | {_success(event)}"
    elif event.kind == "cached":
        body = f"from cache | {_success(event)}"
    elif event.kind == "failed":
        body = "failed"
    elif event.kind == "waiting":
        body = "being trained by another process; waiting"
    else:  # an update line from elsewhere: its message alone
        return head + " ".join(event.message.splitlines())
    if event.message:
        body += f"{' | ' if event.kind in ('update', 'done', 'cached') else ': '}{event.message}"
    return head + " ".join(body.splitlines())


def print_event(event: ProgressEvent) -> None:
    """One flushed line on stderr, which CI logs capture."""
    print(format_event(event), file=sys.stderr, flush=True)


def encode_update(steps: int, budget: int, elapsed_s: float, success: float | None, episodes: int) -> str:
    """What a training worker sends as its progress line at each tenth of the budget (JSON)."""
    return json.dumps(
        {"steps": steps, "budget": budget, "elapsed_s": round(elapsed_s, 3), "success": success, "episodes": episodes}
    )


def decode_update(spec: str, seed: int, line: str) -> ProgressEvent:
    """The ``"update"`` event of a worker's progress line; a line not made by :func:`encode_update` is the message."""
    try:
        data: Any = json.loads(line)
        return ProgressEvent(
            spec,
            seed,
            "update",
            steps=int(data["steps"]),
            budget=int(data["budget"]),
            elapsed_s=float(data["elapsed_s"]),
            success=None if data["success"] is None else float(data["success"]),
            episodes=int(data["episodes"]),
        )
    except (ValueError, TypeError, KeyError):
        return ProgressEvent(spec, seed, "update", message=line)
