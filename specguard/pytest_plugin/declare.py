"""Declaring goal specs in pytest: the ``@sg.goal_spec`` decorator.

A goal spec is a test function that takes fixtures (initial envs, trees,
anything) and returns an :class:`specguard.Spec`. ``pytest --goal-specs``
trains it within its budget and asserts its thresholds; without the flag the
items are skipped with a reason saying how to run them.

Example:
    >>> import specguard as sg
    >>> @sg.goal_spec(expect={"pendulum": 0.8, "position": 0.9}, xfail={"position": "the paper's local optimum"})
    ... def test_pendulum_refined(pendulum_env, refined_tree):
    ...     return sg.Spec(pendulum_env, refined_tree, budget=sg.Budget(timesteps=100_000))
    >>> [m.name for m in test_pendulum_refined.pytestmark]
    ['usefixtures', 'goal_spec']
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

from specguard.error import InvalidSpec
from specguard.tree.keys import ROOT, check_expect, check_xfail, check_xfail_thresholded, require_thresholds

__all__ = ["FALSIFY", "GOAL_FIXTURE", "FalsifyItem", "SpecItem", "goal_spec", "goal_specs"]

F = TypeVar("F", bound=Callable[..., Any])

GOAL_FIXTURE = "specguard_goal"  # the plugin's fixture the goal items are parametrised over


def goal_spec(
    expect: Mapping[str, float] | float | None = None,
    *,
    xfail: Mapping[str, str] | Sequence[str] | None = None,
    falsify: Any = None,
) -> Callable[[F], F]:
    """Mark a test function returning a ``Spec`` (or an ``AgentCheck``: an agent to judge against it) as a goal spec.

    Args:
        expect: ``{goal name or path: min success}``, or one number for the
            root goal. Given here, each goal becomes its own test item (the
            report shows which goal failed) and these thresholds replace the
            spec's own ``expect``. ``None``: one item asserting the spec's ``expect``.
        xfail: goals expected to miss their threshold, with the reason
            (``{goal: reason}`` or a list of goals): they report XFAIL, and
            XPASS once they start passing.
        falsify: add an item ``[falsify]`` that searches each trained run's start space for
            starts from which its policy misses the spec (:class:`specguard.Falsify`; a start
            space or its ranges; ``True``: the spec's own, ``Spec.starts``, else the env's). It
            fails on a counterexample, or with ``Falsify(max_rate=...)`` on a failure rate over
            the start space above it.

    A malformed ``expect`` or ``xfail`` does not stop collection: the test
    becomes one item that fails with the error (naming the test and the
    option), and the session's other goal specs still run.
    """

    def apply(fn: F) -> F:
        import pytest

        where = f"goal_spec {getattr(fn, '__qualname__', fn)!r}"
        try:
            thresholds, reasons = _check_declaration(where, expect, xfail)
            check = _check_falsify(where, falsify)
        except InvalidSpec as e:
            marked = pytest.mark.usefixtures(GOAL_FIXTURE)(fn)
            return pytest.mark.goal_spec(expect=None, xfail={}, error=str(e))(marked)  # type: ignore[no-any-return]
        marked = pytest.mark.usefixtures(GOAL_FIXTURE)(fn)
        extra = {"falsify": check} if check is not None else {}  # the [falsify] item's check
        return pytest.mark.goal_spec(expect=thresholds, xfail=reasons, **extra)(marked)  # type: ignore[no-any-return]

    return apply


def _check_declaration(where: str, expect: object, xfail: object) -> tuple[dict[Any, float] | None, dict[Any, str]]:
    """The decorator's thresholds and xfail reasons, read by the rules a Spec's own follow (:mod:`specguard.tree.keys`).

    ``expect=None`` asserts the spec's own thresholds; given, it must hold at least one.

    Raises:
        InvalidSpec: naming the test and what is wrong.
    """
    thresholds = None if expect is None else check_expect(where, expect)
    reasons = check_xfail(where, xfail)
    if thresholds is not None:
        require_thresholds(where, thresholds)
        if ROOT in thresholds:  # one number asserts the root goal, whose item is called "root": so may its xfail be
            reasons = {ROOT if k == "root" else k: v for k, v in reasons.items()}
        check_xfail_thresholded(where, reasons, thresholds)
    return thresholds, reasons


def _check_falsify(where: str, falsify: object) -> Any:
    """The decorator's falsify check (:func:`specguard.falsify.assertion.as_falsify`), or None."""
    if falsify is None or falsify is False:
        return None
    from specguard.falsify.assertion import as_falsify

    return as_falsify(where, falsify)


@dataclass(frozen=True)
class FalsifyItem:
    """The ``[falsify]`` item of a goal spec declared with ``falsify=``."""

    def __str__(self) -> str:
        return "falsify"


FALSIFY = FalsifyItem()


@dataclass(frozen=True)
class SpecItem:
    """One item of :func:`goal_specs`: a spec (by its key) and the goal the item asserts."""

    spec: str
    goal: str
    xfail: str | None = None  # the spec's reason when it expects this goal to miss
    falsify: Any = None  # the falsify item's check (specguard.falsify.assertion.Falsify); its goal is "falsify"

    @property
    def id(self) -> str:
        return f"{self.spec}-{self.goal}"


def goal_specs(
    specs: Mapping[str, Any], *, marks: Mapping[str, Any] | None = None, falsify: Mapping[str, Any] | None = None
) -> Callable[..., Any]:
    """A pytest test asserting every spec of ``specs`` by its own thresholds, one item per spec and goal.

    Assign it to a ``test_*`` name in a test module; the specs are declared once
    (their ``expect`` and ``xfail``), where ``specguard run``/``show`` and
    ``specguard reproduce`` find them too.

    Args:
        specs: ``{key: Spec or AgentCheck}``; items are named ``test_x[key-goal/path]``. An
            :class:`~specguard.engine.check_agent.AgentCheck`'s agent is judged against its spec, not trained.
        marks: ``{key: mark or list of marks}`` for some specs' items, e.g. an
            opt-in marker for specs that need their whole budget.
        falsify: ``{key: falsify}`` for some specs: one more item ``test_x[key-falsify]``
            each, as ``goal_spec(falsify=...)`` adds.

    Example:
        >>> import specguard as sg
        >>> pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
        >>> slow = sg.Spec(pendulum, sg.Goal("slow", omega=(-0.25, 0.25)), budget=sg.Budget(timesteps=1000), expect=0.8)
        >>> test_pendulum = sg.goal_specs({"slow": slow})
        >>> [m.name for m in test_pendulum.pytestmark]
        ['usefixtures', 'goal_spec']
    """
    import pytest

    from specguard.spec.spec import Spec

    # an AgentCheck's module is loaded where one was made; not importing it keeps collection light
    agent_check = getattr(sys.modules.get("specguard.engine.check_agent"), "AgentCheck", ())
    cases: list[Any] = []
    for key, value in specs.items():
        where = f"goal_specs[{key!r}]"
        spec = value.spec if isinstance(value, agent_check) else value
        if not isinstance(spec, Spec):
            raise InvalidSpec(where, f"expected a specguard.Spec or a specguard.AgentCheck, got {type(value).__name__}")
        require_thresholds(where, spec.thresholds)
        extra = (marks or {}).get(key, ())
        extra = list(extra) if isinstance(extra, (list, tuple)) else [extra]
        for goal in spec.thresholds:
            case = SpecItem(key, goal, spec.xfail.get(goal))
            cases.append(pytest.param(case, id=case.id, marks=extra))
        if key in (falsify or {}):
            check = _check_falsify(f"goal_specs(falsify={{{key!r}: ...}})", (falsify or {})[key])
            if check is not None:
                case = SpecItem(key, "falsify", falsify=check)
                cases.append(pytest.param(case, id=case.id, marks=extra))
    for option, given in (("marks", marks), ("falsify", falsify)):
        unknown = sorted(set(given or {}) - set(specs))
        if unknown:
            raise InvalidSpec(f"goal_specs({option}=...)", f"names specs {unknown} that are not among {list(specs)}")

    def test(specguard_goal: SpecItem) -> Any:
        return specs[specguard_goal.spec]

    marked = pytest.mark.usefixtures(GOAL_FIXTURE)(test)
    return pytest.mark.goal_spec(expect=None, xfail={}, cases=cases)(marked)  # type: ignore[no-any-return]
