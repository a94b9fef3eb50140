"""Cost of a spec's cache key, measured in one run: the static part and the behavioural probe.

For every case-study spec of ``example_specs`` (and its baseline), prints the
median over ``--rounds`` of: the static fingerprint (the exact description of
the spec's values and functions), one behavioural probe (a fixed-seed rollout
of :data:`specguard.cache.probe.PROBE_STEPS` steps), and the whole
``fingerprint_spec`` (static part, two probes to check the env repeats
itself, and the key). The aim: well under a second per spec.

Prints the figures; exits 0 whatever they are (machines are shared and noisy).

Usage:
    python benchmarks/bench_fingerprint.py [--rounds 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the case studies live beside the package
from example_specs import acrobot, lunar_lander, mountain_car, pendulum
from specguard.cache.canonical import digest
from specguard.cache.fingerprint import _compute
from specguard.cache.probe import probe


def _median_ms(fn: Any, rounds: int) -> float:
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1000 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    print(f"{'spec':<26} {'static ms':>10} {'probe ms':>10} {'whole key ms':>13}")
    for module in (pendulum, acrobot, mountain_car, lunar_lander):
        for name, spec in module.specs.items():
            static = _median_ms(lambda s=spec: digest(s), args.rounds)
            probed = _median_ms(lambda s=spec: probe(s), args.rounds)
            whole = _median_ms(lambda s=spec: _compute(s), args.rounds)
            label = f"{module.__name__.rsplit('.', 1)[-1]}::{name}"
            print(f"{label:<26} {static:>10.2f} {probed:>10.1f} {whole:>13.1f}")


if __name__ == "__main__":
    main()
