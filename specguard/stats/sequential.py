"""Regression gating across seeds: a group-sequential test of a drop in success, looked at again with more seeds.

A pull request's goal is compared with the baseline stored on the main
branch. Each side is a handful of training seeds, each evaluated on ``n``
episodes (``k`` successes). Seeds are the unit: their success rates vary from
seed to seed far more than episodes do, so a test on pooled episodes would
see drops that are only seed-to-seed spread. The comparison is built in three
pieces, each standard:

**The statistic** (:func:`permutation_p_values`): a two-sample permutation test
of the mean per-seed success, one-sided, on Anscombe's variance-stabilising
transform of each seed's rate, ``y = asin(sqrt((k + 3/8) / (n + 3/4)))``. When
nothing changed, the ``m_B + m_A`` seeds of both sides are exchangeable draws
of one distribution, so the share of the ways of splitting them into a
baseline and a pull request whose pull-request side is as low as the one
observed is an exact p-value, whatever that distribution (all
``C(m_B + m_A, m_A)`` splits up to ``ENUMERATED`` of them, else ``RANDOM_SPLITS``
fixed random ones with the usual ``(1 + count) / (1 + splits)``). Seeds of RL
runs are often skewed or bimodal (a seed that never learns); a t-test on
their rates, even pooled and transformed, flags such seeds up to 1.9 times as
often as its level allows with 2 seeds in the pull request, the permutation
test never more (``benchmarks/bench_gate.py``). The price is granularity: with
``m_B = 8`` and 2 seeds a side nothing is below ``1/45``, so a drop is only ever
flagged after more seeds (4 at the earliest, 6 for the family's usual level).

**The looks** (:func:`repeated_p_value`): the pull request starts with the
spec's seeds and, while a comparison is *open*, trains ``step`` more, up to a
ceiling, and looks again. Looking again is accounted for by a group-sequential
design with Lan-DeMets error spending: the information of a look is
``1 / (1/m_B + 1/m_A)`` (``m_B`` baseline seeds, ``m_A`` seeds so far), its
fraction of the ceiling's is ``t``, and the level spent by then is the
Kim-DeMets power family ``alpha * t**3`` (close to O'Brien-Fleming's: very
little at the first look, nearly all at the last). The boundaries come from
the joint normal law of the looks, by recursive numerical integration
(Armitage, McPherson and Rowe 1969; Jennison and Turnbull 2000, ch. 19); a
look's permutation p-value is held against the boundary's nominal level
(their "significance level approach"): exact at each look, the looks' joint
law approximately normal, which the simulations check. Each comparison reports
its *repeated p-value*: the smallest level at which the design would have
flagged it at one of its looks so far. For every level ``a``, a comparison with
nothing changed gets a repeated p-value ``<= a`` with probability at most ``a``,
however many of its looks are taken, so repeated p-values are valid inputs
to a family-wise procedure (:mod:`specguard.stats.family`).

**Stopping**: a comparison is *dropped* once its repeated p-value is at or
below its level, *fine* once the drop is clearly within the margin (the
one-sided upper ``FUTILITY_CONFIDENCE`` confidence bound of the drop in
success, in points on the rate scale, lies below ``margin``), and *open*
otherwise. Stopping for "fine" is non-binding: it only ever ends a look
sequence earlier, which cannot raise false alarms.

Example:
    >>> design = Design(alpha=0.05 / 15, baseline_seeds=8, first=2, ceiling=8)
    >>> design.looks
    (2, 4, 6, 8)
    >>> [round(t, 3) for t in design.fractions((2, 4, 6, 8))]
    [0.4, 0.667, 0.857, 1.0]
    >>> look = compare_seeds([(28, 30)] * 8, [(29, 30), (27, 30)], design, (2,))
    >>> look.state
    <GateState.FINE: 'fine'>
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from specguard.validation import check_open_fraction

__all__ = [
    "DEFAULT_ALPHA",
    "DEFAULT_COMPARE_SEEDS",
    "DEFAULT_MARGIN",
    "ENUMERATED",
    "FUTILITY_CONFIDENCE",
    "RANDOM_SPLITS",
    "SPENDING_POWER",
    "Design",
    "GateState",
    "Look",
    "boundaries",
    "compare_seeds",
    "describe_change",
    "drop_bounds",
    "look_levels",
    "permutation_p_values",
    "repeated_p_value",
    "spent",
    "states",
    "transformed",
    "z_of",
]

DEFAULT_ALPHA = 0.05
"""The family-wise level of a session's comparisons (:mod:`specguard.stats.family`)."""

DEFAULT_COMPARE_SEEDS = 8
"""The one default of every door for the seeds a comparison may train (``--goal-specs-compare-seeds``), and for
the seeds a saved baseline stores: a spec's own ``Budget.max_seeds`` when that is larger."""

DEFAULT_MARGIN = 0.2
"""The drop in success (points on the rate scale) a comparison calls *fine* once it is clearly below it."""

SPENDING_POWER = 3.0
"""The Kim-DeMets power family ``alpha * t**rho`` with this ``rho``: O'Brien-Fleming-like, saving level for the last
looks, where the seeds are."""

FUTILITY_CONFIDENCE = 0.975
"""The confidence of the upper bound on the drop that must lie below the margin for a comparison to be *fine*."""

MIN_LEVEL = 1e-7  # repeated p-values are resolved down to this (a smaller one is reported as this)
_LEVELS = np.geomspace(MIN_LEVEL, 1.0, 97)
_GRID = 401  # points per look of the recursive integration (odd: Simpson's rule)


class GateState(str, enum.Enum):
    """A comparison at one look."""

    DROPPED = "dropped"
    FINE = "fine"
    OPEN = "open"


def spent(fraction: float, alpha: float, power: float = SPENDING_POWER) -> float:
    """The level spent by information fraction ``fraction``: ``alpha * fraction**power``, fraction clipped to [0, 1]."""
    return float(alpha * min(1.0, max(0.0, fraction)) ** power)


@dataclass(frozen=True)
class Design:
    """One comparison's sequential design.

    Args:
        alpha: the comparison's own level (its share of the family's: ``DEFAULT_ALPHA`` over the comparisons).
        baseline_seeds: seeds in the baseline (``m_B``).
        first: seeds of the pull request at the first look.
        ceiling: seeds of the pull request at most (the first look's, if smaller).
        step: seeds added per further look.
        margin: the drop (rate points) a comparison is *fine* once it is clearly below.
    """

    alpha: float
    baseline_seeds: int
    first: int
    ceiling: int
    step: int = 2
    margin: float = DEFAULT_MARGIN

    def __post_init__(self) -> None:
        check_open_fraction("Design", "alpha", self.alpha, "the comparison's own level")
        for name in ("baseline_seeds", "first", "step"):
            if getattr(self, name) < 1:
                raise ValueError(f"expected {name} >= 1, got {getattr(self, name)!r}")
        if not 0.0 < self.margin <= 1.0:
            raise ValueError(f"expected a margin in (0, 1], got {self.margin!r}")
        object.__setattr__(self, "ceiling", max(self.ceiling, self.first))

    @property
    def looks(self) -> tuple[int, ...]:
        """The pull request's seeds at each planned look: ``first``, then ``step`` more each, up to ``ceiling``."""
        seeds = [*list(range(self.first, self.ceiling, self.step)), self.ceiling]
        return tuple(seeds)

    def next_seeds(self, seeds: int) -> int:
        """The seeds of the look after one at ``seeds`` (``seeds`` itself at the ceiling)."""
        return min(self.ceiling, max(seeds + self.step, self.first))

    def fractions(self, seeds: Sequence[int]) -> tuple[float, ...]:
        """The information fraction of looks at ``seeds`` pull-request seeds: ``(1/m_B + 1/M) / (1/m_B + 1/m)``."""
        full = 1.0 / self.baseline_seeds + 1.0 / self.ceiling
        return tuple(min(1.0, full / (1.0 / self.baseline_seeds + 1.0 / m)) for m in seeds)


def _simpson(n: int) -> np.ndarray:
    w = np.ones(n)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return w / 3.0


def _crossing(bound: float, scores: np.ndarray, weighted: np.ndarray, sigma: float) -> float:
    """The chance of continuing to a look and crossing ``bound`` there: the sub-density carried one increment on."""
    from scipy.special import ndtr

    return float(np.sum(weighted * ndtr((scores - bound) / sigma)))


@functools.lru_cache(maxsize=4096)
def boundaries(fractions: tuple[float, ...], alpha: float, power: float = SPENDING_POWER) -> tuple[float, ...]:
    """The one-sided efficacy boundaries (z scale) of looks at ``fractions``, spending ``alpha * t**power``.

    ``P(Z_1 >= c_1 or ... or Z_K >= c_K) = spent(t_K)`` for the standardised
    statistics of a process with independent increments (``corr(Z_j, Z_k) =
    sqrt(t_j / t_k)``), computed look by look: the sub-density of the score
    ``S = Z sqrt(t)`` on the continuation region is carried to the next look by
    convolution with the increment's normal law (Simpson's rule on a grid).
    A look that spends nothing gets an infinite boundary.
    """
    from scipy.optimize import brentq
    from scipy.special import ndtri

    if any(b <= a for a, b in itertools.pairwise(fractions)) or not fractions or fractions[0] <= 0:
        raise ValueError(f"expected increasing information fractions in (0, 1], got {fractions!r}")
    out: list[float] = []
    s: np.ndarray | None = None  # grid of the score at the previous look (continuation region)
    dens: np.ndarray | None = None  # sub-density times quadrature weights on it
    before, prev_t = 0.0, 0.0
    for t in fractions:
        target = spent(t, alpha, power) - before
        if s is None:  # the first look: S ~ N(0, t)
            c = math.inf if target <= 0 else float(-ndtri(target))
            upper = c * math.sqrt(t) if math.isfinite(c) else 9.0 * math.sqrt(t)
            grid = np.linspace(-9.0 * math.sqrt(t), upper, _GRID)
            new = np.exp(-0.5 * grid**2 / t) / math.sqrt(2 * math.pi * t)
        else:
            assert dens is not None
            sigma = math.sqrt(t - prev_t)
            lo, hi = -9.0 * math.sqrt(t), 12.0 * math.sqrt(t)
            if target <= 0 or _crossing(hi, s, dens, sigma) >= target:
                c, upper = math.inf, 9.0 * math.sqrt(t)
            elif _crossing(lo, s, dens, sigma) <= target:  # the level left exceeds what can still cross: flag anything
                c, upper = lo / math.sqrt(t), lo
            else:
                args = (s, dens, sigma, target)
                upper = float(brentq(lambda b, *a: _crossing(b, *a[:3]) - a[3], lo, hi, args=args, xtol=1e-10))
                c = upper / math.sqrt(t)
            grid = np.linspace(-9.0 * math.sqrt(t), upper, _GRID)
            kernel = np.exp(-0.5 * ((grid[:, None] - s[None, :]) / sigma) ** 2) / (sigma * math.sqrt(2 * math.pi))
            new = kernel @ dens
        h = grid[1] - grid[0]
        s, dens = grid, new * _simpson(_GRID) * h
        out.append(c)
        before += max(target, 0.0)
        prev_t = t
    return tuple(out)


@functools.lru_cache(maxsize=1024)
def _level_table(fractions: tuple[float, ...], power: float) -> np.ndarray:
    """Boundaries per level of ``_LEVELS`` (rows) and look (columns)."""
    return np.array([boundaries(fractions, float(a), power) for a in _LEVELS])


def look_levels(z: np.ndarray, fractions: Sequence[float], look: int, power: float = SPENDING_POWER) -> np.ndarray:
    """Per statistic ``z`` (z scale) at look ``look`` (0-based) of looks at ``fractions``: the smallest level at
    which a design spending ``alpha * t**power`` flags it there (``MIN_LEVEL`` at least; 1 when none would).

    Interpolated in the level (log scale) between the boundaries of ``_LEVELS``.
    """
    table = _level_table(tuple(float(t) for t in fractions[: look + 1]), power)
    column = table[:, look]  # decreasing in the level; +inf where a level spends nothing at this look
    finite = np.isfinite(column)
    z = np.asarray(z, dtype=float)
    if not finite.any():
        return np.ones_like(z)
    xs, logs = column[finite][::-1], np.log(_LEVELS[finite])[::-1]
    levels = np.exp(np.interp(z, xs, logs))
    levels = np.where(z < xs[0], 1.0, levels)
    return np.where(z >= xs[-1], _LEVELS[finite][0], levels)


def repeated_p_value(z: Sequence[float], fractions: Sequence[float], power: float = SPENDING_POWER) -> float:
    """The smallest level at which a design spending ``alpha * t**power`` would have flagged one of the looks.

    Args:
        z: each look's statistic on the z scale (a t-test's p-value ``p`` as ``-ndtri(p)``).
        fractions: each look's information fraction.

    For every level ``a``, ``P(repeated p-value <= a) <= a`` when nothing changed (up to the normal approximation).
    """
    if len(z) != len(fractions):
        raise ValueError(f"expected one statistic per look, got {len(z)} statistics for {len(fractions)} looks")
    return min(float(look_levels(np.array(zk), fractions, k, power)) for k, zk in enumerate(z))


ENUMERATED = 20_000
"""Permutation tests enumerate every split of the seeds up to this many splits."""

RANDOM_SPLITS = 19_999
"""Beyond :data:`ENUMERATED`, this many random splits (fixed per size: the same data give the same p-value)."""


def transformed(successes: np.ndarray, episodes: np.ndarray) -> np.ndarray:
    """Anscombe's variance-stabilising transform of per-seed rates: ``asin(sqrt((k + 3/8) / (n + 3/4)))``."""
    return np.arcsin(np.sqrt((np.asarray(successes, float) + 0.375) / (np.asarray(episodes, float) + 0.75)))


@functools.lru_cache(maxsize=256)
def _splits(total: int, chosen: int) -> tuple[np.ndarray, bool]:
    """Indicator columns of the pull-request side of each split of ``total`` seeds (``chosen`` in it); exact?"""
    count = math.comb(total, chosen)
    if count <= ENUMERATED:
        columns = list(itertools.combinations(range(total), chosen))
        exact = True
    else:
        rng = np.random.default_rng(total * 1000 + chosen)
        columns = [tuple(rng.choice(total, chosen, replace=False)) for _ in range(RANDOM_SPLITS)]
        exact = False
    matrix = np.zeros((total, len(columns)))
    for j, column in enumerate(columns):
        matrix[list(column), j] = 1.0
    return matrix, exact


def permutation_p_values(before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One-sided permutation p-values for a drop and for a rise of the pull request's mean.

    Args:
        before, after: per-seed values (last axis: seeds; leading axes: independent comparisons).

    Ties count against the pull request (a split as extreme as the observed one counts), so
    identical sides give 1, not a small p-value.
    """
    before, after = np.asarray(before, float), np.asarray(after, float)
    values = np.concatenate([before, after], axis=-1)
    matrix, exact = _splits(values.shape[-1], after.shape[-1])
    sums = values @ matrix
    observed = after.sum(-1, keepdims=True)
    tol = 1e-9 * (1.0 + np.abs(observed))
    low = (sums <= observed + tol).sum(-1)
    high = (sums >= observed - tol).sum(-1)
    splits = matrix.shape[1]
    if exact:
        return low / splits, high / splits
    return (low + 1) / (splits + 1), (high + 1) / (splits + 1)


def drop_bounds(
    kb: np.ndarray, nb: np.ndarray, ka: np.ndarray, na: np.ndarray, confidence: float = FUTILITY_CONFIDENCE
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean per-seed success of each side and the upper ``confidence`` bound of the drop (rate points).

    The bound is a pooled two-sample t bound on per-seed rates, its variance floored at
    the binomial variance of a seed at the pooled rate (identical seeds are no evidence
    of zero spread); with one seed a side, the binomial variance alone. A drop is a
    difference of two rates, so it lies in ``[-1, 1]``: the bound is clipped to that
    range (with few seeds and a wide spread the t quantile alone would reach past it,
    a drop of 142 points; clipping changes no verdict, as the margin is at most 1).
    """
    from scipy.special import ndtri, stdtrit

    kb, nb, ka, na = (np.asarray(x, dtype=float) for x in (kb, nb, ka, na))
    mb, ma = kb.shape[-1], ka.shape[-1]
    df = mb + ma - 2
    rb, ra = kb / nb, ka / na
    pooled = (kb.sum(-1) + ka.sum(-1) + 0.5) / (nb.sum(-1) + na.sum(-1) + 1.0)
    floor = pooled * (1.0 - pooled) / ((nb.sum(-1) + na.sum(-1)) / (mb + ma))
    if df >= 1:
        ss = ((rb - rb.mean(-1, keepdims=True)) ** 2).sum(-1) + ((ra - ra.mean(-1, keepdims=True)) ** 2).sum(-1)
        variance = np.maximum(ss / df, floor)
        quantile = float(stdtrit(df, confidence))
    else:
        variance, quantile = floor, float(-ndtri(1.0 - confidence))
    drop = rb.mean(-1) - ra.mean(-1)
    upper = drop + quantile * np.sqrt(variance * (1.0 / mb + 1.0 / ma))
    return rb.mean(-1), ra.mean(-1), np.clip(upper, -1.0, 1.0)


def z_of(p: np.ndarray | float) -> np.ndarray:
    """A one-sided p-value on the z scale, ``-ndtri(p)``: what the design's boundaries are in."""
    from scipy.special import ndtri

    return np.asarray(-ndtri(np.clip(p, 1e-300, 1.0)))


def states(p_drop: np.ndarray, upper: np.ndarray, design: Design) -> np.ndarray:
    """Each comparison's state from its repeated p-value for a drop and its drop's upper bound: the one rule.

    Dropped at or below the design's level; else fine once the upper bound lies below the margin; else open.
    """
    return np.where(
        np.asarray(p_drop) <= design.alpha,
        GateState.DROPPED.value,
        np.where(np.asarray(upper) < design.margin, GateState.FINE.value, GateState.OPEN.value),
    )


@dataclass(frozen=True)
class Look:
    """A comparison after its latest look.

    Attributes:
        state: dropped, fine or open.
        p_drop, p_rise: repeated p-values over the looks so far (for a drop; for a rise, by the
            same design turned round).
        seeds: the pull request's seeds at each look.
        before, after: mean per-seed success, baseline and pull request, at the latest look.
        upper: the upper bound of the drop at the latest look (rate points).
        alpha, margin, baseline_seeds: the design's.
    """

    state: GateState
    p_drop: float
    p_rise: float
    seeds: tuple[int, ...]
    before: float
    after: float
    upper: float
    alpha: float
    margin: float
    baseline_seeds: int

    @property
    def dropped(self) -> bool:
        return self.state is GateState.DROPPED

    @property
    def improved(self) -> bool:
        """A rise by the same design turned round (reported, never failed)."""
        return self.p_rise <= self.alpha

    def describe(self) -> str:
        """One line: the verdict, success before and after, the p-value or the bound, and the seeds it took."""
        seeds = f"{self.seeds[-1]} seeds vs {self.baseline_seeds} in the baseline"
        if len(self.seeds) > 1:
            seeds += f", looks at {', '.join(map(str, self.seeds))}"
        return describe_change(
            self.state,
            self.before,
            self.after,
            p_drop=self.p_drop,
            p_rise=self.p_rise,
            alpha=self.alpha,
            upper=self.upper,
            margin=self.margin,
            sample=seeds,
            most="the most allowed",
        )


def describe_change(
    state: GateState,
    before: float,
    after: float,
    *,
    p_drop: float,
    p_rise: float,
    alpha: float,
    upper: float,
    margin: float,
    sample: str,
    most: str,
) -> str:
    """A comparison's line, for any comparison with a baseline (a spec's seeds, an agent's paired episodes): the
    verdict (dropped; improved, a rise at ``p_rise <= alpha``; unchanged within chance; undecided), success before
    and after, the p-value or the bound, and ``sample``, what it was measured on (``most``: why an undecided one
    stopped there).

    Example:
        >>> describe_change(GateState.FINE, 0.9, 0.85, p_drop=0.9, p_rise=0.8, alpha=0.025, upper=0.12, margin=0.2,
        ...                 sample="20 paired episodes", most="all of them")
        'unchanged within chance: 90% -> 85% (a drop of 12 points at most, under the margin of 20; 20 paired episodes)'
    """
    change = f"{before:.0%} -> {after:.0%}"
    if state is GateState.DROPPED:
        return f"dropped: {change} (p = {p_drop:.2g} <= {alpha:.2g}; {sample})"
    if p_rise <= alpha:
        return f"improved: {change} (p = {p_rise:.2g} <= {alpha:.2g}; {sample})"
    bound = f"a drop of {_points_at_most(upper, margin if state is GateState.FINE else None)} points at most"
    if state is GateState.FINE:
        return f"unchanged within chance: {change} ({bound}, under the margin of {margin * 100:.0f}; {sample})"
    return (
        f"undecided: {change} (p = {p_drop:.2g} > {alpha:.2g}, {bound} is not under the margin of "
        f"{margin * 100:.0f}; {sample}, {most})"
    )


def _points_at_most(upper: float, below: float | None) -> str:
    """A bound on a drop in percentage points, rounded up (a bound stays one), with the fewest decimals that keep it
    under ``below`` where it lies under it (a 0.197 bound under a margin of 0.2 reads 19.7, not 20).

    >>> _points_at_most(0.12, 0.2), _points_at_most(0.197, 0.2), _points_at_most(0.19991, 0.2)
    ('12', '19.7', '19.991')
    >>> _points_at_most(0.3, None)  # not under a margin: whole points
    '30'
    """
    points = max(upper, 0.0) * 100
    for decimals in range(4):
        scale = 10**decimals
        shown = math.ceil(round(points * scale, 9)) / scale
        if below is None or shown < below * 100:
            return f"{shown:.{decimals}f}"
    return f"{points:.4f}"


def compare_seeds(
    before: Sequence[tuple[int, int]],
    after: Sequence[tuple[int, int]],
    design: Design,
    seeds: Sequence[int],
) -> Look:
    """Judge a comparison after looks at ``seeds`` pull-request seeds (``after``'s first ``m`` runs at each look).

    Args:
        before: the baseline's ``(successes, episodes)`` per seed (``design.baseline_seeds`` is taken from it).
        after: the pull request's, in the order they were trained; the latest look sees them all.
        seeds: the seeds at each look so far, increasing, the last ``len(after)``.

    Raises:
        ValueError: a side without runs, or looks that do not end at ``len(after)``.
    """
    if not before or not after:
        raise ValueError(f"both sides need at least one run, got {len(before)} and {len(after)}")
    if not seeds or list(seeds) != sorted(set(seeds)) or seeds[-1] != len(after) or seeds[0] < 1:
        raise ValueError(f"expected increasing looks ending at the {len(after)} runs, got {list(seeds)!r}")
    design = dataclasses.replace(design, baseline_seeds=len(before), ceiling=max(design.ceiling, seeds[-1]))
    kb = np.array([k for k, _ in before], dtype=float)
    nb = np.array([n for _, n in before], dtype=float)
    ka = np.array([k for k, _ in after], dtype=float)
    na = np.array([n for _, n in after], dtype=float)
    fractions = design.fractions(seeds)
    p_drop = p_rise = 1.0
    yb, ya = transformed(kb, nb), transformed(ka, na)
    for look, m in enumerate(seeds):
        low, high = permutation_p_values(yb, ya[:m])
        p_drop = min(p_drop, float(look_levels(z_of(low), fractions, look)))
        p_rise = min(p_rise, float(look_levels(z_of(high), fractions, look)))
    mean_before, mean_after, upper = (float(x) for x in drop_bounds(kb, nb, ka, na))
    return Look(
        state=GateState(str(states(np.array(p_drop), np.array(upper), design)[()])),
        p_drop=p_drop,
        p_rise=p_rise,
        seeds=tuple(seeds),
        before=mean_before,
        after=mean_after,
        upper=upper,
        alpha=design.alpha,
        margin=design.margin,
        baseline_seeds=len(before),
    )
