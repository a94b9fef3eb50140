"""Reproductions: every spec of case-study files trained at a chosen size, specs side by side, through the cache.

Each file given is a case study (e.g. ``example_specs/pendulum.py``): its
specs are its module-level ``Spec`` objects and dicts of specs (as for
``specguard run``), and its optional ``PAPER`` dict gives the paper's reported
figure per spec key. Every spec is trained on ``seeds`` seeds at its whole
budget times ``budget_scale`` (no anytime verdicts: learning curves need the
whole budget), through the run cache, so an interrupted reproduction resumes
where it stopped. Specs train side by side, one thread each (each seed a
process of its own), ``workers`` at a time. An interruption (Ctrl-C) drops the
specs not started and stops the running ones at once: their unfinished seeds
store nothing, every finished run stays cached. The document and plots are
:mod:`specguard.report.reproduction`.
"""

from __future__ import annotations

import dataclasses
import datetime
import os
import platform
import threading
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

from specguard.cache.versions import versions
from specguard.engine.run_spec import run_spec
from specguard.engine.spec_result import SpecResult
from specguard.error import SpecError
from specguard.parallel.signals import STOP_POLL_S, stopping_all_tasks
from specguard.parallel.workers import resolve_workers
from specguard.spec.budget import Budget
from specguard.spec.loading import import_file, load_objects
from specguard.spec.spec import Spec
from specguard.training.progress import ProgressEvent
from specguard.utils.atomic import DEFAULT_CACHE_DIR

__all__ = ["CaseStudy", "Reproduction", "load_case", "machine", "reproduce", "sized"]


@dataclass(frozen=True)
class CaseStudy:
    """A case study: its specs by key and the paper's figure per key."""

    name: str
    specs: dict[str, Spec]
    paper: dict[str, str]


@dataclass
class Reproduction:
    """What a reproduction measured: per case, per spec key, the result."""

    cases: list[CaseStudy]
    results: dict[str, dict[str, SpecResult]]
    seeds: int
    scales: dict[str, float]  # per case: the factor its budgets were trained at
    command: str
    date: str
    machine: str
    version: str  # specguard's version and source digest (every run key holds it)


def load_case(path: str) -> CaseStudy:
    """The case study a file defines: its specs (``specguard run``'s rule) and its ``PAPER`` figures.

    Raises:
        SpecError: the file cannot be imported or defines no specs.
    """

    specs = load_objects(path)
    paper = getattr(import_file(Path(path)), "PAPER", {})
    if not isinstance(paper, Mapping):
        raise SpecError(f"{path}: PAPER must be a dict {{spec key: the paper's figure}}, got {type(paper).__name__}")
    return CaseStudy(Path(path).stem, dict(specs), {str(k): str(v) for k, v in paper.items()})


def sized(spec: Spec, seeds: int, budget_scale: float) -> Spec:
    """The spec at the reproduction's size: ``seeds`` runs, the whole (scaled) budget, no quorum to meet early."""
    scaled = spec.scaled(budget_scale, checkpoints=1)
    budget = dataclasses.replace(scaled.budget, min_seeds=seeds, max_seeds=seeds)
    assert isinstance(budget, Budget)
    return dataclasses.replace(scaled, budget=budget, quorum=None)


def reproduce(
    cases: Sequence[CaseStudy],
    *,
    seeds: int = 5,
    budget_scale: float = 1.0,
    case_scales: Mapping[str, float] | None = None,
    workers: int | str = 2,
    cache_dir: str | Path | None = DEFAULT_CACHE_DIR,
    progress: Callable[[ProgressEvent], None] | None = None,
    command: str = "",
) -> Reproduction:
    """Train every spec of every case at ``seeds`` seeds, ``workers`` specs at a time.

    ``case_scales`` (``{case name: factor}``) replaces ``budget_scale`` for
    some cases, e.g. a long case at half its budget. Every spec runs (no stop
    at the first miss); a spec whose seeds fail keeps its errors in its result.

    Raises:
        SpecError: ``case_scales`` names a case that is not given, or ``workers`` is
            not a worker count (:func:`specguard.parallel.workers.resolve_workers`).
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
            results[name][key] = _result(future)
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


def _result(future: Future[SpecResult]) -> SpecResult:
    """``future.result()``, waited for in short slices so that Ctrl-C is never missed.

    The OS may deliver SIGINT to any thread; Python then runs its handler in
    the main thread only once that thread executes bytecode again. A main
    thread blocked in an untimed wait (``future.result()``) would sleep through
    the interruption until the spec finished, minutes later.
    """
    while not future.done():
        wait([future], timeout=STOP_POLL_S)
    return future.result()
