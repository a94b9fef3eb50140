"""The regression gate on real training: Pendulum (w) against itself, and against two sabotaged versions.

A baseline as ``--goal-specs-save`` stores it: Pendulum (w), seeds 0-7. Then
three pull requests, compared by the gate itself
(:func:`specguard.gate.comparison.compare_spec`: the permutation test per look,
the group-sequential levels, extra seeds while a comparison is open), each
comparison judged at Holm's first step over a session of ``--family``
comparisons (15, as the main job's):

* **no change**: the same spec on fresh seeds (8 and 9 to start, then 10, 11, ...);
* **no change, 2 seeds a side**: a baseline of seeds 0 and 1 only, the pull request on seeds 2 and 3
  (then 4, 5, ...): the pairing of a baseline saved at the spec's own seeds;
* **weight cut**: the position weight cut from 0.8 to 0.2 (stabilization 0.8), seeds 0, 1, ...;
* **distance removed**: the position goal without its Distance (weights 0.8 / 0.2), seeds 0, 1, ...

Prints each side's per-seed successes, the looks, the verdict per goal and the
seeds the sequential rule spent; writes the figures as JSON (``--out``).
Trains for a few minutes on 2 cores; runs are cached (``--cache-dir``), so a
second run reads them back.

Usage:
    python benchmarks/gate_real.py [--cache-dir .specguard/cache] [--out gate-real.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
import specguard as sg
from example_specs import pendulum
from specguard.engine.run_spec import RunOptions, train_seeds
from specguard.engine.spec_result import SpecResult
from specguard.gate.baseline import Baseline
from specguard.gate.comparison import compare_spec, gate_ceiling
from specguard.spec.spec import Spec
from specguard.stats.family import first_level
from specguard.stats.sequential import DEFAULT_ALPHA, DEFAULT_COMPARE_SEEDS

BASE = pendulum.specs["w"]
SABOTAGED = {
    "weight cut": sg.Spec(
        pendulum.initial_env,
        sg.All(pendulum.near_position, pendulum.stabilization, name="pendulum", weights=(0.2, 0.8)),
        expect={"pendulum": 0.8, "position": 0.8},
        name="pendulum-w-weight-cut",
        **pendulum.COMMON,
    ),
    "distance removed": sg.Spec(
        pendulum.initial_env,
        sg.All(pendulum.position, pendulum.stabilization, name="pendulum", weights=(0.8, 0.2)),
        expect={"pendulum": 0.8, "position": 0.8},
        name="pendulum-w-no-distance",
        **pendulum.COMMON,
    ),
}


def per_seed(result: SpecResult, path: str) -> str:
    return ", ".join(f"s{r.seed} {r.successes[path]}/{r.episodes}" for r in result.runs)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache-dir", default=".specguard/cache")
    parser.add_argument("--workers", default="auto")
    parser.add_argument("--family", type=int, default=15, help="comparisons in the session (default 15)")
    parser.add_argument("--out", default=None, help="write the figures as JSON here")
    args = parser.parse_args()
    workers: int | str = int(args.workers) if args.workers.isdigit() else args.workers

    def train(spec: Spec, seeds: list[int]) -> SpecResult:
        return train_seeds(spec, seeds, RunOptions(workers=workers, cache_dir=args.cache_dir, progress=None))

    paths = list(BASE.thresholds)
    keys = {path: f"pendulum-w::{path}" for path in paths}
    ceiling = gate_ceiling(BASE, DEFAULT_COMPARE_SEEDS)
    start = time.perf_counter()
    saved = train(BASE, list(range(ceiling)))
    baseline = Baseline(
        runs={keys[p]: [(r.successes[p], r.episodes) for r in saved.runs] for p in paths},
        specs={keys[p]: saved.spec_key or "" for p in paths},
        seeds={keys[p]: [r.seed for r in saved.runs] for p in paths},
    )
    seconds = sum(r.train_seconds for r in saved.runs)
    print(f"baseline: {BASE.label}, seeds {[r.seed for r in saved.runs]}, {seconds:.0f} s of training")
    for p in paths:
        print(f"  {p}: {per_seed(saved, p)}")
    figures: dict[str, Any] = {
        "baseline": {p: [[r.seed, r.successes[p], r.episodes] for r in saved.runs] for p in paths},
        "baseline_train_seconds": seconds,
        "level": first_level(DEFAULT_ALPHA, args.family),
        "pull_requests": {},
    }
    pair = Baseline(
        runs={keys[p]: [(r.successes[p], r.episodes) for r in saved.runs[:2]] for p in paths},
        specs={keys[p]: saved.spec_key or "" for p in paths},
        seeds={keys[p]: [r.seed for r in saved.runs[:2]] for p in paths},
    )
    cases = [("no change", BASE, [ceiling, ceiling + 1], baseline), ("no change, 2 seeds a side", BASE, [2, 3], pair)]
    cases += [(name, s, [0, 1], baseline) for name, s in SABOTAGED.items()]
    for name, spec, seeds, against in cases:
        own = train(spec, seeds)
        gate = compare_spec(
            spec,
            own,
            against,
            keys,
            level=first_level(DEFAULT_ALPHA, args.family),
            ceiling=ceiling,
            train=lambda more, spec=spec: train(spec, more),
        )
        trained = sum(r.train_seconds for r in gate.runs)
        print(f"\n{name}: {spec.label}, seeds {gate.seeds} ({len(gate.seeds)} trained, {trained:.0f} s of training)")
        record: dict[str, Any] = {"seeds": gate.seeds, "train_seconds": trained, "goals": {}}
        for p in paths:
            look = gate.looks[p]
            runs = [(r.seed, r.successes[p], r.episodes) for r in gate.runs]
            print(f"  {p}: {', '.join(f's{s} {k}/{n}' for s, k, n in runs)}")
            print(f"    {look.describe()}")
            record["goals"][p] = {
                "runs": [list(r) for r in runs],
                "state": look.state.value,
                "p_drop": look.p_drop,
                "looks": list(look.seeds),
                "describe": look.describe(),
            }
        figures["pull_requests"][name] = record
    print(f"\n({time.perf_counter() - start:.0f} s)")
    if args.out:
        Path(args.out).write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
