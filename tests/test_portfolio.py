"""The guided search's portfolio: a uniform floor always, the rest to the samplers that pay off."""

from __future__ import annotations

import numpy as np
import pytest

from specguard.falsify import portfolio as pf
from specguard.falsify.portfolio import Portfolio


def run(portfolio: Portfolio, score, rounds: int, batch: int = 8) -> list[str]:
    """``rounds`` rounds of proposals scored by ``score`` (a function of a unit-box point); the arms used."""
    used: list[str] = []
    for _ in range(rounds):
        points, arms = portfolio.propose(batch)
        portfolio.observe(points, np.array([score(p) for p in points]), arms)
        used += arms
    return used


def toward_corner(p: np.ndarray) -> float:
    """Lower towards the corner (0.9, 0.9): the score points somewhere."""
    return float(np.linalg.norm(p - np.array([0.9, 0.9])))


def flat(p: np.ndarray) -> float:
    return 1.0


def test_before_anything_is_scored_every_start_is_uniform():
    portfolio = Portfolio(3, np.random.default_rng(0))
    points, arms = portfolio.propose(8)
    assert arms == ["uniform"] * 8 and points.shape == (8, 3)


@pytest.mark.parametrize("score", [toward_corner, flat])
def test_the_uniform_floor_holds_however_the_others_earn(score):
    portfolio = Portfolio(2, np.random.default_rng(1))
    run(portfolio, score, rounds=30)
    shares = portfolio.shares()
    assert shares["uniform"] >= pf.UNIFORM_FLOOR
    assert sum(shares.values()) == pytest.approx(1.0) and set(shares) == set(portfolio.arms)


def test_samplers_that_find_lower_scores_earn_more_of_the_next_rounds():
    portfolio = Portfolio(2, np.random.default_rng(2))
    run(portfolio, toward_corner, rounds=40)
    rates = {a: portfolio.paid[a] / max(1, portfolio.tried[a]) for a in portfolio.arms}
    assert rates["trend"] > rates["uniform"] and rates["local"] > rates["uniform"]
    shares = portfolio.shares()  # what is not the floor goes mostly to the guided samplers, not evenly
    assert shares["uniform"] < pf.UNIFORM_FLOOR + (1 - pf.UNIFORM_FLOOR) / len(portfolio.arms) - 0.05


def test_the_trend_sampler_follows_the_scores_across_the_space():
    portfolio = Portfolio(2, np.random.default_rng(3))
    run(portfolio, toward_corner, rounds=20)
    draws = np.stack([portfolio._draw("trend") for _ in range(200)])
    assert np.all(np.abs(draws) <= 1.0)
    assert np.linalg.norm(draws.mean(axis=0) - np.array([0.9, 0.9])) < 0.3


def test_the_local_sampler_retires_its_parents_and_then_draws_uniformly():
    portfolio = Portfolio(1, np.random.default_rng(4))
    portfolio.observe(np.array([[0.5]]), np.array([0.0]), ["uniform"])
    steps = [portfolio._draw("local") for _ in range(pf.RETIRE)]
    assert all(abs(s[0] - 0.5) < 6 * pf.STEP for s in steps)
    assert portfolio._uses[0] == pf.RETIRE  # used up: the next local draw has no parent left
    assert np.all(np.abs(np.stack([portfolio._draw("local") for _ in range(50)])) <= 1.0)
