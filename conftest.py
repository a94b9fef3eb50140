"""The suite's two tiers, in one rule (for ``tests/``, ``plugins/tests/`` and the docstring examples alike).

``pytest -m "not slow"`` is the fast tier: unit and property tests that train nothing and start no process.
An item of the suite (under ``testpaths``; the main job's ``example_specs/`` is left alone) is ``slow`` when it
says so (``@pytest.mark.slow``; the contract kit's ``parametrize_with_checks`` marks the checks that start a
fresh interpreter), when it requests a fixture of :data:`SLOW_FIXTURES` (a pytest run inside the test), or when
it is a docstring example (they show whole uses, some of which train or start processes; all 136 took 4 s).
Every other item runs under a tripwire: should it train (stable-baselines3's ``learn``, specguard's
``train_run``) or start a process (``subprocess``, ``multiprocessing``, ``os.fork``), it fails, naming what it
did and the mark it needs. So the fast tier cannot grow slow in silence, and no test can leave the slow tier by
forgetting its mark: the whole suite (``pytest -n 2``, as CI runs it) trips on the same rule.
"""

from __future__ import annotations

import functools
import multiprocessing.process
import os
import subprocess
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import pytest
from _pytest.doctest import DoctestItem

SLOW_FIXTURES = frozenset({"pytester"})
"""Fixtures that make an item slow by themselves: a pytest session inside the test (most train a spec)."""

_current: list[pytest.Item] = []  # the fast item running now (the tripwire is armed while it is set)


def pytest_configure(config: pytest.Config) -> None:
    _arm_once()  # the ``slow`` marker itself is registered by specguard's pytest plugin


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    # The suite is what README's test command collects (testpaths); the rule leaves any other item alone: the main
    # job's goal specs (example_specs/) train, and are no test of specguard's own.
    suite = [config.rootpath / path for path in config.getini("testpaths")]
    for item in items:
        if not any(item.path.is_relative_to(folder) for folder in suite):
            continue
        if isinstance(item, DoctestItem) or SLOW_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
        item.stash[_FAST] = item.get_closest_marker("slow") is None


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item: pytest.Item) -> Iterator[None]:
    with _armed(item):
        return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    with _armed(item):
        return (yield)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item: pytest.Item) -> Iterator[None]:
    with _armed(item):
        return (yield)


@contextmanager
def _armed(item: pytest.Item) -> Iterator[None]:
    fast = item.stash.get(_FAST, False)
    item.stash[_TRIPPED] = None
    if fast:
        _current.append(item)
    try:
        yield
    finally:
        if fast:
            _current.pop()
        tripped, item.stash[_TRIPPED] = item.stash.get(_TRIPPED, None), None
    if fast and tripped:  # raised inside code that caught it: the item fails all the same
        pytest.fail(tripped, pytrace=False)


_TRIPPED = pytest.StashKey[str | None]()
_FAST = pytest.StashKey[bool]()  # an item of the suite's fast tier: the tripwire is armed while it runs


def _trip(what: str) -> None:
    if not _current:
        return
    item = _current[-1]
    message = (
        f"{item.nodeid} {what} but is not marked slow: the fast tier (-m 'not slow') trains nothing and starts no "
        "process; give the test @pytest.mark.slow (or its module pytestmark = pytest.mark.slow)"
    )
    item.stash[_TRIPPED] = message
    if threading.current_thread() is threading.main_thread():
        raise pytest.fail.Exception(message, pytrace=False)
    # another thread (a slot pool's) goes on, lest the test wait for it forever: the item fails when its phase ends


def _wrap(owner: Any, name: str, what: str | Callable[..., str]) -> None:
    original = getattr(owner, name)
    if getattr(original, "_tier_tripwire", False):
        return

    @functools.wraps(original)
    def tripwire(*args: Any, **kwargs: Any) -> Any:
        _trip(what(*args, **kwargs) if callable(what) else what)
        return original(*args, **kwargs)

    tripwire._tier_tripwire = True  # type: ignore[attr-defined]
    setattr(owner, name, tripwire)


def _arm_once() -> None:
    from stable_baselines3.common.base_class import BaseAlgorithm

    import specguard.training.train as training

    _wrap(training, "train_run", "trains a spec (specguard.training.train.train_run)")
    _wrap(BaseAlgorithm, "_setup_learn", lambda model, *a, **k: f"trains {type(model).__name__} (learn)")
    _wrap(subprocess.Popen, "_execute_child", lambda popen, args, *a, **k: f"starts a process ({_command(args)})")
    _wrap(multiprocessing.process.BaseProcess, "start", "starts a multiprocessing process")
    _wrap(os, "fork", "forks")


def _command(args: Any) -> str:
    words = [args] if isinstance(args, str | bytes | os.PathLike) else list(args)
    return " ".join(os.fsdecode(w) if isinstance(w, bytes | os.PathLike) else str(w) for w in words)[:120]
