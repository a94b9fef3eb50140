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

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from numbers import Real
from typing import Any, TypeVar

from specguard.error import InvalidSpec
from specguard.tree.keys import ROOT, check_threshold

__all__ = ["GOAL_FIXTURE", "SpecItem", "goal_spec", "goal_specs"]

F = TypeVar("F", bound=Callable[..., Any])

GOAL_FIXTURE = "specguard_goal"  # the plugin's fixture the goal items are parametrised over


def _check_expect(where: str, expect: object) -> dict[Any, float] | None:
    if expect is None:
        return None
    if isinstance(expect, Real) and not isinstance(expect, bool):
        expect = {ROOT: expect}
    if not isinstance(expect, Mapping) or not expect:
        raise InvalidSpec(where, f"expected expect to be {{goal: min success}} or a number, got {expect!r}")
    out: dict[Any, float] = {}
    for goal, value in expect.items():
        if goal is not ROOT and not isinstance(goal, str):
            raise InvalidSpec(where, f"expected goal names or paths as keys of expect, got {goal!r}")
        out[goal] = check_threshold(f"{where}.expect[{goal!r}]", value)
    return out


def goal_spec(
    expect: Mapping[str, float] | float | None = None,
    *,
    xfail: Mapping[str, str] | Sequence[str] | None = None,
) -> Callable[[F], F]:
    """Mark a test function returning a ``Spec`` as a goal spec.

    Args:
        expect: ``{goal name or path: min success}``, or one number for the
            root goal. Given here, each goal becomes its own test item (the
            report shows which goal failed) and these thresholds replace the
            spec's own ``expect``. ``None``: one item asserting the spec's ``expect``.
        xfail: goals expected to miss their threshold, with the reason
            (``{goal: reason}`` or a list of goals): they report XFAIL, and
            XPASS once they start passing.

    A malformed ``expect`` or ``xfail`` does not stop collection: the test
    becomes one item that fails with the error (naming the test and the
    option), and the session's other goal specs still run.
    """

    def apply(fn: F) -> F:
        import pytest

        where = f"goal_spec {getattr(fn, '__qualname__', fn)!r}"
        try:
            thresholds, reasons = _check_declaration(where, expect, xfail)
        except InvalidSpec as e:
            marked = pytest.mark.usefixtures(GOAL_FIXTURE)(fn)
            return pytest.mark.goal_spec(expect=None, xfail={}, error=str(e))(marked)  # type: ignore[no-any-return]
        marked = pytest.mark.usefixtures(GOAL_FIXTURE)(fn)
        return pytest.mark.goal_spec(expect=thresholds, xfail=reasons)(marked)  # type: ignore[no-any-return]

    return apply


def _check_declaration(where: str, expect: object, xfail: object) -> tuple[dict[Any, float] | None, dict[Any, str]]:
    """The decorator's thresholds and xfail reasons, checked.

    Raises:
        InvalidSpec: naming the test and what is wrong.
    """
    thresholds = _check_expect(where, expect)
    if xfail is None:
        reasons: dict[Any, str] = {}
    elif isinstance(xfail, Mapping):
        reasons = {str(k): str(v) for k, v in xfail.items()}
    elif isinstance(xfail, Sequence) and not isinstance(xfail, str):
        reasons = {str(k): "expected to miss its threshold" for k in xfail}
    else:
        raise InvalidSpec(where, f"expected xfail to be {{goal: reason}} or a list of goals, got {xfail!r}")
    if thresholds is not None and ROOT in thresholds:
        # One number asserts the root goal, which xfail calls "root".
        reasons = {ROOT if k == "root" else k: v for k, v in reasons.items()}
    if thresholds is not None:
        unknown = [g for g in reasons if g not in thresholds]
        if unknown:
            raise InvalidSpec(where, f"xfail names goals {unknown} that expect does not list: {list(thresholds)}")
    return thresholds, reasons


@dataclass(frozen=True)
class SpecItem:
    """One item of :func:`goal_specs`: a spec (by its key) and the goal the item asserts."""

    spec: str
    goal: str
    xfail: str | None = None  # the spec's reason when it expects this goal to miss

    @property
    def id(self) -> str:
        return f"{self.spec}-{self.goal}"


def goal_specs(specs: Mapping[str, Any], *, marks: Mapping[str, Any] | None = None) -> Callable[..., Any]:
    """A pytest test asserting every spec of ``specs`` by its own thresholds, one item per spec and goal.

    Assign it to a ``test_*`` name in a test module; the specs are declared once
    (their ``expect`` and ``xfail``), where ``specguard run``/``show`` and
    ``specguard reproduce`` find them too.

    Args:
        specs: ``{key: Spec}``; items are named ``test_x[key-goal/path]``.
        marks: ``{key: mark or list of marks}`` for some specs' items, e.g. an
            opt-in marker for specs that need their whole budget.

    Example:
        >>> import specguard as sg
        >>> from example_specs import pendulum
        >>> test_pendulum = sg.goal_specs({"w": pendulum.specs["w"]})
        >>> [m.name for m in test_pendulum.pytestmark]
        ['usefixtures', 'goal_spec']
    """
    import pytest

    from specguard.engine.spec import Spec

    cases: list[Any] = []
    for key, spec in specs.items():
        where = f"goal_specs[{key!r}]"
        if not isinstance(spec, Spec):
            raise InvalidSpec(where, f"expected a specguard.Spec, got {type(spec).__name__}")
        if not spec.thresholds:
            raise InvalidSpec(where, "expected a spec with thresholds (expect=...): there is nothing to assert")
        extra = (marks or {}).get(key, ())
        extra = list(extra) if isinstance(extra, (list, tuple)) else [extra]
        for goal in spec.thresholds:
            case = SpecItem(key, goal, spec.xfail.get(goal))
            cases.append(pytest.param(case, id=case.id, marks=extra))
    unknown = sorted(set(marks or {}) - set(specs))
    if unknown:
        raise InvalidSpec("goal_specs(marks=...)", f"names specs {unknown} that are not among {list(specs)}")

    def test(specguard_goal: SpecItem) -> Any:
        return specs[specguard_goal.spec]

    marked = pytest.mark.usefixtures(GOAL_FIXTURE)(test)
    return pytest.mark.goal_spec(expect=None, xfail={}, cases=cases)(marked)  # type: ignore[no-any-return]
