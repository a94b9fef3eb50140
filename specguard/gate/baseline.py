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
:func:`specguard.pytest_plugin.judge.check_item` notes that instead of failing.

Each stored goal also records its spec's identity
(:attr:`specguard.cache.fingerprint.SpecFingerprint.spec_key`, the key the cache and
the plugin's shared results use) and its seeds, so a comparison says whether
the spec itself changed since the baseline or only its result did, and a spec
whose identity and runs are the baseline's own is not compared at all
(:meth:`Baseline.same_runs`).

A save merges by spec, under a lock beside the file (``NAME.json.lock``): it
reads the stored baseline, replaces the goals of the specs the session ran,
keeps every other spec's, and says which (:class:`Saved`). So a session that
ran a subset (``-k``, one file) does not erase the rest, and two sessions
saving at once both land. A goal of a spec the session ran but did not check
(``-k`` on one goal) is kept while its spec is unchanged, and dropped, by name,
once the spec it was measured on is gone.

An agent judged by :func:`~specguard.engine.check_agent.check_agent` (a goal
spec returning an ``sg.AgentCheck``) is stored whole, per test, as an
:class:`AgentEntry` (format 4 added them; older baselines load with none): its
identity and name, its spec's key, the evaluation's settings, and per
evaluation episode its env seed and each asserted goal's and safety rate's
outcome, for a paired comparison (:mod:`specguard.gate.saved_agent`). A test
saved as an agent replaces the goals a trained spec stored under its id, and the
other way round.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from specguard.error import BaselineError
from specguard.utils.atomic import write_atomic
from specguard.utils.text import value_text
from specguard.validation import is_natural

__all__ = ["AgentEntry", "Baseline", "BaselineError", "Saved", "load_baseline", "save_baseline", "spec_of_key"]

FORMAT = 4
FORMATS = (1, 2, 3, 4)  # format 1 stored runs only; 2 added the spec identity; 3 the seeds; 4 the agents
LOCK_TIMEOUT = 60.0  # seconds a save waits for another one to the same baseline
LISTED = 8  # specs named at most per kind in a save's line


Runs = Sequence[tuple[int, int]]  # (successes, episodes) per seed

SETTINGS = ("observation", "wrap", "seed_base")
"""An agent's evaluation settings a saved entry records: what it saw, its ``wrap``'s digest, its first env seed."""


@dataclass(frozen=True)
class AgentEntry:
    """An agent's saved evaluation episodes for one goal-spec test: what a paired comparison needs.

    Attributes:
        agent: the agent's identity (:attr:`specguard.agents.agent.Agent.identity`); name: its name.
        spec: the key of the spec it was judged against
            (:attr:`~specguard.cache.fingerprint.SpecFingerprint.spec_key`).
        settings: per name of :data:`SETTINGS`, its value (``wrap``: a digest, or None).
        seeds: each episode's env seed, in order.
        outcomes: per asserted goal path and safety key, each episode's outcome (1: met or safe, 0: not).

    Example:
        >>> entry = AgentEntry("ab12", "lean", "cd34", {"observation": "env", "wrap": None, "seed_base": 7},
        ...                    [7, 8], {"up": [1, 0]})
        >>> AgentEntry.from_dict("t.py::test", entry.to_dict()) == entry
        True
    """

    agent: str
    name: str
    spec: str
    settings: dict[str, Any]
    seeds: list[int]
    outcomes: dict[str, list[int]]

    def to_dict(self) -> dict[str, Any]:
        """The stored form: per episode, its env seed and each key's outcome."""
        episodes = [
            {"seed": seed, "outcomes": {key: values[i] for key, values in self.outcomes.items()}}
            for i, seed in enumerate(self.seeds)
        ]
        return {
            "agent": self.agent,
            "name": self.name,
            "spec": self.spec,
            "settings": self.settings,
            "episodes": episodes,
        }

    @classmethod
    def from_dict(cls, group: str, data: Any) -> AgentEntry:
        """An entry read back from its stored form.

        Raises:
            ValueError: naming the test and what is wrong.
        """
        if not isinstance(data, dict) or not all(isinstance(data.get(k), str) for k in ("agent", "name", "spec")):
            raise ValueError(f"bad agent entry for {value_text(group)}: {value_text(data)}")
        settings, episodes = data.get("settings"), data.get("episodes")
        if not isinstance(settings, dict) or sorted(settings) != sorted(SETTINGS):
            raise ValueError(f"bad settings for agent {value_text(group)}: {value_text(settings)}")
        if not isinstance(episodes, list) or not episodes or not all(isinstance(e, dict) for e in episodes):
            raise ValueError(f"bad episodes for agent {value_text(group)}: {value_text(episodes)}")
        seeds = _seeds(group, [e.get("seed") for e in episodes], len(episodes), per="episode")
        keys = episodes[0].get("outcomes")
        if not isinstance(keys, dict) or not keys or not all(_outcomes(e.get("outcomes"), keys) for e in episodes):
            raise ValueError(
                f"bad outcomes for agent {value_text(group)}: expected 0 or 1 for the same keys in every episode"
            )
        outcomes = {str(key): [int(e["outcomes"][key]) for e in episodes] for key in keys}
        return cls(data["agent"], data["name"], data["spec"], dict(settings), seeds, outcomes)


def _outcomes(stored: Any, keys: dict[str, Any]) -> bool:
    """Whether one stored episode's outcomes are 0 or 1 for exactly ``keys``."""
    return (
        isinstance(stored, dict)
        and sorted(stored) == sorted(keys)
        and all(type(v) is int and v in (0, 1) for v in stored.values())
    )


@dataclass(frozen=True)
class Baseline:
    """A stored baseline: per goal key, every run's counts, the spec identity they came from, and their seeds;
    per agent test, its :class:`AgentEntry`."""

    runs: dict[str, list[tuple[int, int]]]
    specs: dict[str, str]
    seeds: dict[str, list[int]] = field(default_factory=dict)
    agents: dict[str, AgentEntry] = field(default_factory=dict)

    @property
    def family(self) -> int:
        """The comparisons it holds (at least 1): its goals and safety rates, and every agent's asserted keys; a
        comparison with it is judged at Holm's first step over them."""
        return max(1, len(self.runs) + sum(len(entry.outcomes) for entry in self.agents.values()))

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


def spec_of_key(key: str) -> str:
    """The spec (the plugin's group) of a stored key ``group::goal``: goal keys never hold ``::``.

    Example:
        >>> spec_of_key("specs.py::test_swing[fast]::pendulum/up:spin")
        'specs.py::test_swing[fast]'
    """
    return key.rsplit("::", 1)[0]


@dataclass(frozen=True)
class Saved:
    """What a save did to the stored baseline: specs replaced, added and kept, and goals dropped.

    ``dropped``: goals of a spec the session ran but did not check, stored from
    an earlier version of that spec (another identity).
    """

    replaced: list[str]
    added: list[str]
    kept: list[str]
    dropped: list[str] = field(default_factory=list)

    def text(self) -> str:
        """One line: ``replaced 1 spec (b.py::t), added none, kept 2 others``."""
        parts = [f"replaced {_names(self.replaced, 'spec')}", f"added {_names(self.added, 'spec')}"]
        parts.append(f"kept {len(self.kept)} other{'s' if len(self.kept) != 1 else ''}" if self.kept else "kept none")
        if self.dropped:
            parts.append(f"dropped {_names(self.dropped, 'goal')} of an earlier version of its spec")
        return ", ".join(parts)


def _names(names: Sequence[str], noun: str) -> str:
    """``2 specs (a, b)``; ``none``; at most :data:`LISTED` named."""
    if not names:
        return "none"
    shown = ", ".join(names[:LISTED]) + (f", and {len(names) - LISTED} more" if len(names) > LISTED else "")
    return f"{len(names)} {noun}{'s' if len(names) != 1 else ''} ({shown})"


def _entries(
    rows: Mapping[str, Runs], specs: Mapping[str, str], seeds: Mapping[str, Sequence[int]]
) -> dict[str, dict[str, Any]]:
    """The stored form of each goal: its runs, its spec identity (or None), and its seeds when known."""
    goals: dict[str, Any] = {}
    for key, runs in rows.items():
        goals[key] = {"runs": [list(r) for r in runs], "spec": specs.get(key)}
        if key in seeds:
            if len(seeds[key]) != len(runs):
                raise ValueError(f"{key!r}: {len(seeds[key])} seeds for {len(runs)} runs")
            goals[key]["seeds"] = [int(s) for s in seeds[key]]
    return goals


def _stored(baseline: Baseline) -> dict[str, dict[str, Any]]:
    """A loaded baseline back in its stored form."""
    return _entries(baseline.runs, baseline.specs, baseline.seeds)


def _merge(
    old: dict[str, dict[str, Any]],
    new: dict[str, dict[str, Any]],
    old_agents: Mapping[str, AgentEntry],
    new_agents: Mapping[str, AgentEntry],
) -> tuple[dict[str, Any], dict[str, AgentEntry], Saved]:
    """``old`` (goals, and agents by test) with the specs of ``new`` replaced by theirs, and what that did.

    A goal of a replaced spec that ``new`` lacks stays if it was measured on the
    spec ``new`` stores (the same identity, or none known), else it is dropped. A
    test saved as an agent replaces the goals stored under its id, and a spec's
    goals replace the agent stored under its id.
    """
    ran = {spec_of_key(key) for key in new} | set(new_agents)
    identity = {spec_of_key(key): entry["spec"] for key, entry in new.items() if entry["spec"] is not None}
    merged, dropped = dict(new), []
    for key, entry in old.items():
        spec = spec_of_key(key)
        if key in new or spec in new_agents:
            continue
        if spec in ran and entry["spec"] is not None and identity.get(spec) not in (None, entry["spec"]):
            dropped.append(key)
        else:
            merged[key] = entry
    agents = {group: entry for group, entry in old_agents.items() if group not in ran} | dict(new_agents)
    before = {spec_of_key(key) for key in old} | set(old_agents)
    saved = Saved(
        replaced=sorted(ran & before), added=sorted(ran - before), kept=sorted(before - ran), dropped=sorted(dropped)
    )
    return dict(sorted(merged.items())), dict(sorted(agents.items())), saved


def save_baseline(
    path: Path,
    rows: Mapping[str, Runs],
    specs: Mapping[str, str] | None = None,
    seeds: Mapping[str, Sequence[int]] | None = None,
    agents: Mapping[str, AgentEntry] | None = None,
) -> Saved:
    """Merge ``{key: [(successes, episodes), ...]}`` (each key's spec identity and seeds, when known) and
    ``agents`` (per test, its agent's entry) into the baseline at ``path`` by spec, under its lock, and write it
    atomically.

    Returns:
        What the save replaced, added, kept and dropped, per spec.

    Raises:
        BaselineError: the stored baseline is corrupt (it is left as it is), or another save held its lock
            for :data:`LOCK_TIMEOUT` seconds.
        OSError: the file cannot be written.
    """
    from filelock import FileLock, Timeout

    new = _entries(rows, specs or {}, seeds or {})
    path.parent.mkdir(parents=True, exist_ok=True)
    lock = FileLock(str(path.with_name(f"{path.name}.lock")), timeout=LOCK_TIMEOUT, thread_local=False)
    try:
        with lock:
            stored = load_baseline(path) if path.exists() else Baseline({}, {})
            goals, kept, saved = _merge(_stored(stored), new, stored.agents, agents or {})
            data = {"format": FORMAT, "goals": goals, "agents": {group: e.to_dict() for group, e in kept.items()}}
            write_atomic(path, json.dumps(data, indent=1, sort_keys=True))
    except Timeout:
        raise BaselineError(
            f"baseline {str(path)!r}: another save has held its lock {lock.lock_file!r} for over "
            f"{LOCK_TIMEOUT:g} s; nothing was saved"
        ) from None
    return saved


def _seeds(key: str, stored: Any, runs: int, per: str = "run") -> list[int]:
    """A goal's stored seeds, one per run (an agent's: one per episode, ``per="episode"``), distinct, each an
    integer ``>= 0`` (a seed, as ``is_natural`` reads it).

    Raises:
        ValueError: naming the goal and the seeds stored.
    """
    if not (isinstance(stored, list) and len(stored) == runs and all(is_natural(x) for x in stored)):
        raise ValueError(
            f"bad seeds for {value_text(key)}: expected {runs} integers >= 0, one per {per}, got {value_text(stored)}"
        )
    if len(set(stored)) != len(stored):
        raise ValueError(f"bad seeds for {value_text(key)}: expected distinct seeds, got {value_text(stored)}")
    return [int(x) for x in stored]


def load_baseline(path: Path) -> Baseline:
    """Read a baseline written by :func:`save_baseline`.

    Raises:
        BaselineError: the file is missing, a directory or corrupt; the message names it.
    """
    if path.is_dir():
        raise BaselineError(
            f"baseline {str(path)!r} is a directory, not a baseline file; move it away or name another baseline"
        )
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
                raise ValueError(f"bad entry for {value_text(key)}: {value_text(entry)}")
            parsed = [(int(k), int(n)) for k, n in entry["runs"]]
            if not parsed or any(n < 1 or not 0 <= k <= n for k, n in parsed):
                raise ValueError(f"bad counts for {value_text(key)}: {value_text(entry['runs'])}")
            runs[str(key)] = parsed
            if entry.get("spec") is not None:
                if not isinstance(entry["spec"], str):
                    raise ValueError(f"bad spec identity for {value_text(key)}: {value_text(entry['spec'])}")
                specs[str(key)] = entry["spec"]
            if entry.get("seeds") is not None:
                seeds[str(key)] = _seeds(key, entry["seeds"], len(parsed))
        agents = {str(group): AgentEntry.from_dict(group, e) for group, e in data.get("agents", {}).items()}
        return Baseline(runs, specs, seeds, agents)
    except (ValueError, TypeError, KeyError, AttributeError, RecursionError) as e:  # RecursionError: JSON nested deep
        raise BaselineError(f"baseline {str(path)!r} is corrupt ({e}); delete it and save a new one") from e
