"""The main job, measured: ``pytest --goal-specs example_specs`` cold, then warm, on this machine.

Runs README's main job twice in a subprocess with a fresh cache directory:
cold (every run trained) and warm (every run from the cache). Prints, per spec,
the steps trained per seed (and whether training stopped at a checkpoint with
every threshold met), the evaluation episodes spent (interim checkpoints plus
the final evaluation), the training time and the digest of each seed's judged
weights (with the numerics the runs computed with: two machines that print the
same digests trained the same agents); how much of the wall time is spent
the cold run's wall time against its training packed on the cores without
gaps (a spec's seeds train in parallel, and the next specs' seeds ahead on a
core the current spec leaves idle), and the core-seconds that trained nothing;
then the totals against the targets: at most 3 million environment steps
trained in all, wall time at most 1.10x the packed training, at most 5
minutes cold on 2 cores, under 10 s warm.

Exits with the main job's own exit status when it fails (so CI sees a failing
main job); time and step figures are printed, never asserted (machines are
shared and noisy).

Usage:
    python benchmarks/bench_main_job.py [-- extra pytest arguments]
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path
from typing import Any

from specguard.parallel.workers import resolve_workers

ROOT = Path(__file__).resolve().parent.parent
STEPS_TARGET = 3_000_000
COLD_TARGET_S = 5 * 60
WARM_TARGET_S = 10.0
PACKED_TARGET = 1.10  # cold wall time against the training packed on the cores


def main_job(tmp: Path, name: str, extra: list[str]) -> tuple[int, float, list[dict[str, Any]]]:
    """Run the main job; returns its exit status, wall time and report rows."""
    junit = tmp / f"{name}.xml"  # the rows travel as JUnit properties: no report (its GIFs) to time
    command = [sys.executable, "-m", "pytest", "--goal-specs", "example_specs", "-p", "no:cacheprovider", "-q"]
    command += [f"--goal-specs-cache-dir={tmp / 'cache'}", f"--junitxml={junit}", *extra]
    start = time.perf_counter()
    status = subprocess.run(command, cwd=ROOT).returncode
    wall = time.perf_counter() - start
    rows = []
    if junit.exists():
        for prop in ET.parse(junit).iter("property"):
            if prop.get("name") == "specguard":
                rows.append(json.loads(prop.get("value") or "{}"))
    return status, wall, rows


def per_spec(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per spec (its first row: every goal row of a spec carries the same runs)."""
    specs: dict[str, dict[str, Any]] = {}
    for row in rows:
        specs.setdefault(row["group"], row)
    return specs


def main() -> int:
    extra = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    with tempfile.TemporaryDirectory() as tmp:
        cold_status, cold, rows = main_job(Path(tmp), "cold", extra)
        warm_status, warm, _ = main_job(Path(tmp), "warm", extra)
    specs = per_spec(rows)
    print(f"\nmain job on {os.cpu_count()} cores: cold {cold:.0f} s (exit {cold_status}), warm {warm:.1f} s")
    print(f"{'spec':<55} {'steps per seed':<28} {'eval episodes':>13} {'training':>9}")
    totals: dict[str, float] = defaultdict(float)
    for group, row in specs.items():
        seeds = row["per_seed"]
        steps = ", ".join(f"{s['timesteps']}{'*' if s['met_early'] else ''}" for s in seeds)
        evaluated = sum(s["evaluated"] for s in seeds)
        totals["steps"] += sum(s["timesteps"] for s in seeds)
        totals["evaluated"] += evaluated
        totals["train"] += row["train_seconds"]
        totals["slower"] += max((s["train_seconds"] for s in seeds), default=0.0)
        totals["longest"] = max([totals["longest"], *(s["train_seconds"] for s in seeds)])
        print(f"{group.split('::', 1)[-1]:<55} {steps:<28} {evaluated:>13} {row['train_seconds']:>8.0f}s")
    print("(* training stopped at a checkpoint: every threshold met)")
    computed = sorted({s["numerics"] for row in specs.values() for s in row["per_seed"] if s.get("numerics")})
    numerics = ", ".join(computed) or "unrecorded"
    print(f"the judged weights per seed (each digest's first 12 hex digits; an agent's identity; {numerics} numerics):")
    for group, row in specs.items():
        digests = ", ".join((s.get("weights_digest") or "-")[:12] for s in row["per_seed"])
        if any(s.get("weights_digest") for s in row["per_seed"]):
            print(f"  {group.split('::', 1)[-1]:<53} {digests}")
    print(
        f"total: {totals['steps'] / 1e6:.2f}M steps trained (target <= {STEPS_TARGET / 1e6:g}M: "
        f"{totals['steps'] / STEPS_TARGET:.2f}x), {totals['evaluated']:.0f} evaluation episodes, "
        f"{totals['train']:.0f} s of training over all seeds"
    )
    workers = resolve_workers("auto")  # the main job's training processes, by the rule that sets them
    packed = max(totals["train"] / workers, totals["longest"])  # no seed splits over cores
    idle = workers * cold - totals["train"]  # core-seconds of the cold run that trained nothing
    print(
        f"the training over {workers} cores packed without gaps: {packed:.0f} s; the cold run's wall time is "
        f"{cold / packed:.2f}x that (target <= {PACKED_TARGET:.2f}x); {idle:.0f} core-seconds trained nothing "
        f"({idle / (workers * cold):.0%} of {workers} x {cold:.0f} s: start-up, collection, final evaluations, "
        f"a core waiting; the slower seed of each spec sums to {totals['slower']:.0f} s)"
    )
    print(f"cold wall time {cold:.0f} s (target <= {COLD_TARGET_S} s on 2 cores: {cold / COLD_TARGET_S:.2f}x)")
    print(f"warm wall time {warm:.1f} s (target < {WARM_TARGET_S:g} s: {warm / WARM_TARGET_S:.2f}x)")
    return cold_status or warm_status


if __name__ == "__main__":
    sys.exit(main())
