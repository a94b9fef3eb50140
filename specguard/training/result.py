"""What one run measured (:class:`RunResult`), as plain data that is checked wherever it comes back.

A run's result crosses two trust boundaries as plain data: back from a worker
process or cluster worker, and back from the cache. Both read it through
:meth:`RunResult.from_dict`, which checks every field.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Collection
from dataclasses import asdict, dataclass, field
from typing import Any

__all__ = ["RunResult", "check_run_result"]


@dataclass
class RunResult:
    """What one run measured; plain data (``to_dict`` is JSON-serialisable).

    Attributes:
        spec: the spec's label.
        seed: the training seed.
        timesteps: environment steps actually trained.
        episodes: evaluation episodes.
        successes: per node path, evaluation episodes whose last state lies in the goal;
            then per safety key (``path:name``), evaluation episodes without a violation.
        train_seconds: wall-clock training time.
        hit_wall_clock: training hit the budget's wall-clock cap.
        curve: success per goal (and safety rate per safety key) over training
            episodes (stochastic policy),
            ``[{"timesteps": t, "episodes": n, "success": {key: rate}}, ...]``;
            a point where the policy was evaluated (an interim checkpoint, or
            the end) also has ``"evaluation": {key: rate}`` and
            ``"evaluation_episodes"``.
        met_early: every threshold was met at an interim checkpoint, so
            training stopped there (``timesteps`` is that step) and that
            checkpoint's evaluation is the run's result (:mod:`specguard.stats.anytime`).
        weights: per node with ``weights="auto"``, the adapted weights in
            force when training ended (:mod:`specguard.training.auto_weights`); each
            curve point also has the ones in force then, under ``"weights"``.
            Empty when no node adapts its weights.
        started_in_goal: of the ``episodes``, those whose first state (at reset) was
            already in the root goal: met before the policy acted (the root goal
            judged on sampled starts before training, :mod:`specguard.construction.preflight`).
        terminated: of the ``episodes``, those that ended by termination rather than truncation:
            where the root goal holds until the end, episodes the env ended before their horizon
            (a fall, a crash; or a constraint's budget spent), which an ``Always`` goal does not
            keep unless ``until="termination"`` (docs/semantics.md, "Goals that hold until the end").
        capped: of the ``episodes``, those cut at specguard's step cap, the end of an episode whose env
            declares no episode limit (:mod:`specguard.construction.cap`).
        stop_reason: why training stopped before its budget when one of the spec's own callbacks
            (``Spec(callbacks=...)``) stopped it, as every door says it: ``"stopped by <callback> at <steps> of
            <budget> steps"`` (and why, when its ``_on_step`` returned None); ``None`` when none did. A stored
            run without it (written before it was recorded) reads as ``None``.
        numerics: what the run computed with, as its worker held it (:func:`specguard.utils.numerics.hold_numerics`):
            ``"portable"``, or ``"native (AVX512)"`` with the vector kernels torch picked; ``None`` for a run stored
            before it was recorded.
        weights_digest: the SHA-256 hex digest of the policy judged (:func:`specguard.cache.weights.weights_digest`:
            an SB3 model's policy's parameters in ``state_dict`` order, with the ``VecNormalize`` statistics it
            reads; a trainer's agent's torch parameters, else its canonical form), computed in the worker once that
            policy is final: two machines tell whether they judged the same weights without sharing a file. It is
            :attr:`Agent.identity <specguard.agents.agent.Agent.identity>` of that model in memory; for an agent
            trained elsewhere (:func:`~specguard.engine.check_agent.check_agent`), the agent's identity. ``None``:
            the agent cannot be digested, or a stored run written before it was recorded.
        looks: what each evaluation of the run saw, episode by episode, in order (its interim looks, then its final
            evaluation unless a look met every threshold): ``{"timesteps": t, "features": [[f, ...], ...], "held":
            {key: "1011..."}}``, the features of each episode's first state (6 significant digits) and, per goal and
            safety key, whether the episode met it (``"1"``) or not. The data a falsifier's failure predictor
            learns from (earlier checkpoints are less robust agents of the same training). Empty for a run stored
            before it was recorded, and for an agent trained elsewhere.
    """

    spec: str
    seed: int
    timesteps: int
    episodes: int
    successes: dict[str, int]
    train_seconds: float
    hit_wall_clock: bool = False
    curve: list[dict[str, Any]] = field(default_factory=list)
    met_early: bool = False
    weights: dict[str, list[float]] = field(default_factory=dict)
    started_in_goal: int = 0
    terminated: int = 0
    capped: int = 0
    stop_reason: str | None = None
    numerics: str | None = None
    weights_digest: str | None = None
    looks: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Any, *, seed: int, paths: Collection[str]) -> RunResult:
        """The run in ``data`` (as :meth:`to_dict` wrote it), after every check of :func:`check_run_result`.

        Raises:
            ValueError: the first check that failed, in words.
        """
        if isinstance(data, dict):
            data = {**_ADDED_LATER, "looks": [], **data}  # a run stored before a field was recorded: its default
        check_run_result(data, seed, paths)
        return cls(**data)


# fields a stored run may lack, with the value it reads as
_ADDED_LATER: dict[str, Any] = {"stop_reason": None, "numerics": None, "weights_digest": None}


_HEX_DIGEST = re.compile("[0-9a-f]{64}")


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def check_run_result(result: Any, seed: int, paths: Collection[str]) -> None:
    """Raise ``ValueError`` naming the first way ``result`` is not a :class:`RunResult` of ``seed`` for ``paths``."""
    if not isinstance(result, dict):
        raise ValueError("result is not an object")
    expected = {f.name for f in dataclasses.fields(RunResult)}
    if set(result) != expected:
        raise ValueError(f"result fields {sorted(result)} are not {sorted(expected)}")
    if result["seed"] != seed or not _is_int(result["seed"]):
        raise ValueError(f"seed {result['seed']!r} is not {seed}")
    if not isinstance(result["spec"], str):
        raise ValueError("spec label is not a string")
    if not _is_int(result["timesteps"]) or result["timesteps"] < 0:
        raise ValueError(f"timesteps {result['timesteps']!r} is not an integer >= 0")
    episodes = result["episodes"]
    if not _is_int(episodes) or episodes < 1:
        raise ValueError(f"episodes {episodes!r} is not an integer >= 1")
    for name in ("started_in_goal", "terminated", "capped"):
        count = result[name]
        if not _is_int(count) or not 0 <= count <= episodes:
            raise ValueError(f"{name} {count!r} is not an integer in [0, episodes={episodes}]")
    weights = result["weights"]
    if not isinstance(weights, dict) or not all(
        isinstance(ws, list) and all(isinstance(w, float) and math.isfinite(w) for w in ws) for ws in weights.values()
    ):
        raise ValueError("weights is not an object of lists of finite numbers")
    successes = result["successes"]
    if not isinstance(successes, dict):
        raise ValueError("successes is not an object")
    missing, extra = sorted(set(paths) - set(successes)), sorted(set(successes) - set(paths))
    if missing or extra:  # e.g. an entry stored before safety rates were measured
        parts = (("missing", missing), ("unexpected", extra))
        diff = "; ".join(f"{what} {', '.join(map(repr, keys))}" for what, keys in parts if keys)
        raise ValueError(f"successes do not list exactly the tree's goals and safety rates ({diff})")
    for path, k in successes.items():
        if not _is_int(k) or not 0 <= k <= episodes:
            raise ValueError(f"successes[{path!r}] = {k!r} is not an integer in [0, episodes={episodes}]")
    if not isinstance(result["train_seconds"], (int, float)) or isinstance(result["train_seconds"], bool):
        raise ValueError("train_seconds is not a number")
    for flag in ("hit_wall_clock", "met_early"):
        if not isinstance(result[flag], bool):
            raise ValueError(f"{flag} is not a boolean")
    for text in ("stop_reason", "numerics"):
        if result[text] is not None and not isinstance(result[text], str):
            raise ValueError(f"{text} {result[text]!r} is neither a string nor null")
    digest = result["weights_digest"]
    if digest is not None and not (isinstance(digest, str) and _HEX_DIGEST.fullmatch(digest)):
        raise ValueError(f"weights_digest {digest!r} is neither a SHA-256 hex digest nor null")
    if not isinstance(result["curve"], list) or not all(isinstance(p, dict) for p in result["curve"]):
        raise ValueError("curve is not a list of points")
    _check_looks(result["looks"], set(successes))


_LOOK_FIELDS = {"timesteps", "features", "held"}


def _check_looks(looks: Any, keys: Collection[str]) -> None:
    """Raise ``ValueError`` naming the first way ``looks`` is not what :attr:`RunResult.looks` holds for ``keys``."""
    if not isinstance(looks, list):
        raise ValueError("looks is not a list")
    for i, look in enumerate(looks):
        if not isinstance(look, dict) or set(look) != _LOOK_FIELDS:
            raise ValueError(f"looks[{i}] is not an object of {', '.join(sorted(_LOOK_FIELDS))}")
        if not _is_int(look["timesteps"]) or look["timesteps"] < 0:
            raise ValueError(f"looks[{i}].timesteps {look['timesteps']!r} is not an integer >= 0")
        features = look["features"]
        if not isinstance(features, list) or not all(
            isinstance(row, list) and all(_is_number(x) and math.isfinite(x) for x in row) for row in features
        ):
            raise ValueError(f"looks[{i}].features is not a list of lists of finite numbers")
        if len({len(row) for row in features}) > 1:
            raise ValueError(f"looks[{i}].features has episodes of different lengths")
        held = look["held"]
        if not isinstance(held, dict) or not set(held) <= set(keys):
            raise ValueError(f"looks[{i}].held is not an object of the run's goal and safety keys")
        for key, bits in held.items():
            if not isinstance(bits, str) or len(bits) != len(features) or set(bits) - {"0", "1"}:
                raise ValueError(f"looks[{i}].held[{key!r}] is not one 0 or 1 per episode ({len(features)})")


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)
