"""Budget: defaults, scaling and validation errors."""

from __future__ import annotations

import pytest

import specguard as sg


def test_defaults():
    b = sg.Budget(timesteps=1000)
    assert (b.min_seeds, b.max_seeds, b.eval_episodes, b.max_eval_episodes, b.wall_clock_s) == (2, 2, 30, 120, None)


def test_scaled_keeps_everything_but_timesteps():
    b = sg.Budget(timesteps=1000, min_seeds=2, max_seeds=5, wall_clock_s=60)
    assert b.scaled(0.25) == sg.Budget(timesteps=250, min_seeds=2, max_seeds=5, wall_clock_s=60)
    assert sg.Budget(timesteps=1).scaled(0.1).timesteps == 1


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"timesteps": 0}, r"Budget.timesteps: expected an integer >= 1, got 0"),
        ({"timesteps": -5}, r"Budget.timesteps: expected an integer >= 1, got -5"),
        ({"timesteps": 1.5}, r"Budget.timesteps: expected an integer >= 1, got 1.5"),
        ({"timesteps": 10, "min_seeds": 0}, r"Budget.min_seeds: expected an integer >= 1, got 0"),
        ({"timesteps": 10, "min_seeds": 3, "max_seeds": 2}, r"Budget.max_seeds: expected max_seeds >= min_seeds"),
        ({"timesteps": 10, "eval_episodes": 0}, r"Budget.eval_episodes: expected an integer >= 1, got 0"),
        ({"timesteps": 10, "eval_episodes": 10, "max_eval_episodes": 5}, r"Budget.max_eval_episodes"),
        ({"timesteps": 10, "wall_clock_s": -1}, r"Budget.wall_clock_s: expected a number of seconds > 0"),
    ],
)
def test_bad_budgets(kwargs, message):
    with pytest.raises(sg.InvalidSpec, match=message):
        sg.Budget(**kwargs)


def test_bad_scale():
    with pytest.raises(sg.InvalidSpec, match=r"budget scale: expected a number > 0, got 0"):
        sg.Budget(timesteps=10).scaled(0)
