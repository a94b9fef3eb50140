"""What a gate can see: the chance of a verdict at a true success, and the smallest drop a comparison flags."""

from __future__ import annotations

import numpy as np
import pytest

from specguard.stats.anytime import final_evaluation
from specguard.stats.power import (
    SeedLaw,
    chance_met,
    chance_passed,
    estimated_spread,
    gate_power,
    min_detectable_drop,
)
from specguard.stats.sequential import Design


@pytest.mark.parametrize("p", [0.75, 0.9, 0.97])
def test_chance_met_is_what_the_final_evaluation_does(p):
    """The exact sum against runs replayed through the evaluation itself."""
    rng = np.random.default_rng(0)
    stages, confidence = [30, 60, 120], 0.99583
    runs = 4000
    met = 0
    for _ in range(runs):
        outcomes = rng.random(120) < p

        def evaluate(start, count, outcomes=outcomes):
            return {"g": int(outcomes[start : start + count].sum())}

        counts, episodes = final_evaluation(evaluate, stages, {"g": 0.8}, confidence)
        from specguard.stats.intervals import run_verdict
        from specguard.stats.verdicts import RunVerdict

        met += run_verdict(counts["g"], episodes, 0.8, confidence) is RunVerdict.MET
    exact = chance_met(p, threshold=0.8, stages=stages, confidence=confidence)
    assert met / runs == pytest.approx(exact, abs=0.025)


def test_chance_met_at_the_extremes():
    assert chance_met(1.0, threshold=0.8, stages=[30], confidence=0.95) == 1.0
    assert chance_met(0.0, threshold=0.8, stages=[30], confidence=0.95) == 0.0


def test_a_quorum_passes_with_the_binomial_chance():
    assert chance_passed(0.9, required=2, runs=2) == pytest.approx(0.81)
    assert chance_passed(0.5, required=1, runs=3) == pytest.approx(0.875)


def test_spread_is_estimated_beyond_what_episodes_give():
    assert estimated_spread([(15, 30)]) is None
    assert estimated_spread([(15, 30), (16, 30)]) == 0.0
    rng = np.random.default_rng(2)
    law = SeedLaw(0.5, 0.2)
    estimates = [estimated_spread([(int(k), 100) for k in law.draw(rng, (40,), 100)]) for _ in range(50)]
    assert np.mean(estimates) == pytest.approx(0.2, abs=0.03)


def test_seed_laws_keep_their_mean_and_narrow_an_impossible_spread():
    rng = np.random.default_rng(3)
    rates = SeedLaw(0.9, 0.05).draw(rng, (20_000,), 1000) / 1000
    assert rates.mean() == pytest.approx(0.9, abs=0.005) and rates.std() == pytest.approx(0.05, abs=0.005)
    assert SeedLaw(0.98, 0.5).draw(rng, (10,), 30).max() <= 30  # narrowed to what a mean of 0.98 can carry
    assert (SeedLaw(1.0, 0.1).draw(rng, (5,), 30) == 30).all()


def test_more_seeds_see_smaller_drops():
    start = Design(alpha=0.05 / 15, baseline_seeds=8, first=2, ceiling=2)
    extra = Design(alpha=0.05 / 15, baseline_seeds=8, first=2, ceiling=8)
    assert min_detectable_drop(0.93, 0.05, start, episodes=30, sims=300) is None  # 2 against 8 cannot reach 0.0033
    seen = min_detectable_drop(0.93, 0.05, extra, episodes=30, sims=300)
    assert seen is not None and 0.1 < seen < 0.3
    assert gate_power(0.93, seen, 0.05, extra, episodes=30, sims=300) >= 0.8
    wide = min_detectable_drop(0.42, 0.15, extra, episodes=30, sims=300)
    assert wide is None or wide > seen
