"""What a gate can see, without training: the chance of a verdict at a given true success, by exact sums or simulation.

Two questions, both answered from a spec's budget and nothing trained:

* **thresholds** (:func:`chance_met`): the chance that one run whose policy
  succeeds with probability ``p`` is judged *met* at its final evaluation
  (``eval_episodes``, doubled while undecided up to ``max_eval_episodes``, each
  stage judged at the spec's look-corrected confidence), and the chance the
  goal passes its quorum (:func:`chance_passed`). Exact binomial sums.
* **comparisons** (:func:`min_detectable_drop`): the smallest drop in success
  the regression gate flags with 80% power, by simulating the gate itself
  (:func:`simulate_gate`: the same permutation tests, looks and stopping rule
  as :func:`specguard.stats.sequential.compare_seeds`) on seeds whose true
  rates are beta-distributed around the goal's success with a given
  seed-to-seed spread (:class:`SeedLaw`), each seed evaluated on ``episodes``
  binomial episodes.

The spread is the standard deviation of the seeds' true success rates: assumed
(:data:`DEFAULT_SPREAD`), or estimated from a baseline's seeds
(:func:`estimated_spread`).

Example:
    >>> round(chance_met(0.9, threshold=0.8, stages=(30, 60, 120), confidence=0.99583), 2)
    0.48
    >>> estimated_spread([(15, 30), (16, 30)])  # no more spread than 30 episodes alone give
    0.0
    >>> round(estimated_spread([(27, 30), (15, 30), (29, 30), (24, 30)]), 2)
    0.2
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from specguard.stats.intervals import run_verdict
from specguard.stats.sequential import (
    Design,
    GateState,
    drop_bounds,
    look_levels,
    permutation_p_values,
    states,
    transformed,
    z_of,
)
from specguard.stats.verdicts import RunVerdict

__all__ = [
    "DEFAULT_SPREAD",
    "POWER",
    "SIMULATIONS",
    "SeedLaw",
    "Simulated",
    "chance_met",
    "chance_passed",
    "estimated_spread",
    "gate_power",
    "min_detectable_drop",
    "simulate_gate",
]

DEFAULT_SPREAD = 0.05
"""The seed-to-seed spread (standard deviation of per-seed true success) assumed where no baseline estimates it."""

POWER = 0.8
"""The power a detectable drop is flagged with."""

SIMULATIONS = 1000
"""Simulated pull requests per power figure of a plan (a power near 80% is then known to about +-1.3 points)."""


@dataclass(frozen=True)
class SeedLaw:
    """Seeds whose true success rates are beta-distributed with mean ``success`` and standard deviation ``spread``.

    A spread the mean cannot carry (a beta's variance is below ``success * (1 - success)``) is
    narrowed to 99% of that bound; a spread of 0 gives every seed the same rate.
    """

    success: float
    spread: float

    def draw(self, rng: np.random.Generator, shape: tuple[int, ...], episodes: int) -> np.ndarray:
        """Successes out of ``episodes`` per seed: ``shape`` of them."""
        mu = min(max(self.success, 0.0), 1.0)
        limit = mu * (1.0 - mu)
        variance = min(self.spread**2, 0.99 * limit)
        if variance <= 0.0 or limit <= 0.0:
            rates = np.full(shape, mu)
        else:
            total = limit / variance - 1.0
            rates = rng.beta(mu * total, (1.0 - mu) * total, size=shape)
        return rng.binomial(episodes, rates)


@dataclass(frozen=True)
class Simulated:
    """Simulated comparisons: each one's repeated p-value for a drop, pull-request seeds trained and final state."""

    p_drop: np.ndarray
    seeds: np.ndarray
    state: np.ndarray

    @property
    def flagged(self) -> np.ndarray:
        return np.asarray(self.state == GateState.DROPPED.value)


def simulate_gate(
    before: SeedLaw,
    after: SeedLaw,
    design: Design,
    *,
    sims: int,
    episodes: int,
    rng: np.random.Generator,
    test: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] = permutation_p_values,
) -> Simulated:
    """Run the gate's sequential comparison on ``sims`` simulated pull requests.

    The baseline has ``design.baseline_seeds`` seeds drawn from ``before``; the pull
    request draws from ``after`` and looks at ``design.looks`` seeds, stopping as
    :func:`specguard.stats.sequential.compare_seeds` does. ``test`` gives each look's
    p-values from the transformed per-seed rates (the gate's permutation test; another
    only to compare tests, as ``benchmarks/bench_gate.py`` does).
    """
    kb = before.draw(rng, (sims, design.baseline_seeds), episodes)
    ka = after.draw(rng, (sims, design.ceiling), episodes)
    nb, na = np.full(kb.shape, episodes), np.full(ka.shape, episodes)
    yb, ya = transformed(kb, nb), transformed(ka, na)
    looks = design.looks
    fractions = design.fractions(looks)
    p_drop = np.ones(sims)
    seeds = np.zeros(sims, dtype=int)
    state = np.full(sims, GateState.OPEN.value, dtype=f"<U{max(len(g.value) for g in GateState)}")
    active = np.arange(sims)
    for look, m in enumerate(looks):
        if not active.size:
            break
        low, _ = test(yb[active], ya[active, :m])
        p_drop[active] = np.minimum(p_drop[active], look_levels(z_of(low), fractions, look))
        _, _, upper = drop_bounds(kb[active], nb[active], ka[active, :m], na[active, :m])
        seeds[active] = m
        state[active] = states(p_drop[active], upper, design)
        active = active[state[active] == GateState.OPEN.value]
    return Simulated(p_drop=p_drop, seeds=seeds, state=state)


def gate_power(
    success: float, drop: float, spread: float, design: Design, *, episodes: int, sims: int = SIMULATIONS, seed: int = 0
) -> float:
    """The share of simulated pull requests whose goal, ``drop`` below a baseline at ``success``, is flagged."""
    rng = np.random.default_rng(seed)
    after = SeedLaw(max(success - drop, 0.0), spread)
    return float(
        simulate_gate(SeedLaw(success, spread), after, design, sims=sims, episodes=episodes, rng=rng).flagged.mean()
    )


def min_detectable_drop(
    success: float,
    spread: float,
    design: Design,
    *,
    episodes: int,
    power: float = POWER,
    sims: int = SIMULATIONS,
    resolution: float = 0.01,
) -> float | None:
    """The smallest drop (rate points, to ``resolution``) flagged with at least ``power``; None if not even a drop to 0.

    Bisection over the drop, each power figure simulated with the same seed.
    """
    if gate_power(success, success, spread, design, episodes=episodes, sims=sims) < power:
        return None
    lo, hi = 0.0, success
    while hi - lo > resolution:
        mid = (lo + hi) / 2
        if gate_power(success, mid, spread, design, episodes=episodes, sims=sims) >= power:
            hi = mid
        else:
            lo = mid
    return hi


def estimated_spread(runs: Sequence[tuple[int, int]]) -> float | None:
    """The seed-to-seed spread of ``(successes, episodes)`` runs, by moments: the rates' variance less the binomial.

    None with fewer than 2 runs (no spread to see); 0 when the rates vary no more than episodes alone would.
    """
    if len(runs) < 2:
        return None
    rates = np.array([k / n for k, n in runs])
    binomial = float(np.mean([(k / n) * (1 - k / n) / n for k, n in runs]))
    return math.sqrt(max(0.0, float(rates.var(ddof=1)) - binomial))


def _binomial_pmf(n: int, p: float) -> np.ndarray:
    k = np.arange(n + 1)
    if p <= 0.0 or p >= 1.0:
        return np.asarray(k == (0 if p <= 0.0 else n), dtype=float)
    logs = np.array([math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1) for i in k])
    return np.asarray(np.exp(logs + k * math.log(p) + (n - k) * math.log1p(-p)))


def chance_met(
    p: float, *, threshold: float, stages: Sequence[int], confidence: float, undecided_met: bool = False
) -> float:
    """The chance that a run with true success ``p`` is judged met at its final evaluation.

    Stage by stage (cumulative episodes ``stages``), as :func:`specguard.stats.anytime.final_evaluation`
    judges: met or missed ends the evaluation, undecided goes on to the next stage. A run still
    undecided after the last stage counts as met when ``undecided_met`` (a spec's ``undecided="pass"``).
    """
    met = 0.0
    carried = np.array([1.0])  # the chance of each success count so far among runs still undecided
    done = 0
    for total in stages:
        fresh = _binomial_pmf(total - done, p)
        counts = np.convolve(carried, fresh)
        verdicts = [run_verdict(k, total, threshold, confidence) for k in range(total + 1)]
        met += float(sum(c for c, v in zip(counts, verdicts) if v is RunVerdict.MET))
        carried = np.array([c if v is RunVerdict.UNDECIDED else 0.0 for c, v in zip(counts, verdicts)])
        done = total
    if undecided_met:
        met += float(carried.sum())
    return min(1.0, met)


def chance_passed(met: float, *, required: int, runs: int) -> float:
    """The chance that at least ``required`` of ``runs`` runs, each met with chance ``met``, are met: the quorum."""
    return float(sum(math.comb(runs, i) * met**i * (1 - met) ** (runs - i) for i in range(required, runs + 1)))
