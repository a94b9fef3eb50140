"""A failure predictor: the chance that an agent fails from a start, learned from related, less robust agents.

After Uesato et al. ("Rigorous Agent Evaluation: An Adversarial Approach to
Uncover Catastrophic Failures", ICLR 2019), who learn an adversarial value
function from weaker agents of the same training, whose failures are
frequent, and search with it where the agent itself rarely fails.

The data (:class:`FailureData`): episodes of related agents, each with the
features of its first state, how much weaker than the agent judged its agent
was (``weakness``, 0 the agent itself, 1 the weakest), whether it failed, and
a weight. Two sources give them:

* a run's interim looks (``RunResult.looks``): the checkpoint at step ``t``
  of a run of ``T`` steps has weakness ``1 - t / T``; later checkpoints weigh
  more (weight ``t / T``), as the agent judged is the last;
* the agent itself with ``epsilon``-random actions
  (:func:`specguard.falsify.related.perturbed`): at each
  step, with probability ``epsilon``, a uniformly random action instead of its
  own; weakness ``epsilon``. It needs only the agent, so it serves agents
  trained elsewhere too (and a run whose looks saw too few failures).

The model (:class:`FailurePredictor`): a logistic regression over the
standardised features, their squares and products, and the weakness, with an
L2 penalty, fitted by Newton's method (numpy; a few milliseconds on hundreds
of episodes), asked at weakness 0. Why not scikit-learn: on the benchmark's
development agents (docs/guide/falsify.md), this model ranked the agent's own
failures better (AUC 0.68, 0.62 and 0.90 on CartPole seeds 9 and 10 and
InvertedPendulum seed 9) than scikit-learn's ``LogisticRegression`` over the
same features (0.58, 0.52, 0.89) and its ``HistGradientBoostingClassifier``
(0.57, 0.41, 0.85), in 1-3 ms against 11-830 ms, and needs no new dependency.

Example:
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> x = rng.uniform(-1, 1, (400, 2))
    >>> data = FailureData(x, np.full(400, 0.5), x[:, 0] > 0.6, np.ones(400))
    >>> p = FailurePredictor().fit(data)
    >>> bool(p.predict(np.array([[0.9, 0.0]]))[0] > p.predict(np.array([[-0.9, 0.0]]))[0])
    True
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["FailureData", "FailurePredictor", "from_looks"]

PENALTY = 1.0
"""The L2 penalty on the logistic model's coefficients (the intercept is not penalised)."""

ITERATIONS = 25
"""Newton steps at most (it converges in under ten on the benchmark's agents)."""


@dataclass(frozen=True)
class FailureData:
    """Episodes of related agents: per episode (rows), its first state's features, its agent's weakness, whether
    it failed, and its weight.

    Raises:
        ValueError: the arrays disagree in length, or ``features`` is not a 2-D array of finite numbers.
    """

    features: np.ndarray
    weakness: np.ndarray
    failed: np.ndarray
    weights: np.ndarray

    def __post_init__(self) -> None:
        f = np.asarray(self.features, dtype=np.float64)
        if f.ndim != 2 or not np.all(np.isfinite(f)):
            raise ValueError(f"expected features as a 2-D array of finite numbers, got shape {f.shape}")
        n = len(f)
        for name in ("weakness", "failed", "weights"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"expected {n} {name} (one per episode), got {len(getattr(self, name))}")
        object.__setattr__(self, "features", f)
        object.__setattr__(self, "weakness", np.asarray(self.weakness, dtype=np.float64))
        object.__setattr__(self, "failed", np.asarray(self.failed, dtype=bool))
        object.__setattr__(self, "weights", np.asarray(self.weights, dtype=np.float64))

    def __len__(self) -> int:
        return len(self.features)

    @property
    def failures(self) -> int:
        return int(self.failed.sum())

    def __add__(self, other: FailureData) -> FailureData:
        return FailureData(
            np.concatenate([self.features, other.features]),
            np.concatenate([self.weakness, other.weakness]),
            np.concatenate([self.failed, other.failed]),
            np.concatenate([self.weights, other.weights]),
        )


def from_looks(looks: Sequence[Mapping[str, Any]], keys: Sequence[str]) -> FailureData | None:
    """A run's interim looks (``RunResult.looks``) as failure data: an episode failed where any of ``keys`` (the
    asserted goal and safety keys) did not hold; the checkpoint at step ``t`` of the last look's ``T`` has weakness
    ``1 - t / T`` and weight ``t / T``. ``None`` where the looks hold no episode or judged none of ``keys``.

    Example:
        >>> looks = [{"timesteps": 500, "features": [[0.1], [0.2]], "held": {"g": "01"}},
        ...          {"timesteps": 1000, "features": [[0.3]], "held": {"g": "1"}}]
        >>> data = from_looks(looks, ["g"])
        >>> data.failed.tolist(), data.weakness.tolist(), data.weights.tolist()
        ([True, False, False], [0.5, 0.5, 0.0], [0.5, 0.5, 1.0])
    """
    rows = [look for look in looks if look["features"] and any(k in look["held"] for k in keys)]
    if not rows:
        return None
    last = max(int(look["timesteps"]) for look in rows) or 1
    features, weakness, failed, weights = [], [], [], []
    for look in rows:
        progress = int(look["timesteps"]) / last
        held = [look["held"][k] for k in keys if k in look["held"]]
        for i, f in enumerate(look["features"]):
            features.append(f)
            failed.append(any(h[i] == "0" for h in held))
            weakness.append(1.0 - progress)
            weights.append(progress)
    return FailureData(np.array(features, dtype=np.float64), np.array(weakness), np.array(failed), np.array(weights))


class FailurePredictor:
    """P(fail | start features, weakness): a logistic regression over quadratic features, L2-penalised.

    Args:
        penalty: the L2 penalty on the coefficients (:data:`PENALTY`).
    """

    def __init__(self, penalty: float = PENALTY) -> None:
        self.penalty = float(penalty)
        self.coef: np.ndarray | None = None
        self._mean = np.zeros(0)
        self._scale = np.ones(0)

    def _design(self, features: np.ndarray, weakness: np.ndarray) -> np.ndarray:
        z = (np.asarray(features, dtype=np.float64) - self._mean) / self._scale
        d = z.shape[1]
        i, j = np.triu_indices(d)
        return np.column_stack([np.ones(len(z)), z, z[:, i] * z[:, j], weakness])

    def fit(self, data: FailureData) -> FailurePredictor:
        """Fit to ``data`` (weighted): Newton's method on the penalised log-likelihood."""
        self._mean = data.features.mean(axis=0) if len(data) else np.zeros(data.features.shape[1])
        scale = data.features.std(axis=0) if len(data) else np.ones(data.features.shape[1])
        self._scale = np.where(scale > 1e-12, scale, 1.0)
        x = self._design(data.features, data.weakness)
        y = data.failed.astype(np.float64)
        w = data.weights
        ridge = np.full(x.shape[1], self.penalty)
        ridge[0] = 1e-6
        beta = np.zeros(x.shape[1])
        total = w.sum()
        if total > 0:  # start at the weighted base rate, kept off 0 and 1
            rate = np.clip((w * y).sum() / total, 1e-4, 1 - 1e-4)
            beta[0] = np.log(rate / (1 - rate))
        for _ in range(ITERATIONS):
            p = 1.0 / (1.0 + np.exp(-np.clip(x @ beta, -30, 30)))
            gradient = x.T @ (w * (p - y)) + ridge * beta
            hessian = (x * (w * p * (1 - p))[:, None]).T @ x + np.diag(ridge)
            step = np.linalg.solve(hessian, gradient)
            beta -= step
            if np.max(np.abs(step)) < 1e-6:
                break
        self.coef = beta
        return self

    def predict(self, features: np.ndarray, weakness: float = 0.0) -> np.ndarray:
        """The chance of failing from starts with these features (rows), for an agent of this weakness."""
        if self.coef is None:
            raise ValueError("FailurePredictor.predict before fit")
        x = self._design(features, np.full(len(features), float(weakness)))
        return np.asarray(1.0 / (1.0 + np.exp(-np.clip(x @ self.coef, -30, 30))))
