"""The suite's tiers (the repository's conftest.py): an unmarked test that trains or starts a process fails, naming
what it did; a marked one runs; ``-m "not slow"`` leaves the marked, the pytester and the docstring items out; an
item outside the suite's testpaths (the main job's) is left alone."""

from __future__ import annotations

import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

TESTS = '''
import subprocess
import sys
import threading

import gymnasium as gym
import pytest
from stable_baselines3 import PPO


def test_pure():
    assert 1 + 1 == 2


def test_starts_a_process():
    subprocess.run([sys.executable, "-c", "pass"], check=True)


def test_trains():
    PPO("MlpPolicy", gym.make("CartPole-v1"), n_steps=64, batch_size=32, n_epochs=1).learn(64)


def test_swallows_the_trip():
    try:
        subprocess.run([sys.executable, "-c", "pass"], check=True)
    except BaseException:
        pass


def test_starts_a_process_from_a_thread():
    thread = threading.Thread(target=subprocess.run, args=([sys.executable, "-c", "pass"],))
    thread.start()
    thread.join()


@pytest.mark.slow
def test_marked():
    subprocess.run([sys.executable, "-c", "pass"], check=True)


def test_with_pytester(pytester):
    pass


def double(x):
    """
    >>> double(2)
    4
    """
    return 2 * x
'''


OUTSIDE = """
import subprocess
import sys


def test_outside_the_suite():
    subprocess.run([sys.executable, "-c", "pass"], check=True)
"""


def _project(pytester):
    """The repository's conftest.py over a suite (testpaths: ``tests``) and a folder outside it."""
    shutil.copy(ROOT / "conftest.py", pytester.path / "conftest.py")
    pytester.makeini("[pytest]\ntestpaths = tests\n")
    (pytester.path / "tests").mkdir()
    (pytester.path / "tests" / "test_tiers_example.py").write_text(TESTS)
    (pytester.path / "outside").mkdir()
    (pytester.path / "outside" / "test_outside.py").write_text(OUTSIDE)


def test_an_unmarked_test_that_trains_or_starts_a_process_fails_naming_what_it_did(pytester):
    _project(pytester)
    result = pytester.runpytest_subprocess("-p", "pytester", "--doctest-modules", "-p", "no:cacheprovider")
    result.assert_outcomes(passed=4, failed=4)
    outside = pytester.runpytest_subprocess("-p", "no:cacheprovider", "outside")
    outside.assert_outcomes(passed=1)  # the rule is the suite's: a user's or the main job's items are left alone
    out = result.stdout.str()
    for name, what in [
        ("test_starts_a_process", "starts a process ("),
        ("test_trains", "trains PPO (learn)"),
        ("test_swallows_the_trip", "starts a process ("),
        ("test_starts_a_process_from_a_thread", "starts a process ("),
    ]:
        assert f"tests/test_tiers_example.py::{name} {what}" in out, name
    assert "but is not marked slow" in out


def test_the_fast_tier_leaves_out_marked_pytester_and_docstring_items(pytester):
    _project(pytester)
    result = pytester.runpytest_subprocess(
        "-p", "pytester", "--doctest-modules", "-p", "no:cacheprovider", "-m", "not slow", "-k", "pure or double"
    )
    result.assert_outcomes(passed=1, deselected=7)
    slow = pytester.runpytest_subprocess("-p", "pytester", "--doctest-modules", "-p", "no:cacheprovider", "-m", "slow")
    slow.assert_outcomes(passed=3, deselected=5)
