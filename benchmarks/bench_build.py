"""Cost of building and resetting a spec's env against the raw env's, measured in one run.

For every case-study spec of ``example_specs``, prints the median over ``--rounds``
of ``gymnasium.make`` + ``reset`` of its initial env, and of ``Spec.make_env`` +
``reset`` once the spec was checked (:func:`specguard.check_spec`: its checks run
once per spec, its tree compiles once), with their ratio, and what the first,
checking, build cost. The aim: within 2x the raw env's.

Prints the figures; exits 0 whatever they are (machines are shared and noisy).

Usage:
    python benchmarks/bench_build.py [--rounds 40]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the case studies live beside the package
from bench_fingerprint import _median_ms  # this folder is the script's own, first on the path

import specguard as sg
from example_specs import acrobot, cartpole, lunar_lander, mountain_car, pendulum
from specguard.spec.spec import check_spec


def _built(make: Any) -> Any:
    def build() -> None:
        env = make()
        env.reset(seed=0)
        env.close()

    return build


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=40)
    args = parser.parse_args()
    print(f"{'spec':<28} {'raw ms':>8} {'spec ms':>8} {'ratio':>6} {'first ms':>9}")
    for module in (pendulum, cartpole, acrobot, mountain_car, lunar_lander):
        name, spec = next(iter(module.specs.items()))
        raw = _built(spec.initial_env.make)
        with warnings.catch_warnings():  # a spec's own warnings (met at some starts) are not the figures
            warnings.simplefilter("ignore", sg.error.SpecWarning)
            start = time.perf_counter()
            check_spec(spec)
            _built(spec.make_env)()
            first = 1000 * (time.perf_counter() - start)
            built = _built(spec.make_env)
            raw_ms, spec_ms = _median_ms(raw, args.rounds), _median_ms(built, args.rounds)
        label = f"{module.__name__.rsplit('.', 1)[-1]}:{name}"
        print(f"{label:<28} {raw_ms:8.2f} {spec_ms:8.2f} {spec_ms / raw_ms:5.2f}x {first:9.1f}")


if __name__ == "__main__":
    main()
