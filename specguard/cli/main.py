"""The ``specguard`` command line.

``specguard show PATH[::NAME]`` prints the tree and the reward formula of the
specs (or trees) a Python file defines; ``specguard plan PATH[::NAME]`` prints
what each spec's gate can see, training nothing (:mod:`specguard.gate.plan`);
``specguard run PATH[::NAME]`` trains
them within their budgets and prints the per-goal table; ``specguard reproduce
PATH...`` trains every spec of case-study files on several seeds and writes a
Markdown table and plots (:mod:`specguard.engine.reproduce`,
:mod:`specguard.report.reproduction`). A file's specs are its
module-level ``Spec`` objects (named by variable) and the values of its
module-level dicts of specs (named by key); ``show`` also lists goal trees.

``specguard falsify PATH[::NAME]`` searches each trained run's start space for
starts from which it misses the spec; with ``--agent AGENT`` (and ``--algorithm``, ``--observation``, as ``check``
takes them), an agent trained elsewhere instead, training nothing
(:func:`specguard.engine.falsify_run.falsify_agent`). Its exit status: 0 when nothing was found, 1 when a
counterexample was, 2 for bad input (an agent that cannot be loaded, or whose spaces do not fit the env, in one line).

``specguard check PATH[::NAME] --agent AGENT`` judges an agent trained elsewhere (a saved SB3 or sb3-contrib zip, an
rl-zoo3 or Hub folder) against each spec, training nothing (:func:`specguard.engine.check_agent.check_agent`), and
prints the same table as ``run``; its exit status is ``run``'s: 0 when every spec passed, 1 when one failed, 2 for bad
input (an agent that cannot be loaded, or whose spaces do not fit the env, is one line naming it).

``run`` says pytest's words for the same run, per goal and per spec
(:func:`specguard.stats.verdicts.verdict_word`): ``passed``, ``failed``
(``FAILED`` on the spec's line), ``xfailed`` (a goal the spec declares in
``xfail`` missed), ``xpassed`` (it passed), and ``undecided`` (with what it
counts as).

Exit status of ``run``: 0 when every spec passed (a goal the spec declares in
``xfail`` may miss; an undecided goal counts as ``Spec.undecided`` or
``--undecided`` says), 1 when one failed, 2 for a usage or spec error (a spec
with no threshold has nothing to assert: refused before anything trains, as
``pytest --goal-specs`` refuses it). A ``--json`` file that cannot be written at
the end is a warning that says where the results went instead; the exit status
stays the verdicts'. Bad input (a path that is no Python file of specs, a spec
file that exits at import, a bad option value) is one line naming it, exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from specguard.cli import (
    check_command,
    falsify_command,
    plan_command,
    reproduce_command,
    run_command,
    show_command,
)
from specguard.error import SpecError
from specguard.version import __version__

__all__ = ["COMMANDS", "build_parser", "main"]

COMMANDS = {
    "show": show_command,
    "plan": plan_command,
    "run": run_command,
    "reproduce": reproduce_command,
    "falsify": falsify_command,
    "check": check_command,
}
"""The subcommands, one module each: ``add_parser(sub)`` adds its parser, ``run(args, argv)`` runs it (its exit
status)."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="specguard",
        description="Goal-tree specifications for RL: show a spec, plan what its gate can see, run (train and "
        "judge) it, reproduce the case studies, falsify a trained spec, check an agent trained elsewhere.",
    )
    parser.add_argument("--version", action="version", version=f"specguard {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS.values():
        command.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    try:
        return int(COMMANDS[args.command].run(args, argv))
    except SpecError as e:
        print(f"specguard: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("specguard: interrupted; finished runs are cached, unfinished ones were not stored", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
