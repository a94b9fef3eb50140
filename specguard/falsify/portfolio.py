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
  searches the neighbourhood of the single starts closest to failing.

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

import numpy as np

__all__ = ["ARMS", "Portfolio"]

ARMS = ("uniform", "trend", "local")
"""The samplers, in the order a round's starts are given out."""

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
    """

    def __init__(self, dimensions: int, rng: np.random.Generator) -> None:
        self.dimensions = int(dimensions)
        self.rng = rng
        self.points: list[np.ndarray] = []
        self.scores: list[float] = []
        self.paid: Counter[str] = Counter()
        self.tried: Counter[str] = Counter()
        self._uses: Counter[int] = Counter()

    def shares(self) -> dict[str, float]:
        """Each arm's share of the next round: the uniform floor, the rest by payoff rate."""
        rates = {a: (self.paid[a] + 1) / (self.tried[a] + 2) for a in ARMS}
        total = sum(rates.values())
        floor = {a: UNIFORM_FLOOR if a == "uniform" else 0.0 for a in ARMS}
        return {a: floor[a] + (1 - UNIFORM_FLOOR) * r / total for a, r in rates.items()}

    def propose(self, n: int) -> tuple[np.ndarray, list[str]]:
        """``n`` starts in the unit box (rows), with the arm that proposed each."""
        shares = self.shares()
        if len(self.scores) < MIN_ELITE:  # nothing to follow yet
            shares = {a: float(a == "uniform") for a in ARMS}
        counts = self.rng.multinomial(n, [shares[a] for a in ARMS])
        arms = [a for a, k in zip(ARMS, counts, strict=True) for _ in range(int(k))]
        points = np.stack([self._draw(a) for a in arms]) if arms else np.empty((0, self.dimensions))
        return points, arms

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
