"""Importance-sampled failure rates: unbiasedness, coverage and width, checked by simulating a known failure rate.

The start space is the unit square, a start fails when it lies in a small box (0.5% or 2% of the square), and a
falsifier runs K = 300 episodes from a pool of N = 20 K uniform starts, drawn from the defensive mixture (alpha = 1/2)
of a predictor's scores. Each replication draws a fresh pool, so the checks are about the rate of a uniform start,
not only about one pool's share. 2,000 replications per case: a coverage of 95% is then measured to +-0.5% (one
standard error), a side's share of misses of 2.5% to +-0.35%.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from specguard.stats import importance
from specguard.stats.importance import MIN_FAILURES, RateEstimate, importance_rate, proposal, weights_of

EPISODES = 300
POOL = 20 * EPISODES
ALPHA = 0.5
REPLICATIONS = 2_000
CENTER = np.array([0.7, 0.3])


def bump(u, v, center, scale):
    return np.exp(-((u - center[0]) ** 2 + (v - center[1]) ** 2) / (2.0 * scale**2))


# Scores of pool starts (coordinates u, v) for a failure box of side `side` around CENTER.
PREDICTORS = {
    "good": lambda u, v, side: bump(u, v, CENTER, side),  # a bump on the box
    "poor": lambda u, v, side: bump(u, v, (0.2, 0.8), 0.15),  # a bump far from it: every failure weighs 1 / alpha
    "constant": lambda u, v, side: np.full(u.shape, 0.3),  # the uniform proposal: plain Monte Carlo
    "grazing": lambda u, v, side: bump(u, v, CENTER + side, side / 2),  # next to the box: light failures seen first
}


def simulate(rate, predictor, seed, replications=REPLICATIONS, alpha=ALPHA, chunk=250):
    """``replications`` estimates, each from a fresh pool and its own draws."""
    rng = np.random.default_rng(seed)
    half = math.sqrt(rate) / 2
    estimates = []
    for _ in range(replications // chunk):
        u, v = rng.random((chunk, POOL)), rng.random((chunk, POOL))
        fails = (np.abs(u - CENTER[0]) <= half) & (np.abs(v - CENTER[1]) <= half)
        scores = PREDICTORS[predictor](u, v, 2 * half)
        for i in range(chunk):
            q = proposal(scores[i], alpha=alpha)
            drawn = rng.choice(POOL, size=EPISODES, p=q)
            weights = weights_of(q, drawn)
            estimate = importance_rate(fails[i, drawn], weights, POOL, alpha=alpha, min_weight=1 / (POOL * q.max()))
            estimates.append(estimate)
    return estimates


def uniform_width(rate, episodes=EPISODES, confidence=0.95):
    """The median width of the Clopper-Pearson interval from ``episodes`` uniform episodes (exact, over the
    binomial count)."""
    from scipy.special import betaincinv

    tail, total = (1 - confidence) / 2, 0.0
    for k in range(episodes + 1):
        total += math.comb(episodes, k) * rate**k * (1 - rate) ** (episodes - k)
        if total >= 0.5:
            low = betaincinv(k, episodes - k + 1, tail) if k else 0.0
            return betaincinv(k + 1, episodes - k, 1 - tail) - low
    raise AssertionError("unreachable")


# Cases: (rate, predictor, seed). Each is there for what it can catch (mutations, measured, in the test's comments).
CASES = [
    (0.005, "good", 1),
    (0.02, "good", 2),
    (0.02, "poor", 3),
    (0.005, "constant", 4),
    (0.02, "constant", 5),
    (0.005, "grazing", 6),
]


@pytest.fixture(scope="module")
def simulated():
    return {(rate, predictor): simulate(rate, predictor, seed) for rate, predictor, seed in CASES}


@pytest.mark.parametrize(("rate", "predictor"), [case[:2] for case in CASES])
def test_the_estimate_is_unbiased_for_the_rate_of_a_uniform_start(simulated, rate, predictor):
    # Red with the weights capped at 1 (no draw counting for more than a uniform one): (poor, 2%) comes out at half
    # the rate, 77 standard errors low.
    estimates = np.array([e.rate for e in simulated[rate, predictor]])
    standard_error = estimates.std(ddof=1) / math.sqrt(len(estimates))
    assert abs(estimates.mean() - rate) <= 4 * standard_error


@pytest.mark.parametrize(("rate", "predictor"), [case[:2] for case in CASES])
def test_the_interval_covers_the_rate_with_at_most_its_share_of_misses_on_each_side(simulated, rate, predictor):
    # 0.93: 4 standard errors below 0.95; 0.04: 4 above a side's 2.5%. Measured red (share of intervals wholly below
    # the rate): the plain normal interval p_hat +- z sqrt(v), (good, 0.5%) 4.8%; a one-sided bounded interval at 95%,
    # (poor, 2%) 5.0%; MIN_FAILURES = 3, (grazing, 0.5%) 5.5% (MIN_FAILURES = 2: coverage 0.899); no pool term
    # p (1 - p) / N in the variance, (good, 0.5%) coverage 0.873.
    estimates = simulated[rate, predictor]
    below = np.mean([e.high < rate for e in estimates])
    above = np.mean([e.low > rate for e in estimates])
    assert 1 - below - above >= 0.93
    assert below <= 0.04
    assert above <= 0.04


@pytest.mark.parametrize(("rate", "at_most"), [(0.005, 0.5), (0.02, 0.6)])
def test_a_good_predictor_narrows_the_interval(simulated, rate, at_most):
    # Red with alpha = 1 (the predictor unused: a ratio near 1). At 2% the pool's own spread (its 6,000 starts hold
    # about 120 failing ones) caps what the predictor can gain, hence the looser bound.
    widths = [e.high - e.low for e in simulated[rate, "good"]]
    assert np.median(widths) <= at_most * uniform_width(rate)


def test_no_failure_bounds_the_rate_by_the_exact_bound_over_alpha():
    # Red with a one-sided bound (0.05 instead of 0.025) or without the factor 1 / alpha.
    for alpha, episodes in [(0.5, 300), (0.25, 600), (1.0, 30)]:
        weights = np.full(episodes, 1 / alpha)  # the light starts were drawn: any weight up to 1 / alpha
        estimate = importance_rate([False] * episodes, weights, pool=20 * episodes, alpha=alpha, min_weight=0.1)
        assert estimate.rate == 0.0
        assert estimate.low == 0.0
        assert estimate.high == pytest.approx((1 - 0.025 ** (1 / episodes)) / alpha, rel=1e-12)
        assert (estimate.failures, estimate.episodes, estimate.confidence) == (0, episodes, 0.95)


def test_few_failures_give_the_exact_interval_scaled_by_the_extreme_weights():
    # Red if MIN_FAILURES's bounded interval is skipped, or its lower end drops min_weight.
    from scipy.special import betaincinv

    failures, episodes = MIN_FAILURES - 1, 200
    failed = [True] * failures + [False] * (episodes - failures)
    estimate = importance_rate(failed, np.full(episodes, 1.5), pool=4_000, alpha=0.5, min_weight=0.2)
    assert estimate.rate == pytest.approx(1.5 * failures / episodes)
    assert estimate.low == pytest.approx(0.2 * betaincinv(failures, episodes - failures + 1, 0.025))
    assert estimate.high == pytest.approx(2 * betaincinv(failures + 1, episodes - failures, 0.975))
    assert importance_rate(failed, np.full(episodes, 1.5), pool=4_000, alpha=0.5).low == 0.0


def test_the_proposal_mixes_uniform_and_scores_and_bounds_the_weights():
    # Red if the uniform share is left out (q would be 0 at the zero scores) or the mixture is not normalised.
    q = proposal([0.0, 0.5, 1.0, 0.5], alpha=0.2)
    assert q.sum() == pytest.approx(1.0)
    assert q == pytest.approx([0.05, 0.05 + 0.8 * 0.25, 0.05 + 0.8 * 0.5, 0.05 + 0.8 * 0.25])
    assert weights_of(q, [0, 0, 2]) == pytest.approx([1 / 0.2, 1 / 0.2, 0.25 / 0.45])
    assert proposal([0.0, 0.0], alpha=0.3) == pytest.approx([0.5, 0.5])  # no score: uniform
    assert proposal([0.7, 0.1, 0.0]) == pytest.approx(proposal([0.7, 0.1, 0.0], alpha=0.5))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: proposal([0.5], alpha=1.5), r"expected alpha in \(0, 1\], got 1\.5"),
        (lambda: proposal([0.5], alpha=0), r"expected alpha in \(0, 1\], got 0"),
        (lambda: proposal([0.5], alpha=True), r"expected alpha in \(0, 1\], got True"),
        (lambda: proposal([0.2, 1.3]), r"expected scores in \[0, 1\], got 1\.3 at index 1"),
        (lambda: proposal([-0.1]), r"expected scores in \[0, 1\], got -0\.1 at index 0"),
        (lambda: proposal([0.2, float("nan")]), r"expected finite scores, got nan at index 1"),
        (lambda: proposal([]), r"expected scores to be a non-empty 1-D array, got shape \(0,\)"),
        (lambda: proposal([[0.1, 0.2]]), r"expected scores to be a non-empty 1-D array, got shape \(1, 2\)"),
        (lambda: weights_of([0.5, 0.5], [2]), r"expected drawn indices in \[0, 2\), got 2\.\.2"),
        (lambda: weights_of([1.0, 0.0], [0]), r"expected q > 0 everywhere, got 0\.0"),
        (
            lambda: importance_rate([True, False], [1.0, 1.0, 1.0], pool=10),
            r"expected one weight per outcome, got 3 weights and 2 outcomes",
        ),
        (lambda: importance_rate([2, 0], [1.0, 1.0], pool=10), r"expected failed to be booleans, got 2\.0"),
        (
            lambda: importance_rate([True], [3.0], pool=10, alpha=0.5),
            r"expected weights <= 1 / alpha = 2, got 3\.0",
        ),
        (
            lambda: importance_rate([True], [0.01], pool=10),
            r"expected weights >= 1 / pool = 0\.1 \(q <= 1\), got 0\.01",
        ),
        (lambda: importance_rate([True], [1.0], pool=0), r"expected pool to be a whole number of starts >= 1, got 0"),
        (
            lambda: importance_rate([True], [1.0], pool=10, min_weight=1.5),
            r"expected min_weight in \[0, smallest weight 1\.0\], got 1\.5",
        ),
        (lambda: importance_rate([True], [1.0], pool=10, confidence=1.0), r"expected confidence .* got 1\.0"),
    ],
)
def test_invalid_arguments_are_named_with_their_values(call, message):
    # Red if a check is dropped (no error, or numpy's own) or its message stops naming the argument and the value.
    with pytest.raises(ValueError, match=message):
        call()


def test_summary_is_one_line_with_the_rate_its_interval_and_its_source():
    # Red if the percentages or the counts go missing, or "1 failures" comes back.
    assert RateEstimate(0.0052, 0.0031, 0.0074, 37, 600, 0.95).summary() == (
        "0.52% [0.31%, 0.74%] (importance sampling: 37 failures in 600 episodes from the learned proposal)"
    )
    assert RateEstimate(0.00004, 0.0, 0.00021, 1, 300, 0.95).summary().startswith("0.004% [0%, 0.021%] (")
    assert "1 failure in 300" in RateEstimate(0.00004, 0.0, 0.00021, 1, 300, 0.95).summary()
    assert "MIN_FAILURES" in importance.__all__
