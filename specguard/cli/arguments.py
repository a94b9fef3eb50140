"""What the subcommands share: the options' types (each from its shared check), an agent's options, a file's
specs, and the ``--json`` file written without losing the results."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from specguard.error import ExecutorError, InvalidSpec, SpecError
from specguard.parallel.executors import check_address
from specguard.parallel.workers import parse_workers
from specguard.spec.loading import load_objects, spec_path
from specguard.spec.spec import Spec
from specguard.stats.anytime import parse_checkpoints
from specguard.stats.verdicts import UNDECIDED_OUTCOMES
from specguard.utils.atomic import write_atomic
from specguard.utils.parsing import parse_choice, parse_count, parse_natural, parse_positive

__all__ = [
    "add_agent",
    "case_scale",
    "checkpoints",
    "executor",
    "natural",
    "option",
    "positive",
    "prepare_json",
    "scale",
    "specs_of",
    "spread",
    "undecided",
    "workers",
    "wrap_of",
    "write_results",
]

_T = TypeVar("_T")


def option(parse: Callable[[str], _T]) -> Callable[[str], _T]:
    """An option's argparse type from its shared check (:mod:`specguard.utils.parsing` and the rules built on it).

    The check's message (a ``ValueError``'s, or a ``SpecError``'s without where
    and hint) becomes argparse's usage error: ``argument --NAME: <message>``, exit status 2.
    """

    def convert(text: str) -> _T:
        try:
            return parse(text)
        except InvalidSpec as e:
            raise argparse.ArgumentTypeError(e.message) from None
        except ExecutorError as e:
            raise argparse.ArgumentTypeError(e.message.removeprefix("executor: ")) from None
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    convert.__name__ = getattr(parse, "__name__", "value")  # argparse names a type by it
    return convert


def parse_undecided(text: str) -> str:
    return parse_choice(text, UNDECIDED_OUTCOMES)


def parse_spread(text: str) -> float:
    """A standard deviation of per-seed success: a finite number in (0, 0.5)."""
    value = parse_positive(text, "a standard deviation of success, below 0.5")
    if value >= 0.5:
        raise ValueError(f"expected a standard deviation of success below 0.5, got {text!r}")
    return value


def parse_case_scale(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise ValueError(f"expected CASE=X, e.g. lunar_lander=0.5, got {text!r}")
    return name, parse_positive(value)


workers = option(parse_workers)
executor = option(check_address)
checkpoints = option(parse_checkpoints)
undecided = option(parse_undecided)
scale = option(parse_positive)
spread = option(parse_spread)
positive = option(parse_count)
case_scale = option(parse_case_scale)


def natural(meaning: str) -> Callable[[str], int]:
    """An option's type: an integer >= 0 (:func:`specguard.utils.parsing.parse_natural`); ``meaning`` names it."""

    def natural(text: str) -> int:
        return parse_natural(text, meaning)

    return option(natural)


def specs_of(target: str, command: str) -> dict[str, Spec]:
    """The specs of ``target`` for ``command``; a pytest goal-spec file that defines none (its specs are made by
    ``@goal_spec`` functions, an agent's as an ``sg.AgentCheck``) is refused with the pytest command that runs it."""
    from specguard.report.show import has_goal_specs

    path = spec_path(target)
    try:
        return load_objects(target)
    except SpecError as e:
        if not (has_goal_specs(path) and e.message.endswith("defines no Spec objects")):
            raise
        raise SpecError(
            f"{e.message}: it is a pytest goal-spec file, whose @goal_spec functions make their specs (and return "
            f"their agents, as sg.AgentCheck) under pytest; specguard {command} takes Spec objects",
            hint=f"pytest --goal-specs {path}",
        ) from None


def prepare_json(text: str) -> Path:
    """The ``--json`` file, its directory created now: a bad path must not cost a training run."""
    path = Path(text)
    if path.is_dir():
        raise SpecError(f"--json {path}: is a directory; expected a file name, e.g. {path / 'results.json'}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise SpecError(f"--json {path}: cannot create the directory {path.parent} ({e.strerror or e})") from e
    if not os.access(path.parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise SpecError(f"--json {path}: not writable; expected a file in a directory you can write to")
    return path


def write_results(path: Path, text: str) -> None:
    """Write ``--json``'s results; a write that fails warns in one line and keeps them.

    Kept in a temporary file it names, else printed on stdout; the exit status
    stays the verdicts' (the training is done: its results are not lost to a full disk).
    """
    try:
        write_atomic(path, text)
        return
    except OSError as e:
        reason = e.strerror or str(e)
    where = f"specguard: warning: --json {path}: could not write it ({reason}); the results"
    try:
        handle, name = tempfile.mkstemp(prefix=f"specguard-{path.stem}-", suffix=".json")
        with os.fdopen(handle, "w", encoding="utf-8") as f:
            f.write(text)
    except OSError:
        print(f"{where} follow on stdout", file=sys.stderr)
        print(text)
        return
    print(f"{where} are in {name}", file=sys.stderr)


def add_agent(parser: argparse.ArgumentParser, *, required: bool, instead: str = "") -> None:
    """The options naming an agent trained elsewhere and what it sees: ``--agent``, ``--algorithm``,
    ``--observation`` (``check``'s and ``falsify``'s)."""
    from specguard.engine.check_agent import AGENT_OBSERVATIONS

    parser.add_argument(
        "--agent",
        required=required,
        default=None,
        help="the agent: an SB3 or sb3-contrib .zip, an rl-zoo3 or Hugging Face Hub folder, or FILE.py::NAME, a "
        "policy (a callable obs -> action, or an object with predict) defined in a Python file" + instead,
    )
    parser.add_argument("--algorithm", default=None, help="the zip's algorithm, e.g. PPO (default: read from the file)")
    parser.add_argument(
        "--wrap",
        default=None,
        metavar="FILE.py::NAME",
        help="the observation wrappers the agent was trained with: a function env -> env defined in a Python file "
        "(default: those an rl-zoo3 config.yml names, frame_stack and env_wrapper)",
    )
    parser.add_argument(
        "--trust-agent",
        action="store_true",
        help="run the code the agent's files may hold (a zip's pickled fields, a vecnormalize.pkl), as SB3's load "
        "does; by default they are decoded without running any (arrays, spaces, SB3's own classes) and a file that "
        "needs more is refused, naming the field",
    )
    parser.add_argument(
        "--observation",
        choices=AGENT_OBSERVATIONS,
        default="env",
        help="what the agent sees: env, the initial env's own observation (default), or spec, the constructed env's",
    )


def wrap_of(args: argparse.Namespace) -> Callable[[Any], Any] | None:
    """``--wrap FILE.py::NAME``'s function, or ``None``."""
    from specguard.agents.sources import named_object

    if args.wrap is None:
        return None
    if args.agent is None:
        raise SpecError(f"--wrap names the --agent's wrappers, and no --agent is given (--wrap {args.wrap})", hint=None)
    wrap = named_object(args.wrap, "wrap", example="wrappers.py::stacked")
    if not callable(wrap):
        raise SpecError(f"wrap {args.wrap!r}: expected a function env -> env, got a {type(wrap).__name__}", hint=None)
    return wrap  # type: ignore[no-any-return]
