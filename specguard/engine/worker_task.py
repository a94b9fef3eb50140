"""The worker's task: train one seed of a spec, and the one line that says why a seed failed."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from specguard.cache.versions import check_versions, torch_capability
from specguard.error import SpecError, TrainingError
from specguard.parallel.protocol import Failure, Report
from specguard.spec.spec import Spec
from specguard.spec.trainers import SB3
from specguard.utils.numerics import hold_numerics

__all__ = ["describe_failure", "is_spec_error", "train_task"]


def train_task(spec: Spec, seed: int, keyed_versions: Mapping[str, str] | None, *, report: Report) -> dict[str, Any]:
    """A worker's task (a local process or a cluster worker): train one seed, return its result and model bytes.

    The driver stores them in its cache: keys are computed only by the driver
    (functions unpickled in a worker are not the driver's), and cluster
    workers need no shared filesystem. ``"unstored"`` says why a run has no files to store (a trainer's agent that
    cannot be pickled): the driver warns, and keeps and judges the run uncached. ``keyed_versions``, given when the
    result is to be cached, are the versions the driver's key names: a worker
    with other code refuses to train (:class:`~specguard.error.VersionMismatch`).
    """
    from specguard.cache.store import run_files
    from specguard.training.train import train_run

    if keyed_versions is not None:
        check_versions(keyed_versions, f"Spec {spec.label!r}, seed {seed}")
    # before torch computes anything: a worker's numerics are those its environment held from its start
    numerics = hold_numerics(spec.numerics, f"Spec {spec.label!r}, seed {seed}", torch_capability)
    with_model = keyed_versions is not None
    result, model = train_run(spec, seed, report=report)  # the spec arrives checked (Spec.env_factory)
    result.numerics, result.weights_digest = numerics, judged_digest(spec, model)
    files, unstored = run_files(spec, model) if with_model else ({}, None)
    return {"result": result.to_dict(), "files": files, "unstored": unstored}


def judged_digest(spec: Spec, model: Any) -> str | None:
    """The digest of the policy a run judged (:attr:`RunResult.weights_digest
    <specguard.training.result.RunResult>`): an SB3 model's with its training env's ``VecNormalize`` statistics, or a
    trainer's agent's as an agent of the same kind is digested (a model with SB3's ``predict``, with its statistics
    if any, or a callable); ``None`` when it cannot be digested (a trainer's agent, or a custom algorithm class,
    holding what has no canonical form): it is judged all the same."""
    from specguard.cache.weights import weights_digest
    from specguard.evaluation.policy import normalizer_of

    name = type(model).__name__
    try:
        if isinstance(spec.trainer, SB3) or callable(getattr(model, "predict", None)):
            return weights_digest(model, normalizer_of(model), name=name)
        return weights_digest(model, None, name=name, kind="callable")
    except Exception:  # the user's objects: a FingerprintError, or anything a state_dict() or an attribute raises
        return None


_PHASES = {"start": "starting", "build": "building the env", "train": "training step", "evaluate": "evaluation episode"}


def describe_failure(seed: int, failure: Failure) -> str:
    """One line: the seed, where the run was, and why it failed."""
    if isinstance(failure.exception, TrainingError):
        return failure.exception.message  # already names the seed, the phase and the step (the hint is generic)
    where = _PHASES.get(failure.phase, failure.phase)
    step = "" if failure.step is None or failure.phase not in ("train", "evaluate") else f" {failure.step}"
    return f"seed {seed}, {where}{step}: {failure.cause}"


def is_spec_error(failure: Failure) -> bool:
    """A mistake in the spec itself (e.g. rejected hyperparameters): every seed would hit it, so stop all."""
    return isinstance(failure.exception, SpecError) and not isinstance(failure.exception, TrainingError)
