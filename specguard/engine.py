"""Running a spec: seeds in parallel processes, sequential seeds, per-goal verdicts.

``run_spec`` trains ``budget.min_seeds`` runs (in parallel worker processes,
each with one torch thread), judges every thresholded goal, and trains further
seeds, up to ``budget.max_seeds``, only while some goal's quorum is still open.
Runs come from the cache when an identical run was trained before
(:mod:`specguard.cache`).

Example:
    >>> import specguard as sg
    >>> from example_specs import pendulum
    >>> spec = sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=sg.Budget(timesteps=100_000))
    >>> result = sg.run_spec(spec, workers=2)  # doctest: +SKIP
    >>> print(result.table())  # doctest: +SKIP
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import cloudpickle

from specguard.cache import Cache
from specguard.error import SpecError
from specguard.spec import Spec
from specguard.stats import QuorumVerdict, RunVerdict, quorum_verdict, run_verdict, success_interval
from specguard.train import RunResult, TrainingError

__all__ = ["GoalVerdict", "SpecResult", "resolve_workers", "run_spec"]

Progress = Callable[[str], None]


def print_progress(line: str) -> None:
    """The default progress sink: one flushed line on stderr, which CI logs capture."""
    print(line, file=sys.stderr, flush=True)


def resolve_workers(workers: int | str) -> int:
    """``"auto"`` is the number of usable cores; otherwise an integer >= 1."""
    if workers == "auto":
        try:
            return max(1, len(os.sched_getaffinity(0)))
        except AttributeError:  # not on Linux
            return max(1, os.cpu_count() or 1)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise SpecError(f"workers: expected an integer >= 1 or 'auto', got {workers!r}")
    return workers


@dataclass
class GoalVerdict:
    """One goal of a spec against its threshold, over all runs.

    Attributes:
        path: the node path.
        threshold: the minimum success asked for.
        required: runs that must meet it.
        runs: each run's verdict, by seed order.
        verdict: ``"passed"``, ``"failed"``.
        successes, episodes: pooled over runs.
        interval: the pooled success rate's confidence interval.
    """

    path: str
    threshold: float
    required: int
    runs: list[str]
    verdict: str
    successes: int
    episodes: int
    interval: tuple[float, float]

    @property
    def success(self) -> float:
        return self.successes / self.episodes if self.episodes else 0.0


@dataclass
class SpecResult:
    """Everything ``run_spec`` measured; ``to_dict()`` is JSON-serialisable."""

    spec: str
    runs: list[RunResult]
    goals: dict[str, GoalVerdict]
    errors: dict[int, str] = field(default_factory=dict)
    cached: dict[int, bool] = field(default_factory=dict)
    seconds: float = 0.0
    confidence: float = 0.95

    @property
    def passed(self) -> bool:
        return not self.errors and all(g.verdict == QuorumVerdict.PASSED.value for g in self.goals.values())

    def success(self, path: str) -> tuple[int, int]:
        """Pooled ``(successes, episodes)`` of a goal over all runs."""
        return sum(r.successes[path] for r in self.runs), sum(r.episodes for r in self.runs)

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.spec,
            "passed": self.passed,
            "seconds": self.seconds,
            "runs": [r.to_dict() for r in self.runs],
            "goals": {p: asdict(g) for p, g in self.goals.items()},
            "errors": {str(k): v for k, v in self.errors.items()},
            "cached": {str(k): v for k, v in self.cached.items()},
            "confidence": self.confidence,
        }

    def table(self) -> str:
        """A per-goal table: pooled success with interval, threshold, runs, verdict."""
        paths = [p for r in self.runs[:1] for p in r.successes] or list(self.goals)
        rows = [("goal", "success", f"{self.confidence:.0%} interval", "threshold", "runs met", "verdict")]
        for p in paths:
            k, n = self.success(p)
            rate = f"{k / n:.0%} ({k}/{n})" if n else "-"
            iv = "-" if not n else "[{:.2f}, {:.2f}]".format(*success_interval(k, n, self.confidence))
            g = self.goals.get(p)
            met = "-" if g is None else f"{g.runs.count(RunVerdict.MET.value)}/{len(g.runs)} (need {g.required})"
            threshold = "-" if g is None else f">= {g.threshold:g}"
            rows.append((p, rate, iv, threshold, met, "-" if g is None else g.verdict))
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
        lines.insert(1, "  ".join("-" * w for w in widths))
        for seed, message in self.errors.items():
            lines.append(f"seed {seed} failed: {message}")
        return "\n".join(lines)


def _train_in_worker(payload: bytes, seed: int, cache_dir: str | None, report: bool) -> dict[str, Any]:
    """Process entry point: unpickle the spec (cloudpickle carries lambdas), train, store.

    Progress lines go straight to the inherited stderr, which CI logs capture.
    """
    spec: Spec = cloudpickle.loads(payload)
    from specguard.train import train_run

    result, model = train_run(spec, seed, progress=print_progress if report else None)
    if cache_dir is not None:
        Cache(Path(cache_dir)).store(spec, seed, result, model)
    return result.to_dict()


def _judge(spec: Spec, runs: list[RunResult], failed_seeds: int) -> dict[str, GoalVerdict]:
    assert spec.budget.max_seeds is not None
    goals = {}
    for path, threshold in spec.thresholds.items():
        verdicts = [run_verdict(r.successes[path], r.episodes, threshold, spec.confidence) for r in runs]
        counted = [RunVerdict.MET if (v is RunVerdict.UNDECIDED and spec.undecided == "pass") else v for v in verdicts]
        counted += [RunVerdict.MISSED] * failed_seeds  # a run that crashed met nothing
        verdict = quorum_verdict(counted, spec.required_runs, spec.budget.max_seeds)
        k = sum(r.successes[path] for r in runs)
        n = sum(r.episodes for r in runs)
        goals[path] = GoalVerdict(
            path=path,
            threshold=threshold,
            required=spec.required_runs,
            runs=[v.value for v in verdicts],
            verdict=verdict.value,
            successes=k,
            episodes=n,
            interval=success_interval(k, n, spec.confidence) if n else (0.0, 1.0),
        )
    return goals


def _still_needed(spec: Spec, goals: dict[str, GoalVerdict], done: int) -> int:
    """How many more runs could still change an open verdict (0 when every goal is settled)."""
    assert spec.budget.max_seeds is not None
    open_goals = [g for g in goals.values() if g.verdict == QuorumVerdict.OPEN.value]
    if done < spec.budget.min_seeds:
        return spec.budget.min_seeds - done
    if not open_goals:
        return 0
    missing = max(g.required - g.runs.count(RunVerdict.MET.value) for g in open_goals)
    return min(missing, spec.budget.max_seeds - done)


def run_spec(
    spec: Spec,
    *,
    workers: int | str = "auto",
    cache_dir: str | Path | None = ".specguard/cache",
    progress: Progress | None = print_progress,
) -> SpecResult:
    """Train and judge ``spec`` within its budget.

    Args:
        spec: the spec.
        workers: parallel training processes (``"auto"``: the usable cores).
        cache_dir: where trained runs are kept and looked up; ``None`` disables the cache.
        progress: called with one line per event (CI logs read it); ``None`` for silence.

    Returns:
        The runs, per-goal verdicts, errors by seed and which runs came from the cache.
    """
    say = progress or (lambda line: None)
    n_workers = resolve_workers(workers)
    cache = Cache(Path(cache_dir)) if cache_dir is not None else None
    payload = cloudpickle.dumps(spec)
    start = time.perf_counter()
    result = SpecResult(spec=spec.label, runs=[], goals={}, confidence=spec.confidence)
    next_seed = 0
    context = multiprocessing.get_context("spawn")  # torch and forked state do not mix
    pool: cf.ProcessPoolExecutor | None = None
    try:
        while True:
            result.goals = _judge(spec, result.runs, len(result.errors))
            needed = _still_needed(spec, result.goals, len(result.runs) + len(result.errors))
            if needed == 0:
                break
            seeds = list(range(next_seed, next_seed + needed))
            next_seed += needed
            pending: dict[cf.Future[dict[str, Any]], int] = {}
            for seed in seeds:
                hit = cache.load(spec, seed) if cache is not None else None
                if hit is not None:
                    result.runs.append(hit)
                    result.cached[seed] = True
                    say(f"[specguard] {spec.label}: seed {seed} from cache")
                    continue
                if pool is None:
                    pool = cf.ProcessPoolExecutor(max_workers=n_workers, mp_context=context)
                say(f"[specguard] {spec.label}: training seed {seed} ({spec.budget.timesteps} steps)")
                cache_arg = None if cache is None else str(cache.root)
                pending[pool.submit(_train_in_worker, payload, seed, cache_arg, progress is not None)] = seed
            for future in cf.as_completed(pending):
                seed = pending[future]
                try:
                    run = RunResult(**future.result())
                except TrainingError as e:  # other seeds' results are kept
                    result.errors[seed] = str(e)
                    say(f"[specguard] {spec.label}: seed {seed} failed: {e}")
                    continue
                result.runs.append(run)
                result.cached[seed] = False
                rates = ", ".join(f"{p} {c}/{run.episodes}" for p, c in run.successes.items())
                say(f"[specguard] {spec.label}: seed {seed} done in {run.train_seconds:.1f}s: {rates}")
            result.runs.sort(key=lambda r: r.seed)
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    result.seconds = time.perf_counter() - start
    return result
