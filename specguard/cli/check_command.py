"""``specguard check PATH[::NAME] --agent AGENT``: judge an agent trained elsewhere against each spec, training
nothing (:func:`specguard.engine.check_agent.check_agent`), and print ``run``'s table; ``--against OLD`` gates it
against the agent it replaces on the same episodes. Exit 1 when a spec failed (or a goal dropped)."""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from typing import Any

from specguard.cli import arguments
from specguard.tree.keys import require_thresholds
from specguard.utils.atomic import DEFAULT_CACHE_DIR

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    ck = sub.add_parser(
        "check",
        help="judge an agent trained elsewhere (a saved model, an rl-zoo3 or Hub folder) against specs, "
        "training nothing",
    )
    ck.add_argument("target", metavar="PATH[::NAME]")
    arguments.add_agent(ck, required=True)
    ck.add_argument(
        "--against",
        default=None,
        metavar="OLD",
        help="gate the agent against the one it replaces, on the same episodes: exit 1 also when a goal or safety "
        "rate dropped (exact one-sided McNemar test, Holm's procedure at family-wise 5%%)",
    )
    ck.add_argument(
        "--episodes",
        type=arguments.positive,
        default=None,
        metavar="N",
        help="evaluation episodes of the first stage (default: the spec's Budget.eval_episodes)",
    )
    ck.add_argument(
        "--max-episodes",
        type=arguments.positive,
        default=None,
        metavar="N",
        help="the most evaluation episodes, doubled up to while a goal is undecided "
        "(default: the spec's Budget.max_eval_episodes)",
    )
    ck.add_argument(
        "--seed",
        type=arguments.natural("the evaluation seeds' run"),
        default=0,
        help="which evaluation seeds (default: 0)",
    )
    ck.add_argument(
        "--undecided",
        type=arguments.undecided,
        default=None,
        help="what a goal still undecided counts as: fail, xfail or pass (default: the spec's own Spec.undecided)",
    )
    ck.add_argument("--cache-dir", default=DEFAULT_CACHE_DIR, help=f"evaluation cache (default: {DEFAULT_CACHE_DIR})")
    ck.add_argument("--no-cache", action="store_true", help="neither read nor write the cache")
    ck.add_argument("--json", metavar="FILE", help="also write the results as JSON (missing directories are created)")


def run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    """Judge the agent against each spec, training nothing; 1 when a spec failed."""
    from specguard.engine.check_agent import check_agent
    from specguard.gate.agent_gate import compare_agents
    from specguard.report.table import table

    specs = arguments.specs_of(args.target, "check")
    for name, spec in specs.items():  # before any episode: a spec with nothing to assert has no verdict
        require_thresholds(f"{args.target.partition('::')[0]}::{name}", spec.thresholds)
    json_path = arguments.prepare_json(args.json) if args.json else None
    results = {}
    failed = False
    for name, spec in specs.items():
        options = {
            "episodes": args.episodes,
            "max_episodes": args.max_episodes,
            "observation": args.observation,
            "seed": args.seed,
            "algorithm": args.algorithm,
            "trust": args.trust_agent,
            "wrap": arguments.wrap_of(args),
        }
        run = spec.as_run(undecided=args.undecided)
        if args.against is None:
            result = check_agent(run, args.agent, cache_dir=None if args.no_cache else args.cache_dir, **options)
            results[name] = result.to_dict()
        else:
            comparison = compare_agents(run, args.agent, args.against, **options)
            result = comparison.result
            results[name] = {**result.to_dict(), "comparison": comparison.to_dict()}
        print(f"== {name}: {result.status()} ({result.seconds:.1f}s)")
        print(table(result))
        if args.against is not None:
            print(f"-- against {args.against}: {'DROPPED' if comparison.dropped else 'passed'}")
            print(_comparison_table(comparison))
            print(comparison.summary())
        print()
        # one rule with the Python object: AgentComparison.passed is the check as expected and nothing dropped
        failed = failed or not (result.as_expected if args.against is None else comparison.passed)
    if json_path is not None:
        arguments.write_results(json_path, json.dumps(results, indent=1))
    return 1 if failed else 0


def _comparison_table(comparison: Any) -> str:
    """Per goal and safety rate: the old and new agents' successes, the drop's bound, the p-value, the state."""
    from specguard.tree.keys import label

    rows = [("goal", "old", "new", "lost/gained", "drop <=", "p", "state")]
    for key, k in comparison.keys.items():
        rows.append(
            (
                label(key),
                f"{k.old}/{k.episodes}",
                f"{k.new}/{k.episodes}",
                f"{k.lost}/{k.gained}",
                f"{k.bound:+.1%}",
                f"{k.p_value:.3g}",
                k.state.value,
            )
        )
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows)
