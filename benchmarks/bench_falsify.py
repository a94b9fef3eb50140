"""Episodes to the first counterexample: the guided falsifier against uniform random starts, measured in one run.

For each case (a cached spec's run and a start space), ``--searches`` guided
searches (seeds 0, 1, ...; no shrinking: they stop at the first failing
start), as many searches by Hypothesis's own generation steered by
``hypothesis.target`` on the same robustness score (the falsifier's earlier
design), and as many uniform random searches of the same space (numpy seeds
0, 1, ...) each run at most ``--budget`` episodes; a search that finds no
failure counts as ``budget`` episodes (a lower bound, marked ``>``). Cases:
the CartPole "lean and catch" agents at the env's default starts and on a
wider space, Acrobot (c) at its default starts, and Pendulum (w) from any
angle (no failure known: "none found within budget" is the expected answer).

Target: where failures are rarer than 1 in 20 episodes, the median
episodes to the first failure of the guided search <= 1/3 of random's.
Random sampling's median is known exactly from the failure rate: the episodes
to a first failure are geometric, with median ``ceil(ln 0.5 / ln(1 - rate))``;
the rate comes from ``--rate-draws`` uniform draws (10,000 by default), a far
tighter estimate than the median of a few dozen random searches, which is
printed beside it. The ratio is the guided median over that expected median. Also
printed: the shrunk start's distance from the middle of the space against the
first failing start's (normalised per variable), and the cost per episode of
the falsifier's runner against a plain rollout (target <= 1.2x). Exits 0
whatever the figures (targets are reported, not asserted). The models are
trained (or found in ``--cache-dir``) by ``run_spec``.

Usage:
    python benchmarks/bench_falsify.py [--searches 20] [--budget 600] [--cache-dir /tmp/fz-bench] [--case wide]
"""

from __future__ import annotations

import argparse
import contextlib
import math
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the case studies live beside the package

import specguard as sg
from specguard.engine.falsification import batch_policy, property_keys
from specguard.falsify.search import EpisodeRunner, falsify
from specguard.falsify.starts import StartSpace
from specguard.training.policy import policy
from specguard.training.rollout import episode

WIDE = StartSpace({"x": (-1.0, 1.0), "v": (-0.5, 0.5), "theta": (-0.1, 0.1), "omega": (-0.5, 0.5)})
ANY_ANGLE = StartSpace({"theta": (-3.14159, 3.14159), "omega": (-1.0, 1.0)})


def cases() -> list[tuple[str, sg.Spec, StartSpace]]:
    from example_specs import acrobot, cartpole, pendulum

    lean = cartpole.specs["lean_and_catch"]
    return [
        ("CartPole default starts", lean, StartSpace()),
        ("CartPole wide", lean, WIDE),
        ("Acrobot (c) default starts", acrobot.specs["c"], StartSpace()),
        ("Pendulum (w) any angle", pendulum.specs["w"], ANY_ANGLE),
    ]


def random_search(runner: EpisodeRunner, seed: int, budget: int) -> int | None:
    """Episodes of uniform random starts up to and including the first failure (``None``: none in ``budget``)."""
    rng = np.random.default_rng(seed)
    points = runner.starts.uniform(rng, budget)
    for i in range(0, budget, runner.batch):
        for j, outcome in enumerate(runner.run(points[i : i + runner.batch])):
            if outcome.failed:
                return i + j + 1
    return None


def hypothesis_search(runner: EpisodeRunner, seed: int, budget: int) -> int | None:
    """Episodes up to the first failure of Hypothesis's generation, steered by ``target`` on the robustness score.

    Each variable is drawn as an offset from the middle of its range; ``None``: no failure in ``budget`` episodes.
    """
    from hypothesis import HealthCheck, Phase, given, settings, target
    from hypothesis import seed as hypothesis_seed
    from hypothesis import strategies as st

    s = runner.starts
    half = (s.high - s.low) / 2.0
    first: list[int] = []
    before = runner.episodes

    class Failed(Exception):
        pass

    @settings(
        max_examples=budget,
        database=None,
        deadline=None,
        phases=[Phase.generate, Phase.target],
        suppress_health_check=list(HealthCheck),
    )
    @given(st.tuples(*(st.floats(-1.0, 1.0) for _ in s.names)))
    def test(u: tuple[float, ...]) -> None:
        point = np.clip(s.center + np.asarray(u) * half, s.low, s.high)
        outcome = runner.run(point[None, :])[0]
        target(-outcome.judgement.score, label="robustness")
        if outcome.failed:
            first.append(runner.episodes - before)
            raise Failed

    with contextlib.suppress(Failed):
        hypothesis_seed(seed)(test)()
    return first[0] if first else None


def expected_median(rate: float) -> float:
    """Random sampling's median episodes to a first failure at failure rate ``rate`` (geometric; inf for 0).

    Example:
        >>> expected_median(0.5), expected_median(0.0031), expected_median(0.0)
        (1, 224, inf)
    """
    if rate <= 0:
        return math.inf
    return max(1, math.ceil(math.log(0.5) / math.log1p(-rate)))


def median_text(found: list[int | None], budget: int) -> tuple[float, str]:
    values = [budget if f is None else f for f in found]
    med = statistics.median(values)
    misses = sum(f is None for f in found)
    return med, f"{'>' if med >= budget and misses else ''}{med:g} ({len(found) - misses}/{len(found)} found)"


def distance(runner: EpisodeRunner, start: dict[str, float]) -> float:
    s = runner.starts
    point = np.array([start[n] for n in s.names])
    half = np.where(s.high > s.low, (s.high - s.low) / 2.0, 1.0)
    return float(np.linalg.norm((point - s.center) / half))


def episode_cost(spec: sg.Spec, model: Any, normalizer: Any, runner: EpisodeRunner, n: int = 40) -> float:
    """Seconds per episode of the falsifier's runner over seconds per episode of a plain rollout, same starts."""
    env = spec.make_env()
    act = policy(model, normalizer, deterministic=spec.deterministic)
    points = runner.starts.uniform(np.random.default_rng(0), n)
    plain, ours = math.inf, math.inf
    for _ in range(3):  # interleaved, the fastest of each: what else the machine runs weighs on both alike
        t = time.perf_counter()
        plain_steps = sum(len(episode(env, act, 1_000_000 + i)) for i in range(n))
        plain = min(plain, (time.perf_counter() - t) / plain_steps)
        t = time.perf_counter()
        steps = sum(o.steps for o in runner.run(points))
        ours = min(ours, (time.perf_counter() - t) / steps)
    return ours / plain


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--searches", type=int, default=20)
    parser.add_argument("--budget", type=int, default=600)
    parser.add_argument("--cache-dir", default="/tmp/fz-bench")
    parser.add_argument("--rate-draws", type=int, default=10_000, help="uniform draws for each case's failure rate")
    parser.add_argument("--case", default="", help="only cases whose name contains this")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="the runs (training seeds)")
    args = parser.parse_args()
    machine = platform.processor() or platform.machine()
    print(f"machine: {machine}, {platform.system()}, Python {platform.python_version()}")
    print(f"{args.searches} searches per method, at most {args.budget} episodes each\n")
    header = f"{'case':26s} {'run':>3s} {'rate (draws)':>18s} {'guided median':>20s} {'Hypothesis median':>20s}"
    header += f" {'random median':>20s} {'random expected':>15s} {'ratio':>6s} {'shrunk/first':>13s} {'cost/ep':>8s}"
    print(header, flush=True)
    verdicts = []
    for name, spec, space in cases():
        if args.case and args.case not in name:
            continue
        result = sg.run_spec(spec, cache_dir=args.cache_dir, progress=None, workers=2)
        for seed in args.seeds:
            model, normalizer = result.model(seed), result.normalizer(seed)
            runner = EpisodeRunner(
                spec.make_env,
                batch_policy(model, normalizer, spec.deterministic),
                space,
                property_keys(spec),
            )
            guided = []
            for k in range(args.searches):
                before = runner.episodes
                f = falsify(runner, examples=args.budget, uniform=0, seed=k, shrink=False)
                guided.append(f.episodes_to_first if f.found else None)
                assert runner.episodes - before <= args.budget + 1
            hypo = [hypothesis_search(runner, k, args.budget) for k in range(args.searches)]
            randoms = [random_search(runner, k, args.budget) for k in range(args.searches)]
            rate_run = falsify(runner, examples=1, uniform=args.rate_draws, seed=0, shrink=False)
            g_med, g_text = median_text(guided, args.budget)
            _, h_text = median_text(hypo, args.budget)
            _, r_text = median_text(randoms, args.budget)
            rate = rate_run.failure_rate
            expected = expected_median(rate)
            ratio = g_med / expected if math.isfinite(expected) else float("nan")
            shrunk = falsify(runner, examples=args.budget, uniform=0, seed=0, shrink=True)
            if shrunk.found and shrunk.first is not None:
                size = f"{distance(runner, shrunk.counterexample.start):.2f}/{distance(runner, shrunk.first.start):.2f}"
            else:
                size = "-"
            cost = episode_cost(spec, model, normalizer, runner)
            drawn = f"{rate:.2%} ({rate_run.uniform_failures}/{rate_run.uniform_episodes})"
            print(
                f"{name:26s} {seed:3d} {drawn:>18s} {g_text:>20s} {h_text:>20s} {r_text:>20s} {expected:>15g}"
                f" {ratio:6.2f} {size:>13s} {cost:7.2f}x",
                flush=True,
            )
            if all(g is None for g in guided) and all(r is None for r in randoms):
                verdicts.append(f"{name} run {seed}: none found within budget")
            elif rate < 1 / 20:
                verdicts.append(
                    f"{name} run {seed}: ratio {ratio:.2f} ({'met' if ratio <= 1 / 3 else 'MISSED'} <= 0.33)"
                )
    print("\nsummary: " + "; ".join(verdicts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
