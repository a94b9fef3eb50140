"""``specguard plan PATH[::NAME]``: what each spec's gate can see, training nothing (:mod:`specguard.gate.plan`)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from specguard.cli import arguments
from specguard.spec.loading import load_objects, spec_path

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    from specguard.stats.power import DEFAULT_SPREAD
    from specguard.stats.sequential import DEFAULT_COMPARE_SEEDS

    plan = sub.add_parser(
        "plan",
        help="print what each spec's gate can see, training nothing: the chance a run is judged met around each "
        "threshold, and the smallest drop a comparison with a baseline flags with 80%% power",
    )
    plan.add_argument("target", metavar="PATH[::NAME]")
    plan.add_argument(
        "--spread",
        type=arguments.spread,
        default=DEFAULT_SPREAD,
        metavar="S",
        help=f"seed-to-seed spread of success (standard deviation of per-seed success) to assume "
        f"(default: {DEFAULT_SPREAD:g})",
    )
    plan.add_argument(
        "--compare-seeds",
        type=arguments.positive,
        default=DEFAULT_COMPARE_SEEDS,
        metavar="N",
        help=f"the most seeds a comparison trains and a saved baseline stores, as --goal-specs-compare-seeds "
        f"(default {DEFAULT_COMPARE_SEEDS}, or a spec's max_seeds if more)",
    )
    plan.add_argument(
        "--comparisons",
        type=arguments.positive,
        default=None,
        metavar="N",
        help="comparisons in a session, over which the family-wise 5%% is shared (default: the thresholded "
        "goals and safety rates of the specs planned)",
    )


def run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from specguard.gate.plan import plan_spec
    from specguard.report.plan_lines import plan_lines
    from specguard.report.show import has_goal_specs, plan_goal_spec_file

    if has_goal_specs(spec_path(args.target)):  # a pytest file: only pytest resolves its fixtures
        return plan_goal_spec_file(args.target, compare_seeds=args.compare_seeds)
    specs = load_objects(args.target)
    family = args.comparisons or max(1, sum(len(spec.thresholds) for spec in specs.values()))
    for name, spec in specs.items():
        if not spec.thresholds:
            print(f"== {name}: no thresholds, nothing to judge or compare\n")
            continue
        plan = plan_spec(spec, family=family, compare_seeds=args.compare_seeds, spread=args.spread, label=name)
        print("\n".join(plan_lines(plan)))
        print()
    return 0
