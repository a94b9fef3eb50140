"""ReplayEnv, the simulator-free test double."""

from __future__ import annotations

import pytest
from gymnasium.utils.env_checker import check_env

from specguard.testing import ReplayEnv


def test_replays_the_trajectory_and_truncates_at_its_end():
    env = ReplayEnv([[0.0], [1.0], [2.0]])
    assert env.reset(seed=0)[0].tolist() == [0.0]
    assert env.step(0)[0].tolist() == [1.0]
    obs, reward, terminated, truncated, _ = env.step(1)
    assert (obs.tolist(), reward, terminated, truncated) == ([2.0], 0.0, False, True)


def test_passes_gymnasium_checker():
    check_env(ReplayEnv([[0.0, 1.0], [1.0, 2.0], [2.0, 3.0]]), skip_render_check=True)


def test_needs_two_observations():
    with pytest.raises(ValueError, match="at least two observations"):
        ReplayEnv([[0.0]])
