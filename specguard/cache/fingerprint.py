"""Exact fingerprints of specs: the one identity the run cache, shared results and baselines key on.

A cached verdict is only as good as its key: a key that misses a change
reuses an old run for a changed reward. So the key is built from what a spec
*computes*, exactly:

* numbers in full precision (``float.hex``), numpy arrays by dtype, shape and
  content, containers by their items (dicts and sets sorted, so hash seeds do
  not matter);
* user functions by their bytecode (not their source text: formatting,
  comments and blank lines do not change it), constants, defaults, closure
  cells, and every module-level name they reference, followed recursively
  (helper functions, constants, arrays, classes, names read from a user module);
* installed libraries by name and distribution version (code under the
  interpreter's ``stdlib``/``site-packages`` directories); specguard by its
  version and a digest of its own source files;
* any other object by what pickle would store of it (``__reduce_ex__``); an
  object pickle cannot store is a :class:`~specguard.error.FingerprintError`
  naming where it was found. No ``repr``, memory address or ``id`` enters a key.

The static part cannot see code it cannot reach by name (an env class
instantiated from a string id, a C extension's internals), so a **behavioural
probe** adds a short fixed-seed rollout of the constructed env (for a baseline
spec, the initial env): seeded random actions for :data:`PROBE_STEPS` steps,
whose observations, rewards, reward terms, goals and terminations are hashed.
It cannot see behaviour off those states (say, a branch only near the goal),
nor anything in training beyond the library versions.

Example:
    >>> import specguard as sg
    >>> pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    >>> upright = sg.Goal("upright", x=(0.966, 1.0), y=(-0.259, 0.259), omega=(-0.25, 0.25))
    >>> spec = sg.Spec(pendulum, upright, budget=sg.Budget(timesteps=1000))
    >>> fp = fingerprint_spec(spec)
    >>> fp.run_key(0) != fp.run_key(1) and len(fp.spec_key) == 64
    True
"""

from __future__ import annotations

import dataclasses
import hashlib
import warnings
from typing import Any

from specguard.cache.canonical import digest
from specguard.cache.probe import probe
from specguard.cache.versions import torch_capability, versions
from specguard.utils.numerics import numerics_key

__all__ = ["SpecFingerprint", "fingerprint_spec"]

# Spec fields that change how many runs are trained or how they are counted, not what one run does:
# they are part of the spec's identity (shared results, baselines) but not of a run's cache key.
_SPEC_ONLY_FIELDS = frozenset({"quorum", "undecided", "name", "xfail"})
# Spec fields that change neither a run nor a verdict: the falsifier's default start space (where runs write logs is
# the trainer's, and left out of its identity).
_NOT_IDENTITY_FIELDS = frozenset({"starts"})
_BUDGET_SPEC_ONLY_FIELDS = frozenset({"min_seeds", "max_seeds"})


# -- a spec's identity ---------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class SpecFingerprint:
    """A spec's identity: the key of its shared result and of each of its runs.

    Attributes:
        spec_key: every field that can change the spec's verdict (seeds,
            quorum and ``undecided`` included), the probe and the versions.
        run_base: what decides one run (the spec less the fields that only
            count runs), the probe and the versions; :meth:`run_key` adds the seed.
        reproducible: the probe gave the same digest twice; an env that does
            not is never cached (its runs could not be reproduced from a key).
    """

    spec_key: str
    run_base: str
    reproducible: bool = True

    def run_key(self, seed: int) -> str:
        """The cache key of run ``seed``."""
        return hashlib.sha256(f"{self.run_base}:{int(seed)}".encode()).hexdigest()


def _fields(obj: Any, exclude: frozenset[str]) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.name not in exclude}


def _trained_fields(spec: Any, fields: dict[str, Any]) -> dict[str, Any]:
    """``fields`` with the trainer's own identity in place of the trainer (:meth:`Trainer.identity
    <specguard.spec.trainers.Trainer.identity>`: an SB3 trainer's algorithm, hyperparameters, ...; a training loop's
    code, as the tree's functions), the observation only where it is not the default, and the numerics.

    A run of the default observation keeps the key it had before specs had them.
    """
    out = dict(fields)
    trainer = out.pop("trainer")
    out.update(trainer.identity(observation=spec.observation))
    if out["observation"] == "features":
        del out["observation"]
    out["numerics"] = numerics_key(spec.numerics, torch_capability)  # a native run is this CPU's: its key names it
    return out


def _compute(spec: Any) -> SpecFingerprint:
    where = f"Spec {spec.label!r}"
    full = _trained_fields(spec, _fields(spec, _NOT_IDENTITY_FIELDS))
    run = _trained_fields(spec, _fields(spec, _SPEC_ONLY_FIELDS | _NOT_IDENTITY_FIELDS))
    run["budget"] = _fields(spec.budget, _BUDGET_SPEC_ONLY_FIELDS)
    build = spec.env_factory()  # a fresh env per probe, on one compiled tree
    first, second = probe(spec, build=build), probe(spec, build=build)
    if first != second:
        warnings.warn(
            f"specguard: {where}: the env does not repeat a fixed-seed rollout (it draws randomness its seed does "
            "not control), so its runs cannot be reproduced from a key and are not cached",
            stacklevel=3,
        )
    common = {"probe": first, "versions": versions()}
    return SpecFingerprint(
        spec_key=digest({"spec": full, **common}, where),
        run_base=digest({"run": run, **common}, where),
        reproducible=first == second,
    )


_MEMO: dict[int, tuple[Any, SpecFingerprint]] = {}
_MEMO_SIZE = 128


def fingerprint_spec(spec: Any) -> SpecFingerprint:
    """The fingerprint of ``spec`` (computed once per spec object and process).

    Raises:
        FingerprintError: a value in the spec cannot be fingerprinted exactly.
        SpecError: the env failed during the behavioural probe.
    """
    hit = _MEMO.get(id(spec))
    if hit is not None and hit[0] is spec:
        return hit[1]
    fp = _compute(spec)
    if len(_MEMO) >= _MEMO_SIZE:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[id(spec)] = (spec, fp)  # holding the spec keeps its id from being reused
    return fp
