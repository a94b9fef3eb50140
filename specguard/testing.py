"""Testing tools: the operator contract kit and a simulator-free test double.

For authors of operators and annotations (:mod:`specguard.extend`): each
check of :mod:`specguard.contract.invariants` states one invariant of the operator contract
(docs/semantics.md, "What the contract kit checks")
and tests it with Hypothesis on random trees that contain the class, the way
scikit-learn's ``parametrize_with_checks`` tests an estimator.

* :func:`parametrize_with_checks`: one pytest item per class and check
  (ids like ``AnyOf-check_markov``);
* :func:`check_operator`: every check that applies, in one call;
* :data:`CHECKS`: the checks; :func:`checks_for`: those that apply to a class;
* :class:`ReplayEnv`: an env replaying a fixed trajectory, a host for trees.

Importing this module imports neither pytest nor Hypothesis; the checks do, when used.

Example:
    In a test module::

        from specguard.testing import parametrize_with_checks
        from my_operators import AtLeast

        @parametrize_with_checks([AtLeast])
        def test_contract(operator, check):
            check(operator)

    The items it makes:

    >>> import specguard as sg
    >>> from specguard.testing import ReplayEnv, check_operator, parametrize_with_checks
    >>> marker = parametrize_with_checks([sg.All, sg.Distance])
    >>> [param.id for param in marker.args[1]][:2]
    ['All-check_observations_in_space', 'All-check_rewards_are_finite_sums_of_terms']
    >>> check_operator(sg.Constraint, max_examples=3)

    A goal tree over a replayed trajectory:

    >>> initial = sg.InitialEnv(lambda: ReplayEnv([[0.0], [1.0]]), features=("x",))
    >>> env = sg.make_env(initial, sg.Goal("up", x=(0.5, None)))
    >>> _ = env.reset(seed=0)
    >>> env.step(0)[1:3]
    (1.0, True)
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from specguard.contract.replay import ReplayEnv

if TYPE_CHECKING:
    import pytest

    from specguard.contract.invariants import CHECKS

__all__ = ["CHECKS", "ReplayEnv", "check_operator", "checks_for", "parametrize_with_checks"]


def __getattr__(name: str) -> Any:
    # CHECKS lives in specguard.contract.invariants, which imports Hypothesis: load it on first use only.
    if name == "CHECKS":
        from specguard.contract.invariants import CHECKS

        return CHECKS
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def checks_for(cls: type) -> tuple[Callable[..., None], ...]:
    """The checks of :data:`CHECKS` that apply to ``cls``, an operator (``Node``) or annotation class.

    Leaves and annotations skip ``check_termination_includes_children``; only a
    class whose ``refinements`` returns a strategy gets ``check_refinement_preserves_root_goal``.

    Raises:
        TypeError: ``cls`` is not a ``Node`` or ``Annotation`` subclass.
    """
    from specguard.contract.invariants import checks_for as applicable

    return applicable(cls)


def parametrize_with_checks(classes: Iterable[type]) -> pytest.MarkDecorator:
    """A ``pytest.mark.parametrize("operator, check", ...)`` with one item per class and applicable check.

    Each item's id is ``<class name>-<check name>`` (``AnyOf-check_markov``),
    so a failure names the class and the invariant; the test calls
    ``check(operator)``. The items of a check that starts a fresh interpreter
    (``check_description_is_exact``) carry the ``slow`` mark, so ``pytest -m
    "not slow"`` leaves them out.

    Args:
        classes: the operator and annotation classes under test.

    Returns:
        The decorator for a test function with the arguments ``operator, check``.

    Raises:
        TypeError: an element is not a ``Node`` or ``Annotation`` subclass.
    """
    import pytest

    from specguard.contract.invariants import FRESH_INTERPRETER

    params = [
        pytest.param(
            cls,
            check,
            id=f"{cls.__name__}-{check.__name__}",
            marks=[pytest.mark.slow] if check in FRESH_INTERPRETER else [],
        )
        for cls in classes
        for check in checks_for(cls)
    ]
    return pytest.mark.parametrize("operator, check", params)


def check_operator(cls: type, max_examples: int | None = None) -> None:
    """Run every check that applies to ``cls``.

    Args:
        cls: the operator or annotation class.
        max_examples: examples per check; ``None`` for each check's default (40,
            ``specguard.contract.trees.MAX_EXAMPLES``; ``check_markov`` 100, ``MARKOV_EXAMPLES``).

    Raises:
        AssertionError: one or more checks failed; the message holds each
            failure's invariant and counterexample.
        TypeError: ``cls`` is not a ``Node`` or ``Annotation`` subclass.
    """
    failures = []
    for check in checks_for(cls):
        try:
            check(cls) if max_examples is None else check(cls, max_examples=max_examples)
        except AssertionError as e:
            failures.append(str(e))
    if failures:
        raise AssertionError(
            f"{len(failures)} contract check(s) failed for {cls.__name__}:\n\n" + "\n\n".join(failures)
        )
