"""Intervals and verdicts, checked against known binomial cases."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.stats import beta

from specguard.stats.intervals import quorum_verdict, run_verdict, success_interval
from specguard.stats.verdicts import QuorumVerdict, RunVerdict

M, X, U = RunVerdict.MET, RunVerdict.MISSED, RunVerdict.UNDECIDED


@pytest.mark.parametrize(
    ("k", "n", "expected"),
    [
        # Clopper-Pearson 95% intervals from the literature (e.g. Brown, Cai & DasGupta 2001 tables).
        (0, 10, (0.0, 0.3085)),
        (10, 10, (0.6915, 1.0)),
        (5, 10, (0.1871, 0.8129)),
        (1, 20, (0.0013, 0.2487)),
        (28, 30, (0.7793, 0.9918)),
    ],
)
def test_known_clopper_pearson_intervals(k, n, expected):
    assert success_interval(k, n) == pytest.approx(expected, abs=1e-4)


@given(st.integers(1, 200).flatmap(lambda n: st.tuples(st.integers(0, n), st.just(n))), st.floats(0.5, 0.99))
def test_interval_is_the_beta_quantile_form(kn, confidence):
    k, n = kn
    lo, hi = success_interval(k, n, confidence)
    a = 1 - confidence
    assert lo == pytest.approx(0.0 if k == 0 else beta.ppf(a / 2, k, n - k + 1), abs=1e-9)
    assert hi == pytest.approx(1.0 if k == n else beta.ppf(1 - a / 2, k + 1, n - k), abs=1e-9)
    assert lo <= k / n <= hi


def test_run_verdicts():
    assert run_verdict(30, 30, threshold=0.8) is M  # [0.884, 1]
    assert run_verdict(0, 30, threshold=0.2) is X  # [0, 0.116]
    assert run_verdict(24, 30, threshold=0.8) is U  # [0.614, 0.923]
    assert run_verdict(0, 1, threshold=0.0) is M


def test_more_episodes_decide_an_undecided_run():
    assert run_verdict(9, 10, threshold=0.7) is U
    assert run_verdict(90, 100, threshold=0.7) is M


@pytest.mark.parametrize(
    ("runs", "required", "max_runs", "expected"),
    [
        ([M, M], 2, 2, QuorumVerdict.PASSED),
        ([M, X], 2, 2, QuorumVerdict.FAILED),
        ([M], 2, 2, QuorumVerdict.OPEN),
        ([M, U], 2, 2, QuorumVerdict.FAILED),  # an undecided final run does not count as met
        ([M] * 6, 6, 10, QuorumVerdict.PASSED),
        ([X] * 4 + [M] * 2, 6, 10, QuorumVerdict.OPEN),
        ([X] * 5, 6, 10, QuorumVerdict.FAILED),
        ([], 1, 3, QuorumVerdict.OPEN),
    ],
)
def test_quorum(runs, required, max_runs, expected):
    assert quorum_verdict(runs, required, max_runs) is expected


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: success_interval(3, 0), "at least one episode"),
        (lambda: success_interval(4, 3), "0 <= successes <= episodes"),
        (lambda: success_interval(1, 3, confidence=1.0), r"confidence to be a number in \(0, 1\), got 1.0"),
        (lambda: quorum_verdict([M], required=3, max_runs=2), "1 <= required <= max_runs"),
        (lambda: quorum_verdict([M, M, M], required=1, max_runs=2), "more than max_runs"),
    ],
)
def test_bad_arguments(call, message):
    with pytest.raises(ValueError, match=message):
        call()
