"""The guided search's proposals: a portfolio of samplers that shifts its starts to the ones that pay off.

Each sampler (an *arm*) proposes starts in the unit box ``[-1, 1]^d`` (every
variable's range mapped onto ``[-1, 1]``):

* ``uniform``: uniform draws. It always keeps a share ``UNIFORM_FLOOR`` (half) of every
  round, so the search keeps sampling the whole space however the others fare
  (FalStar's portfolio keeps a uniform solver for the same reason);
* ``trend`` (the cross-entropy method): a Gaussian, one standard deviation per
  variable, fitted to the lowest-scoring fraction ``ELITE_FRACTION`` of every
  start scored so far; it follows where the scores fall across the space;
* ``local``: a Gaussian step (``STEP`` of the box's half-width) from one of the
  ``ELITE`` lowest-scoring starts, each retired after ``RETIRE`` steps; it
  searches the neighbourhood of the single starts closest to failing;
* ``learned`` (only given a failure predictor, ``predict``): one of
  ``CANDIDATES`` uniform draws, each picked with a chance proportional to the
  square of the predictor's chance that it fails (``SHARPNESS``;
  :mod:`specguard.falsify.predictor`). It steers by where related, weaker
  agents failed, not by the agent's own margins. Not simply the likeliest: a
  predictor that knows little (its chances nearly alike, as from a handful of
  failures) leaves its starts nearly uniform instead of piling them on the
  corner its fitted surface happens to peak at, while a sharp one still sends
  them to its region.

An episode *pays off* when its score falls below the ``PAYOFF_QUANTILE``
quantile of the scores before it (it came closer to failing than most). Each
round's starts beyond the uniform floor are shared out by the arms' payoff
rates (with one success and one failure added to each, so an arm never tried
keeps a share): an arm whose starts keep landing among the lowest scores
earns more of the next round, and a uniform share remains however little it
earns.

Example:
    >>> import numpy as np
    >>> portfolio = Portfolio(dimensions=2, rng=np.random.default_rng(0))
    >>> points, arms = portfolio.propose(8)
    >>> points.shape, arms == ["uniform"] * 8  # nothing scored yet: every start uniform
    ((8, 2), True)
    >>> portfolio.observe(points, np.linspace(0.0, 1.0, 8), arms)
    >>> bool(np.all(np.abs(portfolio.propose(8)[0]) <= 1.0))
    True
"""

from __future__ import annotations

import heapq
from collections import Counter
from collections.abc import Callable, Iterator

import numpy as np

__all__ = ["ARMS", "Portfolio"]

ARMS = ("uniform", "trend", "local", "learned")
"""The samplers, in the order a round's starts are given out (``learned`` only with a predictor)."""

SHARPNESS = 2.0
"""The ``learned`` arm picks a candidate with a chance proportional to its predicted chance of failing to this power.

Measured on tests/test_falsify_learned.py's plane (weaker agents failed from a square, a sixteenth of it, the agent
from a corner of it, 1 start in 400): proportional (1) puts 60% of the arm's starts in the square, and 10 searches
needed 1,270 episodes in all; squared, 77% and 922; a power of 50 (nearly the likeliest candidate), 86% and 899;
without the predictor, 2,272. Squared keeps most of the gain, while a predictor fitted on a few failures, whose
chances are nearly alike, still leaves the arm's starts nearly uniform instead of sending them wherever its surface
peaks.
"""

CANDIDATES = 32
"""The ``learned`` arm picks one of this many uniform draws, by the predictor's chances."""

UNIFORM_FLOOR = 0.5
"""The share of every round drawn uniformly, whatever the arms earned.

Half: where the score leads away from the failures, half of the starts still fail as often as uniform draws do, so
the search needs at most about twice random's episodes (with a quarter, one CartPole agent's searches needed 1.98
times random's).
"""

PAYOFF_QUANTILE = 0.1
"""An episode pays off when its score is below this quantile of the scores before it."""

ELITE_FRACTION = 0.2
"""The ``trend`` arm fits its Gaussian to this fraction of the lowest scores so far."""

MIN_ELITE = 4
"""Starts the ``trend`` arm fits to at least."""

MIN_SPREAD = 0.05
"""The ``trend`` arm's smallest standard deviation per variable (of the unit box's half-width)."""

ELITE = 4
"""The ``local`` arm steps from one of this many starts with the lowest scores so far."""

STEP = 0.1
"""The ``local`` arm's step, per variable, as a fraction of the unit box's half-width."""

RETIRE = 4
"""Steps from one start after which the ``local`` arm leaves it."""


class Portfolio:
    """The guided search's samplers and their shares, over the unit box of ``dimensions`` variables.

    Args:
        dimensions: the start space's variables.
        rng: the search's random generator.
        predict: ``predict(points) -> chances``: the failure predictor's chance of failing from each start (rows of
            unit-box points); ``None``: no ``learned`` arm.
    """

    def __init__(
        self,
        dimensions: int,
        rng: np.random.Generator,
        predict: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.dimensions = int(dimensions)
        self.rng = rng
        self.predict = predict
        self.points: list[np.ndarray] = []
        self.scores: list[float] = []
        self.paid: Counter[str] = Counter()
        self.tried: Counter[str] = Counter()
        self._uses: Counter[int] = Counter()

    @property
    def arms(self) -> tuple[str, ...]:
        """The arms in play: :data:`ARMS`, ``learned`` only with a predictor."""
        return ARMS if self.predict is not None else tuple(a for a in ARMS if a != "learned")

    def shares(self) -> dict[str, float]:
        """Each arm's share of the next round: the uniform floor, the rest by payoff rate."""
        rates = {a: (self.paid[a] + 1) / (self.tried[a] + 2) for a in self.arms}
        total = sum(rates.values())
        floor = {a: UNIFORM_FLOOR if a == "uniform" else 0.0 for a in self.arms}
        return {a: floor[a] + (1 - UNIFORM_FLOOR) * r / total for a, r in rates.items()}

    def propose(self, n: int) -> tuple[np.ndarray, list[str]]:
        """``n`` starts in the unit box (rows), with the arm that proposed each."""
        shares = self.shares()
        if len(self.scores) < MIN_ELITE:  # no scores to follow yet: uniform draws, and the predictor's (needs none)
            ranked = 1.0 - UNIFORM_FLOOR if self.predict is not None else 0.0
            shares = {a: {"uniform": 1.0 - ranked, "learned": ranked}.get(a, 0.0) for a in self.arms}
        counts = self.rng.multinomial(n, [shares[a] for a in self.arms])
        arms = [a for a, k in zip(self.arms, counts, strict=True) for _ in range(int(k))]
        learned = self._learned(arms.count("learned"))
        points = [next(learned) if a == "learned" else self._draw(a) for a in arms]
        return (np.stack(points) if points else np.empty((0, self.dimensions))), arms

    def _learned(self, n: int) -> Iterator[np.ndarray]:
        """``n`` starts of the ``learned`` arm: each the likeliest to fail of ``CANDIDATES`` uniform draws (one
        call of the predictor for all)."""
        if not n or self.predict is None:
            return iter(())
        candidates = self.rng.uniform(-1.0, 1.0, (n, CANDIDATES, self.dimensions))
        chances = np.asarray(self.predict(candidates.reshape(-1, self.dimensions))).reshape(n, CANDIDATES)
        chances = np.maximum(chances, 1e-12) ** SHARPNESS
        cumulative = np.cumsum(chances / chances.sum(axis=1, keepdims=True), axis=1)
        picked = (cumulative < self.rng.random((n, 1))).sum(axis=1).clip(max=CANDIDATES - 1)
        return iter(candidates[np.arange(n), picked])

    def observe(self, points: np.ndarray, scores: np.ndarray, arms: list[str]) -> None:
        """The scores of proposed starts: each arm's payoff is counted, and the starts join the pool."""
        for point, score, arm in zip(points, scores, arms, strict=True):
            if len(self.scores) >= MIN_ELITE:
                self.tried[arm] += 1
                self.paid[arm] += int(score < np.quantile(self.scores, PAYOFF_QUANTILE))
            self.points.append(np.asarray(point, dtype=np.float64))
            self.scores.append(float(score))

    def _draw(self, arm: str) -> np.ndarray:
        d = self.dimensions
        if arm == "trend":
            k = max(MIN_ELITE, int(np.ceil(ELITE_FRACTION * len(self.scores))))
            elite = np.stack([self.points[i] for i in np.argsort(self.scores, kind="stable")[:k]])
            spread = np.maximum(elite.std(axis=0), MIN_SPREAD)
            drawn: np.ndarray = self.rng.normal(elite.mean(axis=0), spread)
            np.clip(drawn, -1.0, 1.0, out=drawn)
            return drawn
        if arm == "local":
            kept = ((s, i) for i, s in enumerate(self.scores) if self._uses[i] < RETIRE)
            parents = heapq.nsmallest(ELITE, kept)
            if not parents:  # every start retired: nothing local left to try
                return self.rng.uniform(-1.0, 1.0, d)
            _, i = parents[int(self.rng.integers(len(parents)))]
            self._uses[i] += 1
            return np.clip(self.points[i] + self.rng.normal(0.0, STEP, d), -1.0, 1.0)
        return self.rng.uniform(-1.0, 1.0, d)
