"""The Dask cluster against the local pool, measured in one run.

1. Per-task overhead, for a tiny spec (2 seeds x 64 steps, no cache, so almost
   all of the time is overhead): the local pool's first run (a fresh process
   per seed; where the platform has a fork server, the first run starts it and
   it imports torch and SB3 once) and its second run (processes forked from
   that server), a fresh local Dask cluster's first run (its workers import
   them once) and its second run (warm workers).
2. Speed-up from 1 to 2 cluster workers on Pendulum (w), 2 seeds at the
   spec's budget (or ``--timesteps``): time with ``LocalCluster(n_workers=1)``
   over time with ``n_workers=2``.

Prints the figures; exits 0 whatever they are (machines are shared and noisy).

Usage:
    python benchmarks/bench_cluster.py [--timesteps 100000]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

import specguard as sg

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the case studies live beside the package
from example_specs import pendulum


def _timed(spec: sg.Spec, **kwargs: object) -> float:
    start = time.perf_counter()
    sg.run_spec(spec, cache_dir=None, progress=None, **kwargs)  # type: ignore[arg-type]
    return time.perf_counter() - start


def _cluster(workers: int):  # type: ignore[no-untyped-def]
    """A local Dask cluster whose workers start with portable numerics (a worker without them is refused)."""
    from distributed import LocalCluster

    from specguard.utils.numerics import portable_environ

    before = dict(os.environ)
    os.environ.update(portable_environ(os.environ))  # the worker processes start with this environment
    try:
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0")
    finally:
        os.environ.clear()
        os.environ.update(before)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=None, help="training steps per seed for part 2")
    args = parser.parse_args()

    tiny = dataclasses.replace(
        pendulum.specs["w"],
        budget=sg.Budget(timesteps=64, min_seeds=2, eval_episodes=2),
        trainer=sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1}, n_envs=1),
    )
    local = _timed(tiny, workers=2)  # the first run in this process starts the fork server (where there is one)
    local_again = _timed(tiny, workers=2)
    start = time.perf_counter()
    with _cluster(2) as cluster:
        up = time.perf_counter() - start
        first = _timed(tiny, executor=cluster.scheduler_address)
        warm = _timed(tiny, executor=cluster.scheduler_address)
    print("tiny spec, 2 seeds x 64 steps (time is almost all overhead):")
    print(f"  local pool, 2 processes:        {local:6.2f} s")
    print(f"  local pool, second run:         {local_again:6.2f} s")
    print(f"  local Dask cluster start-up:    {up:6.2f} s")
    print(f"  cluster, first run (cold):      {first:6.2f} s")
    print(f"  cluster, second run (warm):     {warm:6.2f} s  ({warm / local:.2f}x the local pool)")

    spec = pendulum.specs["w"]
    if args.timesteps is not None:
        spec = dataclasses.replace(spec, budget=dataclasses.replace(spec.budget, timesteps=args.timesteps))
    times = {}
    for workers in (1, 2):
        with _cluster(workers) as cluster:
            times[workers] = _timed(spec, executor=cluster.scheduler_address)
    print(f"Pendulum (w), 2 seeds x {spec.budget.timesteps} steps on a local Dask cluster:")
    print(f"  1 worker:  {times[1]:7.1f} s")
    print(f"  2 workers: {times[2]:7.1f} s  speed-up {times[1] / times[2]:.2f}x")


if __name__ == "__main__":
    main()
