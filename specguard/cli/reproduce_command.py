"""``specguard reproduce PATH...``: train every spec of case-study files on several seeds at their whole budget,
and write a Markdown table beside the paper's figures and plots of success over training
(:mod:`specguard.engine.reproduce`, :mod:`specguard.report.reproduction`); ``--replot`` redraws the plots only."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from specguard.cli import arguments
from specguard.error import SpecError
from specguard.utils.atomic import DEFAULT_CACHE_DIR

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    rep = sub.add_parser(
        "reproduce",
        help="train every spec of the case-study files on N seeds at their whole budget; write a Markdown "
        "table beside the paper's figures and plots of success over training",
    )
    rep.add_argument("targets", metavar="PATH", nargs="*", help="case-study files (their specs and PAPER figures)")
    rep.add_argument(
        "--replot",
        action="store_true",
        help="train nothing: redraw the plots beside --out from the curve data written with them",
    )
    rep.add_argument("--seeds", type=arguments.positive, default=5, help="seeds per spec (default: 5)")
    rep.add_argument("--budget-scale", type=arguments.scale, default=1.0, help="multiply training timesteps, e.g. 0.5")
    rep.add_argument(
        "--case-scale",
        type=arguments.case_scale,
        action="append",
        default=[],
        metavar="CASE=X",
        help="another budget scale for one case (its file's stem), e.g. lunar_lander=0.5; repeatable",
    )
    rep.add_argument(
        "--workers",
        type=arguments.workers,
        default="auto",
        help="specs trained at once, one process each (default: auto)",
    )
    rep.add_argument(
        "--cache-dir", default=DEFAULT_CACHE_DIR, help=f"run cache, to resume (default: {DEFAULT_CACHE_DIR})"
    )
    rep.add_argument("--out", default="docs/reproduction.md", help="the Markdown file; plots go to images/ beside it")
    rep.add_argument("--quiet", action="store_true", help="no progress lines on stderr")


def run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    from specguard.engine.reproduce import load_case, reproduce
    from specguard.parallel.workers import resolve_workers
    from specguard.report.reproduction import replot, write_markdown
    from specguard.training.progress import print_event

    if args.replot:
        if args.targets:
            raise SpecError("reproduce --replot trains nothing: give no case files", hint="drop the PATHs")
        drawn = replot(Path(args.out).parent / "images")
        print(f"redrew {len(drawn)} plots: " + ", ".join(str(p) for p in drawn) if drawn else "no curve data found")
        return 0
    if not args.targets:
        raise SpecError("reproduce: expected at least one case-study file", hint="e.g. example_specs/pendulum.py")

    cases = [load_case(path) for path in args.targets]
    command = "specguard " + " ".join(argv)
    result = reproduce(
        cases,
        seeds=args.seeds,
        budget_scale=args.budget_scale,
        case_scales=dict(args.case_scale),
        workers=resolve_workers(args.workers),
        cache_dir=args.cache_dir,
        progress=None if args.quiet else print_event,
        command=command,
    )
    out = write_markdown(result, Path(args.out))
    print(f"wrote {out} and its plots")
    return 0
