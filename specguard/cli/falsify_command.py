"""``specguard falsify PATH[::NAME]``: search each trained run's start space for starts from which it misses the
spec; with ``--agent``, an agent trained elsewhere instead, training nothing
(:func:`specguard.engine.falsify_run.falsify_agent`). Exit 0 when nothing was found, 1 when a counterexample was."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from specguard.cli import arguments
from specguard.error import SpecError
from specguard.utils.atomic import DEFAULT_CACHE_DIR
from specguard.validation import check_unique

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    from specguard.falsify.robustness import SCORES

    fz = sub.add_parser(
        "falsify",
        help="search a spec's start space for starts from which its trained agents (or --agent) miss the spec",
    )
    fz.add_argument("target", metavar="PATH[::NAME]")
    arguments.add_agent(fz, required=False, instead="; default: the spec's own trained runs")
    fz.add_argument(
        "--seed", type=arguments.natural("the search's seed"), default=0, help="the search's seed (default: 0)"
    )
    fz.add_argument(
        "--examples", type=arguments.positive, default=200, help="guided episodes per run at most (default: 200)"
    )
    fz.add_argument(
        "--uniform",
        type=arguments.natural("uniform draws"),
        default=100,
        help="uniform draws for the failure rate, 0 for none (default: 100)",
    )
    fz.add_argument(
        "--weaker",
        type=arguments.natural("episodes per level of the agent made weaker"),
        default=0,
        help="episodes per level of the agent with epsilon-random actions, the failure predictor's data; they count "
        "among the guided episodes (default: 0, none; a trained run's looks are its data)",
    )
    fz.add_argument(
        "--importance",
        type=arguments.natural("importance-sampling episodes"),
        default=0,
        help="episodes for the failure rate by importance sampling from the failure predictor, 0 for none (default: 0)",
    )
    fz.add_argument(
        "--score",
        choices=SCORES,
        default="last",
        help="the score that steers the search: last, each key's margin in the episode's last state (default), or "
        "episode, over the whole episode (signal temporal logic's; dearer per episode)",
    )
    fz.add_argument(
        "--starts",
        type=_start_range,
        nargs="+",
        metavar="NAME=LO:HI",
        help="start ranges of the env's state variables (default: the spec's own, Spec.starts, else the env's)",
    )
    fz.add_argument(
        "--cache-dir",
        default=DEFAULT_CACHE_DIR,
        help=f"run cache, and its falsify/ the counterexamples (default: {DEFAULT_CACHE_DIR})",
    )
    fz.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def _start_range(text: str) -> tuple[str, tuple[float, float]]:
    """``--starts NAME=LO:HI`` (e.g. ``theta=-0.1:0.1``)."""
    name, _, rng = text.partition("=")
    lo, _, hi = rng.partition(":")
    try:
        return name.strip(), (float(lo), float(hi))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected NAME=LO:HI, e.g. theta=-0.1:0.1, got {text!r}") from None


def run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Train (or find in the cache) each spec, then search its start space for counterexamples, per run; with
    ``--agent``, the agent's instead, training nothing."""
    from specguard.engine.falsify_run import falsify_agent, falsify_runs, start_space
    from specguard.engine.run_spec import run_spec
    from specguard.starts.space import StartSpace
    from specguard.training.progress import print_event

    starts = StartSpace(check_unique("--starts", args.starts)) if args.starts else None  # None: the spec's own
    found_any = False
    specs = arguments.specs_of(args.target, "falsify")
    for spec in specs.values():  # names and bounds checked before anything trains
        start_space(spec, starts).resolve(spec.initial_env.make())
    say = None if args.quiet else (lambda line: print(f"[specguard] {line}", file=sys.stderr))
    if args.agent is None and args.algorithm is not None:
        raise SpecError("falsify: --algorithm names the --agent's algorithm, and no --agent is given", hint=None)
    for name, spec in specs.items():
        if args.agent is not None:
            f = falsify_agent(
                spec,
                args.agent,
                starts,
                examples=args.examples,
                uniform=args.uniform,
                search_seed=args.seed,
                database=Path(args.cache_dir) / "falsify",
                progress=say,
                observation=args.observation,
                algorithm=args.algorithm,
                score=args.score,
                trust=args.trust_agent,
                wrap=arguments.wrap_of(args),
                weaker=args.weaker,
                importance=args.importance,
            )
            print(f"== {name} agent {args.agent}: {'COUNTEREXAMPLE' if f.found else 'none found'}")
            print(f.report())
            print()
            found_any = found_any or f.found
            continue
        quiet = args.quiet
        result = run_spec(spec, cache_dir=args.cache_dir, progress=None if quiet else print_event)
        found = falsify_runs(
            result,
            starts,
            examples=args.examples,
            uniform=args.uniform,
            search_seed=args.seed,
            progress=say,
            score=args.score,
            weaker=args.weaker,
            importance=args.importance,
        )
        for seed, f in found.items():
            print(f"== {name} seed {seed}: {'COUNTEREXAMPLE' if f.found else 'none found'}")
            print(f.report())
            print()
            found_any = found_any or f.found
    return 1 if found_any else 0
