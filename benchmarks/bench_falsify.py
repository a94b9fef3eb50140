"""Episodes to a first counterexample over a suite of agents: the guided falsifier against uniform random starts.

The suite: CartPole "lean and catch" and Acrobot (c) at their envs' default
starts, and InvertedPendulum-v5 "balance" over a start space wider than its
default (the pole within 0.2 rad of upright and up to 1 rad/s); per case, one
agent per training seed (``--seeds``), trained by ``train_seeds`` on the machine
that runs this and kept in ``--agents DIR`` (``DIR/<case>-<seed>/``: the SB3
zip, its ``VecNormalize`` statistics, the run's looks), where later runs find
them: every edit of specguard changes its cache keys, and a benchmark of the
search must search the same agents before and after.

Per agent:

* **failure rate**: ``--rate-draws`` uniform starts (10,000 by default); where none failed, the most
  it can be at 95% (the one-sided exact binomial bound), never a bare 0%;
* **guided**: ``--searches`` searches of the falsifier (seeds 0, 1, ...; no
  shrinking: each stops at its first failing start or after ``--budget``
  episodes), with the share that found a failure;
* **expected episodes to a first failure**, censored searches handled as
  censored: the expected running time with restarts (ERT, as in the COCO
  benchmarking platform), every episode the searches ran over the number of
  searches that found a failure; a search that found none counts its whole
  budget and no success;
* **random's expected episodes**: a uniform start fails with probability equal
  to the failure rate, independently, so its episodes to a first failure are
  geometric, with mean ``1 / rate`` (estimated from the rate draws, a far
  tighter figure than a few dozen random searches would give); and the share
  of random searches of ``--budget`` episodes that would find one,
  ``1 - (1 - rate) ** budget``;
* **ratio**: guided ERT over random's expected episodes;
* **the failure predictor**: each search is given the run's looks (``related=``, as ``falsify_runs`` gives
  them) and ``--weaker`` episodes per level of the agent made weaker (0 by default); with ``--compare``, the
  same searches without a predictor too (rerun only where a predictor was fitted: else the search is the same);
* **importance sampling** (``--importance K``): the failure rate from ``K`` episodes of the predictor's proposal
  beside ``K`` uniform draws', each with its 95% interval, and the ratio of their widths;
* **per sampler** (the portfolio's arms, ``specguard.falsify.portfolio.ARMS``, the middle of the space and
  ``related``, the weaker agent's episodes):
  each one's ERT, the episodes it drew over all searches over the searches whose failure it found, with a 95%
  interval from a bootstrap over the searches (2,000 resamples of the searches, percentiles; ``inf`` where a
  resample has no failure found by it).

Target, over every agent with a failure rate in (0, 5%]: the ratio <= 1/3,
and on no agent above 1 (the verdict lines). Which seeds served what is in
docs/guide/falsify.md: seeds 2-16 served development runs of earlier
versions; 7-11 the failure predictor's; 17-21 (the default) are held out.
Only the seeds asked for are trained (``train_seeds``). Also printed:
the cost per episode of the falsifier's runner against a plain rollout. Exits
0 whatever the figures (targets are reported, not asserted).

``--score episode`` runs the search with the score over the whole episode
(``EpisodeRunner(score="episode")``) instead of the default, the last state's.

Usage:
    python benchmarks/bench_falsify.py [--seeds 17 18 19 20 21] [--searches 20] [--budget 600] [--case CartPole]
        [--score {last,episode}] [--agents DIR] [--weaker N] [--importance K] [--compare]
"""

from __future__ import annotations

import argparse
import json
import math
import pickle
import platform
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the case studies live beside the package

import specguard as sg
from specguard.cache.store import NORMALIZER, Cache
from specguard.engine.falsify_run import batch_policy, property_keys
from specguard.engine.run_spec import RunOptions, train_seeds
from specguard.evaluation.policy import one_torch_thread, policy
from specguard.evaluation.rollout import episode
from specguard.falsify.predictor import from_looks
from specguard.falsify.robustness import SCORES
from specguard.falsify.search import EpisodeRunner, falsify
from specguard.spec.algorithms import load_saved
from specguard.starts.space import StartSpace
from specguard.stats.intervals import failure_upper_bound

PENDULUM_WIDE = StartSpace({"hinge": (-0.2, 0.2), "hinge_vel": (-1.0, 1.0)})
RARE = 0.05
"""The target holds over agents whose failure rate is in (0, RARE]."""


def cases() -> list[tuple[str, sg.Spec, StartSpace]]:
    from example_specs import acrobot, cartpole, inverted_pendulum

    return [
        ("CartPole default starts", cartpole.specs["lean_and_catch"], StartSpace()),
        ("Acrobot (c) default starts", acrobot.specs["c"], StartSpace()),
        ("InvertedPendulum wide", inverted_pendulum.specs["balance"], PENDULUM_WIDE),
    ]


def expected_running_time(found: list[int | None], budget: int) -> float:
    """Episodes run by all searches over the searches that found a failure (``inf``: none did).

    Example:
        >>> expected_running_time([10, None, 30], budget=100)
        70.0
        >>> expected_running_time([None], budget=100)
        inf
    """
    successes = sum(f is not None for f in found)
    spent = sum(budget if f is None else f for f in found)
    return spent / successes if successes else math.inf


SAMPLERS = ("uniform", "middle", "related", "trend", "local", "learned")
"""The samplers whose episodes are counted apart: the portfolio's arms and the middle of the space."""


def sampler_ert(
    drawn: list[dict[str, int]], found_by: list[str | None], sampler: str, *, resamples: int = 2000
) -> tuple[float, float, float]:
    """One sampler's ERT over the searches (its episodes over the failures it found) and a 95% bootstrap interval.

    Example:
        >>> drawn = [{"uniform": 10, "local": 5}, {"uniform": 20}, {"uniform": 8, "local": 2}]
        >>> found_by = ["local", None, "local"]
        >>> sampler_ert(drawn, found_by, "local")[0], sampler_ert(drawn, found_by, "trend")
        (3.5, (inf, inf, inf))
    """
    spent = np.array([d.get(sampler, 0) for d in drawn], dtype=np.float64)
    hits = np.array([f == sampler for f in found_by], dtype=np.float64)
    if not hits.any():
        return math.inf, math.inf, math.inf
    rows = np.random.default_rng(0).integers(len(drawn), size=(resamples, len(drawn)))
    found = hits[rows].sum(axis=1)
    ratios = np.divide(spent[rows].sum(axis=1), found, out=np.full(resamples, np.inf), where=found > 0)
    lo, hi = np.quantile(ratios, [0.025, 0.975], method="inverted_cdf")
    return float(spent.sum() / hits.sum()), float(lo), float(hi)


def sampler_line(drawn: list[dict[str, int]], found_by: list[str | None]) -> str:
    """Per sampler: its ERT with the interval, the failures it found and the episodes it drew, over all searches."""
    parts = []
    for sampler in SAMPLERS:
        episodes = sum(d.get(sampler, 0) for d in drawn)
        if not episodes:
            continue
        ert, lo, hi = sampler_ert(drawn, found_by, sampler)
        parts.append(
            f"{sampler} {ert:.1f} [{lo:.1f}, {hi:.1f}] ({sum(f == sampler for f in found_by)} found, {episodes} ep.)"
        )
    return "    per sampler, ERT [95% bootstrap]: " + "; ".join(parts)


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


def rate_cell(failures: int, draws: int) -> str:
    """The failure-rate column: the rate over the draws, or where none failed the most it can be at 95%.

    >>> rate_cell(3, 1000), rate_cell(0, 3000)
    ('0.30% (3/1000)', '<= 0.10% (0/3000)')
    """
    if failures or not draws:
        return f"{failures / draws if draws else 0.0:.2%} ({failures}/{draws})"
    return f"<= {failure_upper_bound(draws):.2%} ({failures}/{draws})"


def verdict(name: str, seed: int, rate: float, ratio: float, draws: int) -> str:
    """One agent against the target: ``met``/``MISSED`` for rare failures, worse than random anywhere."""
    if rate == 0:
        bound = failure_upper_bound(draws) if draws else 1.0
        return (
            f"{name} run {seed}: no failure in {draws} rate draws: failure rate at most {bound:.2%} at 95% "
            "(one-sided exact binomial bound; outside the target)"
        )
    if math.isnan(ratio):
        return f"{name} run {seed}: the guided search found none"
    if rate <= RARE:
        return f"{name} run {seed}: ratio {ratio:.2f} ({'met' if ratio <= 1 / 3 else 'MISSED'} <= 0.33)"
    return f"{name} run {seed}: ratio {ratio:.2f} ({'not worse' if ratio <= 1 else 'WORSE'} than random)"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--searches", type=int, default=20)
    parser.add_argument("--budget", type=int, default=600)
    parser.add_argument("--cache-dir", default="/tmp/fz-bench")
    parser.add_argument(
        "--agents", default="/tmp/fz-agents", help="where trained agents and their looks are kept and read back"
    )
    parser.add_argument("--rate-draws", type=int, default=10_000, help="uniform draws for each agent's failure rate")
    parser.add_argument("--case", default="", help="only cases whose name contains this")
    parser.add_argument("--seeds", type=int, nargs="+", default=[17, 18, 19, 20, 21], help="the agents (their seeds)")
    parser.add_argument("--workers", type=int, default=2, help="training processes")
    parser.add_argument(
        "--score",
        choices=SCORES,
        default="last",
        help="the search's score: last (the falsifier's default) or episode (over the whole episode)",
    )
    parser.add_argument("--compare", action="store_true", help="also run each search without the failure predictor")
    parser.add_argument("--weaker", type=int, default=0, help="falsify(weaker=): episodes per level, weaker agent")
    parser.add_argument(
        "--importance", type=int, default=0, help="episodes of the importance-sampling rate (0: not measured)"
    )
    args = parser.parse_args()
    with one_torch_thread():  # as the falsifier's own runs are
        run_suite(args)
    return 0


def slug(name: str) -> str:
    """A case's name as a folder name.

    >>> slug("CartPole default starts")
    'cartpole-default-starts'
    """
    return "-".join(name.lower().split())


def trained_agents(name: str, spec: sg.Spec, args: argparse.Namespace) -> dict[int, tuple[Any, Any, list[Any]]]:
    """Per seed, the agent's model, its ``VecNormalize`` statistics and its run's looks (``RunResult.looks``).

    Read from ``--agents DIR`` (``DIR/<case>-<seed>/``) where they were kept; the others are trained by
    ``train_seeds`` and kept there. Kept agents outlive specguard's source digest (which every edit of the
    package changes, and with it every cache key), so one set of agents serves every run of the search.
    """
    out: dict[int, tuple[Any, Any, list[Any]]] = {}
    folders = {seed: Path(args.agents) / f"{slug(name)}-{seed}" for seed in args.seeds}
    missing = [seed for seed, folder in folders.items() if not (folder / "looks.json").exists()]
    if missing:
        options = RunOptions(workers=args.workers, cache_dir=args.cache_dir, progress=None)
        result = train_seeds(spec, missing, options)
        runs = {r.seed: r for r in result.runs}
        for seed in missing:
            folder = folders[seed]
            folder.mkdir(parents=True, exist_ok=True)
            sg.load_model(result, seed).save(folder / "model.zip")
            stats = Cache(args.cache_dir).model_path(result.trained or spec, seed).parent / NORMALIZER
            if stats.exists():  # VecNormalize's own file, as the cache keeps it
                shutil.copyfile(stats, folder / "normalizer.pkl")
            (folder / "looks.json").write_text(json.dumps(runs[seed].looks))
    for seed, folder in folders.items():
        assert isinstance(spec.trainer, sg.SB3)
        model = load_saved(spec.trainer.algorithm, folder / "model.zip")
        normalizer = None
        if (folder / "normalizer.pkl").exists():
            with (folder / "normalizer.pkl").open("rb") as f:
                normalizer = pickle.load(f)  # our own file, written above
        out[seed] = (model, normalizer, json.loads((folder / "looks.json").read_text()))
    return out


def importance_line(runner: EpisodeRunner, related: Any, args: argparse.Namespace, seed: int) -> str:
    """The failure rate by importance sampling from ``--importance`` episodes of the predictor's proposal, against
    the uniform draws' at as many episodes (same search seed): each with its 95% interval, and the widths' ratio."""
    f = falsify(
        runner,
        examples=1,
        uniform=args.importance,
        seed=20_000 + seed,
        shrink=False,
        related=related,
        weaker=args.weaker,
        importance=args.importance,
    )
    lo, hi = f.interval
    uniform = f"uniform {f.failure_rate:.3%} [{lo:.3%}, {hi:.3%}] ({f.uniform_failures}/{f.uniform_episodes})"
    if f.importance is None:
        return f"    rate at {args.importance} episodes: {uniform}; importance sampling: no predictor (few failures)"
    e = f.importance
    ratio = (e.high - e.low) / (hi - lo)
    return (
        f"    rate at {args.importance} episodes: {uniform}; importance sampling {e.rate:.3%} [{e.low:.3%}, "
        f"{e.high:.3%}] ({e.failures} failures; {f.drawn_by.get('related', 0)} weaker-agent episodes); "
        f"width ratio {ratio:.2f}"
    )


def run_suite(args: argparse.Namespace) -> None:
    machine = platform.processor() or platform.machine()
    print(f"machine: {machine}, {platform.system()}, Python {platform.python_version()}")
    print(f"{args.searches} guided searches per agent, at most {args.budget} episodes each, score={args.score!r}\n")
    header = f"{'case':27s} {'run':>3s} {'failure rate':>20s} {'guided found':>12s} {'guided ERT':>10s}"
    header += f" {'random found':>12s} {'random ERT':>10s} {'ratio':>6s} {'cost/ep':>8s} {'seconds':>7s}"
    print(header, flush=True)
    verdicts = []
    for name, spec, space in cases():
        if args.case and args.case not in name:
            continue
        agents = trained_agents(name, spec, args)
        for seed in args.seeds:
            began = time.perf_counter()
            model, normalizer, looks = agents[seed]
            act = batch_policy(model, normalizer, spec.deterministic)
            keys = property_keys(spec)
            runner = EpisodeRunner(spec.make_env, act, space, keys, score=args.score)
            related = from_looks(looks, keys)
            found: list[int | None] = []
            drawn_by: list[dict[str, int]] = []
            found_by: list[str | None] = []
            plain: list[int | None] = []
            for k in range(args.searches):
                f = falsify(
                    runner, examples=args.budget, uniform=0, seed=k, shrink=False, related=related, weaker=args.weaker
                )
                found.append(f.episodes_to_first if f.found else None)
                drawn_by.append(f.drawn_by)
                found_by.append(f.found_by)
                if args.compare and f.predictor is not None:  # else the very same search: nothing learned
                    f = falsify(runner, examples=args.budget, uniform=0, seed=k, shrink=False)
                plain.append(f.episodes_to_first if f.found else None)
            drawn = falsify(runner, examples=1, uniform=args.rate_draws, seed=10_000 + seed, shrink=False)
            rate = drawn.failure_rate
            guided = expected_running_time(found, args.budget)
            random = 1 / rate if rate else math.inf
            ratio = guided / random if math.isfinite(guided) and math.isfinite(random) else math.nan
            random_share = 1 - (1 - rate) ** args.budget
            cost = episode_cost(spec, model, normalizer, runner)
            share = f"{sum(f is not None for f in found)}/{len(found)}"
            print(
                f"{name:27s} {seed:3d} {rate_cell(drawn.uniform_failures, drawn.uniform_episodes):>20s}"
                f" {share:>12s} {guided:10.1f} {random_share:12.0%} {random:10.1f} {ratio:6.2f} {cost:7.2f}x"
                f" {time.perf_counter() - began:7.0f}",
                flush=True,
            )
            print(sampler_line(drawn_by, found_by), flush=True)
            if args.compare:
                ert = expected_running_time(plain, args.budget)
                print(
                    f"    without the predictor: {sum(f is not None for f in plain)}/{len(plain)} found,"
                    f" ERT {ert:.1f}, ratio {ert / random if math.isfinite(random) else math.nan:.2f}",
                    flush=True,
                )
            if args.importance:
                print(importance_line(runner, related, args, seed), flush=True)
            verdicts.append(verdict(name, seed, rate, ratio, drawn.uniform_episodes))
    print("\nsummary:\n  " + "\n  ".join(verdicts))


if __name__ == "__main__":
    sys.exit(main())
