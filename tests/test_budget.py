"""Budget: defaults, scaling and validation errors."""

from __future__ import annotations

import math

import numpy as np
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
        ({"timesteps": 0}, r"Budget: expected timesteps to be an integer >= 1, got 0"),
        ({"timesteps": -5}, r"Budget: expected timesteps to be an integer >= 1, got -5"),
        ({"timesteps": 1.5}, r"Budget: expected timesteps to be an integer >= 1, got 1.5"),
        ({"timesteps": 10, "min_seeds": 0}, r"Budget: expected min_seeds to be an integer >= 1, got 0"),
        ({"timesteps": 10, "min_seeds": 3, "max_seeds": 2}, r"Budget.max_seeds: expected max_seeds >= min_seeds"),
        ({"timesteps": 10, "eval_episodes": 0}, r"Budget: expected eval_episodes to be an integer >= 1, got 0"),
        ({"timesteps": 10, "eval_episodes": 10, "max_eval_episodes": 5}, r"Budget.max_eval_episodes"),
        ({"timesteps": 10, "wall_clock_s": -1}, r"Budget: expected wall_clock_s to be a finite number > 0 \(seconds"),
    ],
)
def test_bad_budgets(kwargs, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        sg.Budget(**kwargs)


def test_bad_scale():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Budget.scaled: expected factor to be a finite number > 0 \(the budget"
    ):
        sg.Budget(timesteps=10).scaled(0)


def test_budgets_reach_the_shared_rules():
    # counts are validation.check_count, seconds and scales validation.check_positive
    assert sg.Budget(timesteps=np.int64(10), min_seeds=np.int32(3)) == sg.Budget(timesteps=10, min_seeds=3)
    with pytest.raises(sg.error.InvalidSpec, match=r"expected checkpoints to be an integer >= 1, got True"):
        sg.Budget(timesteps=10, checkpoints=True)
    with pytest.raises(sg.error.InvalidSpec, match=r"expected wall_clock_s to be a finite number > 0 .*got inf"):
        sg.Budget(timesteps=10, wall_clock_s=math.inf)
    with pytest.raises(sg.error.InvalidSpec, match=r"expected factor to be a finite number > 0 .*got inf"):
        sg.Budget(timesteps=10).scaled(math.inf)
