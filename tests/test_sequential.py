"""The gate's sequential comparison: boundaries, repeated p-values, the permutation test, the stopping rule."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from specguard.stats.power import SeedLaw, simulate_gate
from specguard.stats.sequential import (
    Design,
    GateState,
    boundaries,
    compare_seeds,
    describe_change,
    drop_bounds,
    look_levels,
    permutation_p_values,
    repeated_p_value,
    spent,
    states,
)

DESIGN = Design(alpha=0.05 / 15, baseline_seeds=8, first=2, ceiling=8)


def test_a_design_looks_every_step_up_to_its_ceiling():
    assert DESIGN.looks == (2, 4, 6, 8)
    assert Design(alpha=0.05, baseline_seeds=8, first=3, ceiling=8).looks == (3, 5, 7, 8)
    assert Design(alpha=0.05, baseline_seeds=8, first=4, ceiling=2).looks == (4,)  # the ceiling is at least the start
    assert DESIGN.next_seeds(2) == 4 and DESIGN.next_seeds(7) == 8 and DESIGN.next_seeds(8) == 8
    fractions = DESIGN.fractions(DESIGN.looks)
    assert fractions[-1] == 1.0 and all(a < b for a, b in itertools.pairwise(fractions))
    assert math.isclose(fractions[0], (1 / 8 + 1 / 8) / (1 / 8 + 1 / 2))
    with pytest.raises(ValueError, match=r"Design: expected alpha to be a number in \(0, 1\) .*got 0.0"):
        Design(alpha=0.0, baseline_seeds=8, first=2, ceiling=8)


def test_the_level_is_spent_as_the_power_family_says():
    assert spent(1.0, 0.05) == 0.05 and spent(0.5, 0.05) == pytest.approx(0.05 / 8) and spent(0.0, 0.05) == 0.0


@pytest.mark.parametrize("alpha", [0.05 / 15, 0.025, 0.2])
def test_boundaries_are_crossed_as_often_as_the_level_allows(alpha):
    """Monte Carlo of a process with independent increments: the chance of crossing any boundary is alpha."""
    fractions = DESIGN.fractions(DESIGN.looks)
    c = np.array(boundaries(fractions, alpha))
    rng = np.random.default_rng(1)
    sims = 400_000
    score = (rng.standard_normal((sims, len(fractions))) * np.sqrt(np.diff((0.0, *fractions)))).cumsum(axis=1)
    crossed = (score / np.sqrt(fractions) >= c).any(axis=1).mean()
    assert crossed == pytest.approx(alpha, rel=0.1 if alpha < 0.01 else 0.03)
    assert all(a > b for a, b in itertools.pairwise(c))  # little spent early: high boundaries first


def test_one_look_is_the_fixed_sample_test():
    assert boundaries((1.0,), 0.025)[0] == pytest.approx(1.959964, abs=1e-5)


def test_repeated_p_values_invert_the_boundaries():
    fractions = DESIGN.fractions(DESIGN.looks)
    for level in (1e-4, 0.0033, 0.02):
        c = boundaries(fractions, level)
        assert repeated_p_value([0.0, 0.0, 0.0, c[-1]], fractions) == pytest.approx(level, rel=0.02)
        assert repeated_p_value([c[0] + 1e-9, 0.0], fractions[:2]) == pytest.approx(level, rel=0.02)
    assert repeated_p_value([-3.0], fractions[:1]) == 1.0
    assert float(look_levels(np.array(40.0), fractions, 3)) == pytest.approx(1e-7)  # resolved down to MIN_LEVEL


def test_permutation_p_values_count_the_splits_by_hand():
    low, high = permutation_p_values(np.array([1.0, 2.0, 3.0]), np.array([0.0]))
    assert (low, high) == (0.25, 1.0)  # of the 4 splits, 1 puts a value as low as 0 on the pull-request side
    low, high = permutation_p_values(np.array([1.0, 1.0]), np.array([1.0, 1.0]))
    assert (low, high) == (1.0, 1.0)  # identical sides: no evidence either way
    low, _ = permutation_p_values(np.zeros((3, 8)) + np.arange(8), np.full((3, 2), -1.0))
    assert np.allclose(low, 1 / math.comb(10, 2))  # the smallest p-value 2 seeds against 8 can give


def test_permutation_p_values_are_exact_for_skewed_seeds():
    """Seeds that either learn or do not: the t-test's weak spot; the permutation test keeps its level."""
    rng = np.random.default_rng(3)
    values = np.where(rng.random((20_000, 10)) < 0.1, 0.1, 1.0) + 0.01 * rng.random((20_000, 10))
    low, _ = permutation_p_values(values[:, :8], values[:, 8:])
    for level in (1 / 45, 3 / 45, 0.2):
        assert (low <= level + 1e-12).mean() <= level * 1.05


def test_many_seeds_use_fixed_random_splits():
    rng = np.random.default_rng(0)
    before, after = rng.random(16), rng.random(12)
    first = permutation_p_values(before, after)
    assert first == permutation_p_values(before, after)  # the same data, the same p-value
    assert 0.0 < first[0] < 1.0 and first[0] * 20_000 == pytest.approx(round(first[0] * 20_000))


def test_a_clear_drop_is_flagged_once_enough_seeds_are_in():
    before = [(29, 30), (30, 30), (28, 30), (30, 30), (29, 30), (30, 30), (29, 30), (28, 30)]
    after = [(12, 30), (14, 30), (10, 30), (13, 30), (11, 30), (12, 30)]
    two = compare_seeds(before, after[:2], DESIGN, [2])
    assert two.state is GateState.OPEN  # 1 in 45 is the least 2 seeds against 8 can give
    assert compare_seeds(before, after[:4], DESIGN, [2, 4]).state is GateState.OPEN
    six = compare_seeds(before, after, DESIGN, [2, 4, 6])
    assert six.state is GateState.DROPPED and six.dropped and six.p_drop <= DESIGN.alpha
    assert six.describe().startswith("dropped: 97% -> 40% (p = ")
    assert six.describe().endswith("6 seeds vs 8 in the baseline, looks at 2, 4, 6)")


def test_unchanged_seeds_are_fine_at_once():
    before = [(28, 30), (29, 30), (30, 30), (27, 30)] * 2
    look = compare_seeds(before, [(29, 30), (28, 30)], DESIGN, [2])
    assert look.state is GateState.FINE and look.upper < DESIGN.margin
    assert look.describe().startswith("unchanged within chance: 95% -> 95% (a drop of ")


def test_a_rise_is_reported_by_the_same_design_turned_round():
    before = [(12, 30), (14, 30), (10, 30), (13, 30), (11, 30), (12, 30), (13, 30), (12, 30)]
    look = compare_seeds(before, [(29, 30), (30, 30), (28, 30), (30, 30), (29, 30), (30, 30)], DESIGN, [2, 4, 6])
    assert look.improved and not look.dropped and look.describe().startswith("improved: 40% -> 98% (p = 0.00074")


def test_bad_looks_are_refused():
    with pytest.raises(ValueError, match="ending at the 2 runs"):
        compare_seeds([(1, 2)], [(1, 2), (1, 2)], DESIGN, [1])
    with pytest.raises(ValueError, match="both sides need at least one run"):
        compare_seeds([], [(1, 2)], DESIGN, [1])


def test_the_stopping_rule():
    got = states(np.array([0.001, 0.5, 0.5]), np.array([0.5, 0.1, 0.3]), DESIGN)
    assert list(got) == ["dropped", "fine", "open"]


def test_the_drop_bound_never_trusts_less_spread_than_episodes_give():
    """Every seed alike (all 30 of 30 but one): the bound still counts 30 episodes' binomial spread."""
    kb, nb = np.full(8, 30), np.full(8, 30)
    _, _, upper = drop_bounds(kb, nb, np.array([29, 29]), np.array([30, 30]))
    assert upper > 0.05


def test_false_alarms_stay_at_the_level_when_nothing_changes():
    """The whole rule, seeds simulated: repeated p-values at or below the level no more often than the level."""
    rng = np.random.default_rng(7)
    for law in (SeedLaw(0.93, 0.05), SeedLaw(0.42, 0.15), SeedLaw(0.8, 0.25)):
        result = simulate_gate(law, law, replace_alpha(0.02), sims=3000, episodes=30, rng=rng)
        assert (result.p_drop <= 0.02).mean() <= 0.02 * 1.3, law


def test_a_20_point_drop_of_a_goal_near_93_percent_is_usually_flagged():
    rng = np.random.default_rng(8)
    result = simulate_gate(SeedLaw(0.93, 0.05), SeedLaw(0.73, 0.05), DESIGN, sims=1000, episodes=30, rng=rng)
    assert result.flagged.mean() > 0.7 and set(np.unique(result.seeds)) <= set(DESIGN.looks)
    same = simulate_gate(SeedLaw(0.93, 0.05), SeedLaw(0.93, 0.05), DESIGN, sims=1000, episodes=30, rng=rng)
    assert same.seeds.mean() < 3 and not same.flagged.any()


def replace_alpha(alpha: float) -> Design:
    return Design(alpha=alpha, baseline_seeds=8, first=2, ceiling=8)


@pytest.mark.parametrize(
    ("before", "after"),
    [
        ([(30, 30), (30, 30)], [(0, 30), (30, 30)]),  # 2 seeds a side, one never learns: 266 points before the fix
        ([(30, 30)], [(30, 30), (0, 30)]),  # 1 against 2: 1151 points
        ([(0, 30)], [(30, 30), (0, 30)]),  # a rise, as spread out
    ],
)
def test_a_drop_in_success_is_never_bounded_beyond_100_points(before, after):
    """A success rate moves 100 points at most: the drop's bound is clipped to the difference of two rates."""
    look = compare_seeds(before, after, DESIGN, [len(after)])
    assert -1.0 <= look.upper <= 1.0
    points = float(look.describe().split("a drop of ")[1].split(" points")[0])
    assert 0 <= points <= 100


@pytest.mark.parametrize("upper", [0.12, 0.19, 0.1901, 0.197, 0.1999])
def test_a_fine_comparison_never_reads_as_a_bound_at_the_margin(upper):
    """'unchanged within chance' says the drop's bound lies under the margin: its rounded-up figure must too."""
    line = describe_change(
        GateState.FINE, 0.9, 0.85, p_drop=0.9, p_rise=0.8, alpha=0.025, upper=upper, margin=0.2, sample="s", most="m"
    )
    points = float(line.split("a drop of ")[1].split(" points")[0])
    assert upper * 100 <= points < 20, line


def test_the_drop_bound_lies_in_minus_one_to_one_for_every_outcome_of_few_seeds():
    rng = np.random.default_rng(0)
    kb, ka = rng.integers(0, 31, size=(2000, 2)), rng.integers(0, 31, size=(2000, 3))
    _, _, upper = drop_bounds(kb, np.full_like(kb, 30), ka, np.full_like(ka, 30))
    assert upper.min() >= -1.0 and upper.max() <= 1.0 and upper.max() == 1.0  # wide spread reaches the clip
