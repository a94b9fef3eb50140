"""Stored baselines: per goal, each seed's successes and episodes, and the identity of the spec they came from.

``--goal-specs-save NAME`` stores, per (spec, goal), every seed's successes and
episodes in ``<dir>/NAME.json``: the spec's own seeds and more, up to
:data:`specguard.stats.sequential.DEFAULT_COMPARE_SEEDS` (8) or the spec's
``max_seeds``, so that a pull request's few seeds are compared with a
well-measured baseline. ``--goal-specs-compare NAME`` compares a new run with
it, by the sequential test of :mod:`specguard.stats.sequential` (extra seeds
only while a comparison is open) under the family-wise procedure of
:mod:`specguard.stats.family`.

Safety rates (keys ``path:name``, :mod:`specguard.tree.keys`) are stored and
compared exactly as goals are, under ``group::path:name``. A goal or safety
rate that a baseline has no figures for (a baseline saved before it was
asserted, or before safety rates were measured) is not compared:
:func:`specguard.pytest_plugin.gate.check_item` notes that instead of failing.

Each stored goal also records its spec's identity
(:attr:`specguard.cache.fingerprint.SpecFingerprint.spec_key`, the key the cache and
the plugin's shared results use) and its seeds, so a comparison says whether
the spec itself changed since the baseline or only its result did, and a spec
whose identity and runs are the baseline's own is not compared at all
(:meth:`Baseline.same_runs`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from specguard.error import BaselineError
from specguard.utils.files import write_atomic

__all__ = ["Baseline", "BaselineError", "load_baseline", "save_baseline"]

FORMAT = 3
FORMATS = (1, 2, 3)  # format 1 stored runs only; 2 added the spec identity; 3 the seeds


Runs = Sequence[tuple[int, int]]  # (successes, episodes) per seed


@dataclass(frozen=True)
class Baseline:
    """A stored baseline: per goal key, every run's counts, the spec identity they came from, and their seeds."""

    runs: dict[str, list[tuple[int, int]]]
    specs: dict[str, str]
    seeds: dict[str, list[int]] = field(default_factory=dict)

    def spec_changed(self, key: str, spec_key: str | None) -> bool:
        """Whether the goal's spec differs from the one the baseline measured (False when unknown)."""
        stored = self.specs.get(key)
        return stored is not None and spec_key is not None and stored != spec_key

    def same_runs(self, key: str, spec_key: str | None, runs: Sequence[tuple[int, int, int]]) -> bool:
        """Whether ``runs`` (seed, successes, episodes) are the baseline's own: the same spec, seed for seed.

        A pull request that leaves a spec alone gets its runs from the cache the
        baseline filled; comparing them with themselves would test nothing.
        """
        if not runs or spec_key is None or self.specs.get(key) != spec_key or key not in self.seeds:
            return False
        stored = {seed: tuple(run) for seed, run in zip(self.seeds[key], self.runs[key])}
        return all(stored.get(seed) == (k, n) for seed, k, n in runs)


def save_baseline(
    path: Path,
    rows: Mapping[str, Runs],
    specs: Mapping[str, str] | None = None,
    seeds: Mapping[str, Sequence[int]] | None = None,
) -> None:
    """Write ``{key: [(successes, episodes), ...]}`` (each key's spec identity and seeds, when known) atomically."""
    specs, seeds = specs or {}, seeds or {}
    goals: dict[str, Any] = {}
    for key, runs in rows.items():
        goals[key] = {"runs": [list(r) for r in runs], "spec": specs.get(key)}
        if key in seeds:
            if len(seeds[key]) != len(runs):
                raise ValueError(f"{key!r}: {len(seeds[key])} seeds for {len(runs)} runs")
            goals[key]["seeds"] = [int(s) for s in seeds[key]]
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
        runs, specs, seeds = {}, {}, {}
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
            if entry.get("seeds") is not None:
                stored = entry["seeds"]
                if not isinstance(stored, list) or len(stored) != len(parsed) or len(set(stored)) != len(stored):
                    raise ValueError(f"bad seeds for {key!r}: {stored!r}")
                seeds[str(key)] = [int(x) for x in stored]
        return Baseline(runs, specs, seeds)
    except (ValueError, TypeError, KeyError, AttributeError) as e:
        raise BaselineError(f"baseline {str(path)!r} is corrupt ({e}); delete it and save a new one") from e
