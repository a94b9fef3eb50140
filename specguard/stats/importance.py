"""A failure rate estimated from starts drawn where a learned predictor expects failures: importance sampling.

The failure rate ``p`` of a start space is the chance that a uniform start fails. Drawing starts uniformly finds few
failures when ``p`` is small, so a falsifier draws them from a *proposal* instead, and weighs each outcome back:

1. A **pool** of ``N`` uniform starts (``N`` large, say 20 times the episodes: the pool's own spread is a floor
   under the interval's width, however good the predictor, and starts are cheap to draw and score).
2. A learned predictor scores each pool member, ``pi_i`` in [0, 1] (its predicted chance of failure). The proposal
   over the pool is the *defensive mixture* (:func:`proposal`)::

       q_i = alpha / N + (1 - alpha) * pi_i / sum(pi)        (q_i = 1 / N when every score is 0)

3. ``K`` indices are drawn from ``q`` with replacement, and an episode is run from each: ``f_k`` is 1 when it failed.
   Each draw's **weight** is ``w_k = (1 / N) / q_{j_k}`` (:func:`weights_of`).
4. The estimate (:func:`importance_rate`) is ``p_hat = mean(f_k * w_k)``. Given the pool it is unbiased for the pool's
   failure share, ``E_q[f w] = sum_i q_i f_i / (N q_i)``; the pool is uniform, so it is unbiased for ``p``, whatever the
   predictor. A poor predictor costs variance, never bias, and the uniform share ``alpha`` bounds every weight:
   ``w <= 1 / alpha``.

The interval, at ``confidence``, two-sided with at most ``(1 - confidence) / 2`` on each side:

* From at least :data:`MIN_FAILURES` failures, the estimate's variance is
  ``v = s^2 / K + p_hat (1 - p_hat) / N``: ``s^2`` is the sample variance of ``y_k = f_k w_k`` (the draws' spread
  given the pool), the second term the pool's own spread around ``p``. The interval is Clopper-Pearson's at the
  *effective* counts, ``n = p_hat (1 - p_hat) / v`` episodes with ``n p_hat`` failures (Korn and Graubard, 1998, the
  usual interval of a small weighted proportion). The plain normal interval ``p_hat +- z sqrt(v)`` is too short on
  the low side: ``p_hat`` is skewed to the right (the pool's count of failures, times the draws' share of them), and
  in tests/test_importance.py's simulations 4.8% of its intervals lay wholly below ``p`` (2.5% allowed; 1.5% here).
* From fewer failures the sample variance says little (the failures seen so far may all be light ones), so the
  interval is *bounded* instead. ``p`` is the proposal's failure chance times the failing starts' mean weight, so
  ``(min w) P_q(fail) <= p <= (1 / alpha) P_q(fail)``, and ``P_q(fail)`` has an exact interval from ``failures`` of
  ``K``: the upper end is ``1 / alpha`` times its upper end (``1 - ((1 - confidence) / 2) ** (1 / K)`` without a
  failure), the lower end ``min_weight`` times its lower end, 0 unless the caller gives ``min_weight``, the pool's
  smallest weight ``1 / (N max q)``. Both ends are two-sided (each at ``(1 + confidence) / 2``), like the other
  interval's: a one-sided bound at ``confidence`` here would spend the whole ``1 - confidence`` on the low side
  whenever failures are few, on top of the other interval's share when they are not. These bound the pool's
  failure share; the pool's own spread around ``p`` is left to their slack (the failing starts' weights are rarely
  all at the extreme), which the simulations check.

:data:`MIN_FAILURES` is 5, from the simulations' predictor that scores the failure box's neighbourhood and grazes
only its corner (light failures seen first, heavy ones rare): with the effective-count interval admitted from 2
failures on, 8.8% of the intervals lay wholly below ``p``; from 3, 5.5%; from 4, 3.0%; from 5, 1.5%.

Coverage needs draws of every kind of failure: a predictor that picks out only part of the failure region leaves
the rest to the uniform share, weight ``1 / alpha`` and chance ``alpha`` times its rate per draw. When ``K`` draws
are expected to meet such heavy failures only about once, the estimate is still unbiased but usually too low, and no
interval from the draws alone can tell (a predictor on one corner of a 0.5% box, ``K`` = 300: 74% coverage).

Example:
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> starts = rng.random(20_000)                          # the pool: N uniform starts in [0, 1]
    >>> fails = starts > 0.99                                # the unknown truth: p = 1%
    >>> q = proposal(starts**50, alpha=0.5)                  # a predictor that suspects the high end
    >>> drawn = rng.choice(len(q), size=1_000, p=q)
    >>> estimate = importance_rate(fails[drawn], weights_of(q, drawn), pool=len(q), alpha=0.5)
    >>> estimate.failures > 100, estimate.low < 0.01 < estimate.high
    (True, True)
    >>> importance_rate([False] * 600, [2.0] * 600, pool=12_000).summary()
    '0% [0%, 1.23%] (importance sampling: 0 failures in 600 episodes from the learned proposal)'
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Real

import numpy as np
import numpy.typing as npt

from specguard.validation import check_open_fraction

__all__ = [
    "MIN_FAILURES",
    "RateEstimate",
    "importance_rate",
    "proposal",
    "weights_of",
]

MIN_FAILURES = 5
"""The fewest failures whose spread the interval is trusted to; below, the bounded interval (see the module's text)."""

_SLACK = 1e-9  # relative: what rounding may add to a weight computed as (1 / N) / q


def _check_alpha(alpha: float) -> float:
    if isinstance(alpha, bool) or not isinstance(alpha, Real) or not 0.0 < float(alpha) <= 1.0:
        raise ValueError(f"expected alpha in (0, 1], got {alpha!r}")
    return float(alpha)


def _vector(name: str, values: npt.ArrayLike) -> npt.NDArray[np.float64]:
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"expected {name} to be numbers, got {values!r}") from error
    if array.ndim != 1 or array.size == 0:
        raise ValueError(f"expected {name} to be a non-empty 1-D array, got shape {array.shape}")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise ValueError(f"expected finite {name}, got {array[bad[0]]} at index {bad[0]}")
    return array


def proposal(scores: npt.ArrayLike, alpha: float = 0.5) -> npt.NDArray[np.float64]:
    """The defensive mixture over a pool of uniform starts: ``q_i = alpha / N + (1 - alpha) * pi_i / sum(pi)``.

    Args:
        scores: the predictor's score ``pi_i`` in [0, 1] of each of the ``N`` pool members (its predicted chance of
            failure).
        alpha: the uniform share of the mixture, in (0, 1]; every weight ``(1 / N) / q_i`` is at most ``1 / alpha``.
            1 is plain uniform sampling.

    Returns:
        ``q``, ``N`` probabilities summing to 1; uniform when every score is 0.

    Raises:
        ValueError: ``scores`` empty, not 1-D, not finite or outside [0, 1]; ``alpha`` outside (0, 1].

    Example:
        >>> proposal([0.0, 0.0, 1.0, 1.0], alpha=0.5)
        array([0.125, 0.125, 0.375, 0.375])
    """
    alpha = _check_alpha(alpha)
    pi = _vector("scores", scores)
    bad = np.flatnonzero((pi < 0.0) | (pi > 1.0))
    if bad.size:
        raise ValueError(f"expected scores in [0, 1], got {pi[bad[0]]} at index {bad[0]}")
    n = pi.size
    total = float(pi.sum())
    if total == 0.0:
        return np.full(n, 1.0 / n)
    q: npt.NDArray[np.float64] = alpha / n + (1.0 - alpha) * (pi / total)
    return q


def weights_of(q: npt.ArrayLike, drawn: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The importance weights ``(1 / N) / q_j`` of the pool members drawn, ``N = len(q)``.

    Args:
        q: the proposal over the pool (:func:`proposal`).
        drawn: the indices drawn from ``q``, one per episode (repeats allowed).

    Returns:
        One weight per index in ``drawn``.

    Raises:
        ValueError: ``q`` not a 1-D array of positive numbers, or an index outside the pool.

    Example:
        >>> weights_of(proposal([0.0, 0.0, 1.0, 1.0], alpha=0.5), [3, 0, 3])
        array([0.66666667, 2.        , 0.66666667])
    """
    probabilities = _vector("q", q)
    if (probabilities <= 0.0).any():
        raise ValueError(f"expected q > 0 everywhere, got {probabilities.min()}")
    indices = np.asarray(drawn)
    if indices.ndim != 1 or not (indices.size == 0 or np.issubdtype(indices.dtype, np.integer)):
        raise ValueError(f"expected drawn to be a 1-D array of indices, got {drawn!r}")
    if indices.size and not (indices.min() >= 0 and indices.max() < probabilities.size):
        raise ValueError(f"expected drawn indices in [0, {probabilities.size}), got {indices.min()}..{indices.max()}")
    weights: npt.NDArray[np.float64] = 1.0 / (probabilities.size * probabilities[indices])
    return weights


def _percent(x: float) -> str:
    points = 100.0 * x
    return f"{points:.2g}%" if 0.0 < abs(points) < 0.1 else f"{points:.2f}".rstrip("0").rstrip(".") + "%"


@dataclass(frozen=True)
class RateEstimate:
    """A failure rate estimated by importance sampling, with its interval.

    Attributes:
        rate: the unbiased estimate ``mean(f * w)`` (not clipped: it may exceed 1 in a rare, tiny sample).
        low: the interval's lower end.
        high: the interval's upper end.
        failures: how many of the episodes failed.
        episodes: how many episodes were run (``K``).
        confidence: the interval's level.
    """

    rate: float
    low: float
    high: float
    failures: int
    episodes: int
    confidence: float

    def summary(self) -> str:
        """One line: the rate, its interval, and what it came from.

        Example:
            >>> RateEstimate(0.0052, 0.0031, 0.0074, 37, 600, 0.95).summary()
            '0.52% [0.31%, 0.74%] (importance sampling: 37 failures in 600 episodes from the learned proposal)'
        """
        failures = f"{self.failures} failure{'' if self.failures == 1 else 's'}"
        return (
            f"{_percent(self.rate)} [{_percent(self.low)}, {_percent(self.high)}] "
            f"(importance sampling: {failures} in {self.episodes} episodes from the learned proposal)"
        )


def _exact_bounds(failures: float, episodes: float, confidence: float) -> tuple[float, float]:
    """The two-sided exact (Clopper-Pearson) interval of a binomial chance from ``failures`` of ``episodes``.

    The counts may be fractional (effective counts): the interval is the beta quantiles' all the same.
    """
    tail = (1.0 - confidence) / 2.0
    if failures <= 0.0:
        return 0.0, 1.0 - tail ** (1.0 / episodes)
    from scipy.special import betaincinv  # the beta quantile; scipy.stats takes ~1 s to import, its ppf ~0.4 ms

    low = float(betaincinv(failures, episodes - failures + 1.0, tail))
    high = 1.0 if failures >= episodes else float(betaincinv(failures + 1.0, episodes - failures, 1.0 - tail))
    return low, high


def importance_rate(
    failed: npt.ArrayLike,
    weights: npt.ArrayLike,
    pool: int,
    *,
    alpha: float = 0.5,
    min_weight: float = 0.0,
    confidence: float = 0.95,
) -> RateEstimate:
    """The failure rate of a uniform start, from episodes whose starts were drawn from a proposal over a pool.

    Args:
        failed: each episode's outcome, ``True`` when it failed (``K`` of them; a start drawn twice counts twice).
        weights: each episode's weight ``(1 / N) / q_j`` (:func:`weights_of`), in the same order.
        pool: ``N``, the number of uniform starts the proposal was over.
        alpha: the proposal's uniform share (:func:`proposal`): the bounded interval's upper end is ``1 / alpha``
            times the proposal's failure chance, so it must be the ``alpha`` the weights came from.
        min_weight: the smallest weight over the whole pool, ``1 / (N * max(q))``, for a lower end above 0 in the
            bounded interval; 0 (the default) leaves that end at 0.
        confidence: the interval's level, in (0, 1).

    Returns:
        The estimate, its interval (from the effective counts from :data:`MIN_FAILURES` failures on, bounded below;
        see the module's text) and the counts.

    Raises:
        ValueError: ``failed`` and ``weights`` empty or of different lengths, an outcome other than 0/1, a weight
            outside [1 / N, 1 / alpha], ``min_weight`` above the smallest weight, ``pool`` below 1, ``alpha`` outside
            (0, 1] or ``confidence`` outside (0, 1).

    Example:
        >>> q = proposal([0.0, 0.0, 1.0, 1.0], alpha=0.5)
        >>> drawn = [2, 3, 3, 0, 2, 1, 3, 2]
        >>> failed = [True, True, False, False, True, False, True, True]
        >>> estimate = importance_rate(failed, weights_of(q, drawn), pool=4, alpha=0.5, min_weight=1 / (4 * q.max()))
        >>> round(estimate.rate, 3), estimate.failures, estimate.episodes
        (0.417, 5, 8)
    """
    alpha = _check_alpha(alpha)
    confidence = check_open_fraction("importance_rate", "confidence", confidence)
    if isinstance(pool, bool) or not isinstance(pool, int | np.integer) or pool < 1:
        raise ValueError(f"expected pool to be a whole number of starts >= 1, got {pool!r}")
    outcomes = _vector("failed", failed)
    if not np.isin(outcomes, (0.0, 1.0)).all():
        raise ValueError(f"expected failed to be booleans, got {outcomes[~np.isin(outcomes, (0.0, 1.0))][0]}")
    w = _vector("weights", weights)
    if w.size != outcomes.size:
        raise ValueError(f"expected one weight per outcome, got {w.size} weights and {outcomes.size} outcomes")
    if w.min() < (1.0 - _SLACK) / pool:
        raise ValueError(f"expected weights >= 1 / pool = {1.0 / pool:.3g} (q <= 1), got {w.min()}: is pool right?")
    if w.max() > (1.0 + _SLACK) / alpha:
        raise ValueError(f"expected weights <= 1 / alpha = {1.0 / alpha:.3g}, got {w.max()}: is alpha the proposal's?")
    min_weight = float(min_weight)
    if not 0.0 <= min_weight <= w.min() * (1.0 + _SLACK):
        raise ValueError(f"expected min_weight in [0, smallest weight {w.min()}], got {min_weight}")

    episodes = outcomes.size
    failures = int(outcomes.sum())
    y = outcomes * w
    rate = float(y.mean())
    share = min(max(rate, 0.0), 1.0)
    variance = float(y.var(ddof=1)) / episodes + share * (1.0 - share) / pool if episodes > 1 else 0.0
    if failures >= MIN_FAILURES and variance > 0.0 and share * (1.0 - share) > 0.0:  # share inside (0, 1)
        effective = share * (1.0 - share) / variance
        low, high = _exact_bounds(effective * share, effective, confidence)
    else:
        q_low, q_high = _exact_bounds(failures, episodes, confidence)
        low, high = min_weight * q_low, min(1.0, q_high / alpha)
    return RateEstimate(rate, low, high, failures, episodes, confidence)
