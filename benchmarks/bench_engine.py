"""Cost of running a spec, measured in one run: cold cache, warm cache, parallel seeds.

Trains Pendulum (w) (rl-zoo's PPO, the spec's own 100k-step budget unless
``--timesteps`` says otherwise) for 2 seeds:

1. cold: 2 parallel workers, empty cache (trains and stores both runs);
2. warm: the same spec again (target: under 5 s, no training);
3. sequential: 1 worker, no cache; the speed-up of 2 parallel seeds over this
   is the ratio sequential / cold (target: >= 1.7x on 2 cores).

Prints the figures; exits 0 whatever they are (machines are shared and noisy).

Usage:
    python benchmarks/bench_engine.py [--timesteps 100000]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import specguard as sg

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the case studies live beside the package
from example_specs import pendulum


def timed(spec: sg.Spec, workers: int, cache_dir: Path | None) -> tuple[float, sg.SpecResult]:
    start = time.perf_counter()
    result = sg.run_spec(spec, workers=workers, cache_dir=cache_dir, progress=None)
    return time.perf_counter() - start, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = pendulum.specs["w"].budget.timesteps
    parser.add_argument("--timesteps", type=int, default=default, help=f"training steps per seed ({default})")
    args = parser.parse_args()
    spec = dataclasses.replace(
        pendulum.specs["w"], budget=sg.Budget(timesteps=args.timesteps, min_seeds=2, eval_episodes=30)
    )
    print(f"Pendulum (w), 2 seeds x {args.timesteps} steps, 30 evaluation episodes each")
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp)
        cold, result = timed(spec, 2, cache)
        warm, again = timed(spec, 2, cache)
        sequential, _ = timed(spec, 1, None)
    assert all(again.cached.values()), "the warm run trained"
    print(f"cold cache, 2 workers:   {cold:7.1f} s  ({'passed' if result.passed else 'failed'})")
    print(f"warm cache:              {warm:7.2f} s  target < 5 s {'ok' if warm < 5 else 'MISSED'}")
    print(f"sequential, 1 worker:    {sequential:7.1f} s")
    ratio = sequential / cold
    print(f"parallel speed-up:       {ratio:7.2f}x  target >= 1.7x {'ok' if ratio >= 1.7 else 'MISSED'}")


if __name__ == "__main__":
    main()
