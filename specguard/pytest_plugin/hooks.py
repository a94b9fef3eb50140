"""Hooks for other pytest plugins: a goal spec's result and its falsifications, as objects, as they come.

The plugin adds these hook specifications in ``pytest_addhooks`` (as pytest-xdist
adds its own), so a ``conftest.py`` or another plugin implements them by name,
instead of parsing the JSON rows the plugin leaves in a report's ``user_properties``.
Each is called in the process that ran the spec: under ``pytest -n`` (pytest-xdist)
the worker that trained it, where a conftest's hooks run too, not the controller.

An implementation may take any subset of a hook's arguments, by name::

    # conftest.py
    def pytest_goal_spec_result(item, spec, result):
        print(f"{item.nodeid}: {spec.label} {result.status()}")
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from specguard.engine.spec_result import SpecResult
    from specguard.falsify.search import Falsification
    from specguard.spec.spec import Spec
    from specguard.stats.verdicts import RunVerdict

__all__ = ["pytest_goal_spec_falsification", "pytest_goal_spec_result"]


@pytest.hookspec
def pytest_goal_spec_result(item: pytest.Item, spec: Spec, result: SpecResult) -> None:
    """A spec's result is ready: trained, or read back from the cache; once per spec in a session.

    Called when the first item that needs the spec (one of its goal items, its
    ``[falsify]`` item, or a test calling the ``goal_spec_result`` fixture) runs it;
    the spec's other items share that result and call nothing. Called before the
    item judges its goal, so it comes whatever the item's outcome.

    Args:
        item: the item that ran the spec.
        spec: the spec as trained: the session's options applied
            (``--goal-specs-budget-scale``, ``--goal-specs-checkpoints``, ``--goal-specs-undecided``).
        result: its :class:`~specguard.SpecResult`: per-goal verdicts, runs, models. Its words are the
            spec's own: a goal only ``@goal_spec(xfail=...)`` expects to miss is ``failed`` here and
            ``xfailed`` on its item (the decorator's xfail is pytest's).
    """


@pytest.hookspec
def pytest_goal_spec_falsification(
    item: pytest.Item, spec: Spec, seed: int, falsification: Falsification, verdict: RunVerdict
) -> None:
    """A ``[falsify]`` item searched one trained run's start space; once per run, in seed order.

    Called before the item passes or fails on the verdicts.

    Args:
        item: the ``[falsify]`` item.
        spec: the spec as trained (the session's options applied).
        seed: the run's seed.
        falsification: what the search found (:class:`~specguard.falsify.search.Falsification`:
            the counterexample, if any, and the failure rate over the start space).
        verdict: the run judged by the item's rule (:func:`~specguard.falsify.assertion.falsify_verdict`):
            ``met``, ``missed`` (falsified) or ``undecided``.
    """
