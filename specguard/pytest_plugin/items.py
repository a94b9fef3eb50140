"""Goal-spec items: which spec an item belongs to, the spec it returns with its thresholds, and its outcome in pytest.

The one sequence every goal item runs (a training item, and one under
``--goal-specs-show``): call the test function with its fixtures, check that
it returned a ``Spec`` (or an ``AgentCheck``, an agent trained elsewhere to judge
against its spec), apply the item's thresholds; a ``SpecError`` on the way fails
the item with one line.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator, Sequence
from typing import Any

import pytest

from specguard.error import GoalMissed, RunsCrashed
from specguard.pytest_plugin.declare import GOAL_FIXTURE, FalsifyItem, SpecItem

__all__ = [
    "PROPERTY",
    "GoalMissed",
    "detailed",
    "falsify_check",
    "goal_of",
    "group_of",
    "one_line_errors",
    "raise_outcome",
    "spec_of",
]

PROPERTY = "specguard"
"""The user property that carries a goal item's row (its junit properties are ``specguard.<goal>.<name>``)."""


def group_of(item: pytest.Item) -> str:
    """The item's spec: its test without the goal parameter (one training for all its goals)."""
    assert isinstance(item, pytest.Function)
    callspec = getattr(item, "callspec", None)
    case = callspec.params.get(GOAL_FIXTURE) if callspec is not None else None
    if isinstance(case, SpecItem):
        return f"{item.path.name}::{item.originalname}[{case.spec}]"
    ids = list(getattr(callspec, "_idlist", []))
    params = list(callspec.params) if callspec is not None else []
    if callspec is not None and GOAL_FIXTURE in params and len(ids) == len(params):
        del ids[params.index(GOAL_FIXTURE)]
    suffix = f"[{'-'.join(ids)}]" if ids else ""
    return f"{item.path.name}::{item.originalname}{suffix}"


def goal_of(item: pytest.Function) -> Any:
    """The goal the item asserts (``None``: every threshold of its spec, as the ``[falsify]`` item does)."""
    goal = item.funcargs.get(GOAL_FIXTURE)
    if isinstance(goal, FalsifyItem) or (isinstance(goal, SpecItem) and goal.falsify is not None):
        return None
    return goal.goal if isinstance(goal, SpecItem) else goal  # sg.goal_specs: the spec's own thresholds


def falsify_check(item: pytest.Function, marker: pytest.Mark) -> Any:
    """The check of a ``[falsify]`` item (``goal_spec(falsify=...)``, ``goal_specs(falsify=...)``), or None."""
    param = item.callspec.params.get(GOAL_FIXTURE) if hasattr(item, "callspec") else None
    if isinstance(param, FalsifyItem):
        return marker.kwargs["falsify"]
    return param.falsify if isinstance(param, SpecItem) else None


def where(item: pytest.Item) -> str:
    """The item as messages name it: ``file.py::test[goal]``."""
    return f"{item.path.name}::{item.name}"


def detailed(config: pytest.Config) -> bool:
    """Whether the user asked for details: ``-v`` or ``--tb=long``."""
    return bool(config.get_verbosity() > 0 or config.getoption("tbstyle", "auto") == "long")


@contextlib.contextmanager
def one_line_errors(item: pytest.Item) -> Iterator[None]:
    """Fail ``item`` with one line for a ``SpecError`` raised inside (with its notes under ``-v``)."""
    from specguard.error import SpecError

    error: str | None = None
    try:
        yield
    except SpecError as e:
        error = f"{where(item)}: {e}"
        if detailed(item.config):  # a worker's own traceback only when asked for
            error += "".join(f"\n\n{note}" for note in getattr(e, "__notes__", ()))
    if error is not None:  # one message, not a chain of two (this runs while the with-block's error unwinds)
        raise pytest.fail.Exception(error, pytrace=False) from None


def spec_of(item: pytest.Function, expect: Any) -> tuple[Any, list[str], Any]:
    """Call the item's function with its fixtures and apply its thresholds: the ``Spec``, the goals it asserts, and
    the :class:`~specguard.engine.check_agent.AgentCheck` (with those thresholds) when it returned one, else None.

    Fails the item when the function returns neither; call it inside
    :func:`one_line_errors`, which turns a ``SpecError`` into the item's one line.
    """
    import dataclasses

    from specguard.engine.check_agent import AgentCheck
    from specguard.pytest_plugin.judge import with_thresholds
    from specguard.spec.spec import Spec

    returned = item.obj(**{name: item.funcargs[name] for name in item._fixtureinfo.argnames})
    agent = returned if isinstance(returned, AgentCheck) else None
    if agent is None and not isinstance(returned, Spec):
        pytest.fail(
            f"{where(item)}: a goal spec must return a specguard.Spec or a specguard.AgentCheck, got "
            f"{type(returned).__name__}",
            pytrace=False,
        )
    spec, paths = with_thresholds(agent.spec if agent is not None else returned, expect, goal_of(item))
    return spec, paths, dataclasses.replace(agent, spec=spec) if agent is not None else None


def raise_outcome(item: pytest.Function, checks: Sequence[Any], undecided_as: str, result: Any) -> None:
    """The item's pytest outcome from its goals' checks: pass, ``GoalMissed``, xfail, or pass with a warning.

    Runs that crashed fail the item with :class:`~specguard.error.RunsCrashed`, which an ``xfail`` goal does not
    expect: a run that never finished says nothing about the goal.

    ``undecided_as`` is the session's ``--goal-specs-undecided``: what a goal whose
    runs stayed undecided does (fail, xfail or pass).
    """
    from specguard.stats.verdicts import UNDECIDED_AS, GoalOutcome, Word

    counts_as = UNDECIDED_AS[undecided_as]
    failures = [c.message() for c in checks if c.outcome is GoalOutcome.FAILED]
    undecided = [c.message() for c in checks if c.outcome is GoalOutcome.UNDECIDED]
    if result.errors or failures or (undecided and counts_as is Word.FAILED):
        text = "\n\n".join(failures + undecided)
        if detailed(item.config) and result.tracebacks:
            text += "".join(f"\n\nworker traceback (seed {k}):\n{tb}" for k, tb in sorted(result.tracebacks.items()))
        if result.errors:  # a crash is no miss: an xfail goal (which expects GoalMissed) fails too
            crashed = "\n".join(f"seed {seed} failed: {error}" for seed, error in sorted(result.errors.items()))
            raise RunsCrashed(
                f"runs crashed (a crash is not a miss, even for a goal expected to miss):\n{crashed}\n\n{text}"
            )
        raise GoalMissed(text)
    if undecided and counts_as is Word.XFAILED:
        pytest.xfail("undecided: " + "\n\n".join(undecided))
    if undecided:
        warnings.warn(
            "undecided goal spec passed by --goal-specs-undecided=pass:\n" + "\n".join(undecided), stacklevel=1
        )
