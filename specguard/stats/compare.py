"""Regression gating: stored baselines of per-seed success, and whether a goal dropped.

``--goal-specs-save NAME`` stores, per (spec, goal), every run's successes and
episodes in ``<dir>/NAME.json``; ``--goal-specs-compare NAME`` compares a new
run with it. A goal *dropped* when its success fell by more than chance
allows, by a one-sided two-sample test at level ``alpha`` (default 0.05):

* across seeds, Welch's t-test on the per-seed success rates, when both sides
  have at least 2 seeds and the rates vary;
* otherwise (one seed a side, or every seed alike), Fisher's exact test on the
  pooled episode counts, which treats episodes as independent and so is the
  less cautious of the two.

It *improved* when the same test finds a rise.

Safety rates (keys ``path:name``, :mod:`specguard.tree.keys`) are stored and
compared exactly as goals are, under ``group::path:name``. A goal or safety
rate that a baseline has no figures for (a baseline saved before it was
asserted, or before safety rates were measured) is not compared:
:func:`specguard.pytest_plugin.gate.check_item` notes that instead of failing.

Each stored goal also records its spec's identity
(:attr:`specguard.engine.fingerprint.SpecFingerprint.spec_key`, the key the cache and
the plugin's shared results use), so a comparison says whether the spec
itself changed since the baseline or only its result did.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from specguard.error import SpecError
from specguard.utils.files import write_atomic

__all__ = ["Baseline", "BaselineError", "Comparison", "compare", "load_baseline", "save_baseline"]

FORMAT = 2
FORMATS = (1, 2)  # format 1 stored runs only


class BaselineError(SpecError):
    """A stored baseline cannot be read."""


@dataclass(frozen=True)
class Comparison:
    """A goal's success now against its stored baseline."""

    before: float
    after: float
    p_drop: float
    p_rise: float
    method: str
    alpha: float = 0.05

    @property
    def dropped(self) -> bool:
        return self.p_drop < self.alpha

    @property
    def improved(self) -> bool:
        return self.p_rise < self.alpha

    def describe(self) -> str:
        change = "dropped" if self.dropped else "improved" if self.improved else "unchanged within chance"
        p = self.p_drop if self.dropped else self.p_rise if self.improved else min(self.p_drop, self.p_rise)
        return f"{change}: {self.before:.0%} -> {self.after:.0%} ({self.method}, p = {p:.3g})"


Runs = Sequence[tuple[int, int]]  # (successes, episodes) per seed


@dataclass(frozen=True)
class Baseline:
    """A stored baseline: per goal key, every run's counts, and the spec identity they came from."""

    runs: dict[str, list[tuple[int, int]]]
    specs: dict[str, str]

    def spec_changed(self, key: str, spec_key: str | None) -> bool:
        """Whether the goal's spec differs from the one the baseline measured (False when unknown)."""
        stored = self.specs.get(key)
        return stored is not None and spec_key is not None and stored != spec_key


def compare(before: Runs, after: Runs, alpha: float = 0.05) -> Comparison:
    """Compare per-seed ``(successes, episodes)`` of a baseline with a new run."""
    from scipy.stats import fisher_exact, ttest_ind

    if not before or not after:
        raise ValueError("both sides need at least one run")
    rates_b = [k / n for k, n in before]
    rates_a = [k / n for k, n in after]
    kb, nb = sum(k for k, _ in before), sum(n for _, n in before)
    ka, na = sum(k for k, _ in after), sum(n for _, n in after)
    varies = len(set(rates_b)) > 1 or len(set(rates_a)) > 1
    if len(before) >= 2 and len(after) >= 2 and varies:
        with warnings.catch_warnings():  # identical samples: scipy warns, the p-value (0.5) is right
            warnings.simplefilter("ignore", RuntimeWarning)
            p_drop = float(ttest_ind(rates_a, rates_b, equal_var=False, alternative="less").pvalue)
            p_rise = float(ttest_ind(rates_a, rates_b, equal_var=False, alternative="greater").pvalue)
        method = f"Welch t-test over {len(before)} vs {len(after)} seeds"
    else:
        table = [[ka, na - ka], [kb, nb - kb]]
        p_drop = float(fisher_exact(table, alternative="less").pvalue)
        p_rise = float(fisher_exact(table, alternative="greater").pvalue)
        method = f"Fisher exact test over {nb} vs {na} episodes"
    return Comparison(before=kb / nb, after=ka / na, p_drop=p_drop, p_rise=p_rise, method=method, alpha=alpha)


def save_baseline(path: Path, rows: Mapping[str, Runs], specs: Mapping[str, str] | None = None) -> None:
    """Write ``{key: [(successes, episodes), ...]}`` (and each key's spec identity) atomically to ``path``."""
    specs = specs or {}
    goals = {k: {"runs": [list(r) for r in runs], "spec": specs.get(k)} for k, runs in rows.items()}
    data = {"format": FORMAT, "goals": goals}
    write_atomic(path, json.dumps(data, indent=1, sort_keys=True))


def load_baseline(path: Path) -> Baseline:
    """Read a baseline written by :func:`save_baseline`.

    Raises:
        BaselineError: the file is missing or corrupt; the message names it.
    """
    if not path.is_file():
        raise BaselineError(f"baseline {str(path)!r} does not exist; store one first with --goal-specs-save")
    try:
        data: Any = json.loads(path.read_text())
        if data.get("format") not in FORMATS:
            raise ValueError(f"unknown format {data.get('format')!r}")
        runs, specs = {}, {}
        for key, entry in data["goals"].items():
            if data["format"] == 1:
                entry = {"runs": entry, "spec": None}
            if not isinstance(entry, dict):
                raise ValueError(f"bad entry for {key!r}: {entry!r}")
            parsed = [(int(k), int(n)) for k, n in entry["runs"]]
            if not parsed or any(n < 1 or not 0 <= k <= n for k, n in parsed):
                raise ValueError(f"bad counts for {key!r}: {entry['runs']!r}")
            runs[str(key)] = parsed
            if entry.get("spec") is not None:
                if not isinstance(entry["spec"], str):
                    raise ValueError(f"bad spec identity for {key!r}: {entry['spec']!r}")
                specs[str(key)] = entry["spec"]
        return Baseline(runs, specs)
    except (ValueError, TypeError, KeyError, AttributeError) as e:
        raise BaselineError(f"baseline {str(path)!r} is corrupt ({e}); delete it and save a new one") from e
