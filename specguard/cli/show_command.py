"""``specguard show PATH[::NAME]``: the tree, reward formula, observation layout and budget of a file's specs (and
its trees), training nothing; a pytest goal-spec file's under pytest, which resolves its fixtures."""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from typing import Any

from specguard.spec.loading import load_objects, spec_path
from specguard.spec.spec import Spec
from specguard.tree.nodes import Node

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    show = sub.add_parser(
        "show",
        help="print the tree, reward formula, observation layout and budget of specs in a file "
        "(a pytest goal-spec file too), training nothing",
    )
    show.add_argument("target", metavar="PATH[::NAME]")


def run(args: argparse.Namespace, argv: Sequence[str]) -> int:
    target = args.target
    from specguard.report.show import has_goal_specs, render_spec, render_tree, show_goal_spec_file

    if has_goal_specs(spec_path(target)):  # a pytest file: only pytest resolves its fixtures
        return show_goal_spec_file(target)
    for name, obj in load_objects(target, (Spec, Node)).items():
        if isinstance(obj, Spec):
            print(render_spec(obj, name))
        else:
            print("\n".join([f"== {name}", *render_tree(obj)]))
        print()
    return 0
