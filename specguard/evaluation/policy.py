"""A trained model as a policy: its action for an observation, with what it carries from step to step.

The one assembly of a policy from an SB3 model, used wherever a model acts: a
run's evaluation and anytime checkpoints (:mod:`specguard.training.train`),
rollouts and GIFs (:mod:`specguard.evaluation.rollout`) and the falsifier
(:mod:`specguard.engine.falsify_run`). Per env it keeps

* the model's ``VecNormalize`` statistics, applied to every observation;
* a recurrent policy's state (sb3-contrib's RecurrentPPO: its LSTM's hidden and
  cell states), cleared when an episode starts (:meth:`Policy.start`) and
  carried from each step to the next, as ``model.predict(obs, state=...,
  episode_start=...)`` asks;
* the env's action masks, read before every action, for an algorithm whose
  ``predict`` takes ``action_masks`` (sb3-contrib's MaskablePPO).

A model without a recurrent state acts exactly as ``model.predict(obs)[0]``. A callable ``obs -> action`` without
``predict`` (the agent a trainer of the user's yields, ``Spec(trainer=...)``) acts as itself (:func:`callable_policy`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any

import numpy as np

from specguard.error import SpecError
from specguard.spec.algorithms import takes_action_masks

__all__ = ["Policy", "callable_policy", "normalizer_of", "observation_rows", "one_torch_thread", "policy"]


@contextmanager
def one_torch_thread() -> Iterator[None]:
    """torch on one thread while a policy acts in this process, as training workers run it; the setting is restored.

    A policy's network is small and its batches are a few rows: more threads only add their synchronisation, and on
    a busy machine they wait for each other. Measured on a 2-core machine under load, the falsifier's runner on
    CartPole took 190 microseconds a step on one thread and 11 milliseconds on two.
    """
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def normalizer_of(model: Any, normalizer: Any = None) -> Any:
    """The ``VecNormalize`` whose statistics the policy expects: ``normalizer`` if given, else the model's training env
    when it is one, else ``None``."""
    if normalizer is not None:
        return normalizer
    from stable_baselines3.common.vec_env import VecNormalize

    env = model.get_env() if hasattr(model, "get_env") else None
    return env if isinstance(env, VecNormalize) else None


class Policy:
    """``model``'s action for an observation (or a batch of them, one row per env), with what it carries per env.

    Call :meth:`start` with the envs as their episodes start (after ``reset``), then the policy once per step.
    It satisfies :class:`specguard.construction.episode_policy.EpisodePolicy`.

    Args:
        model: a trained SB3 model (any ``BaseAlgorithm``).
        normalizer: the statistics of a ``normalize=True`` spec; default: the model's training env when it is one.
        deterministic: the model's deterministic action, or a sampled one.
        batch: the policy takes a batch of observations (rows, one per env) and returns their actions as the model
            gives them; otherwise one observation, and a discrete action as a Python ``int``.
    """

    def __init__(self, model: Any, normalizer: Any = None, *, deterministic: bool = True, batch: bool = False) -> None:
        import gymnasium as gym

        self.model = model
        self.deterministic = deterministic
        self.batch = batch
        self.masked = takes_action_masks(model)
        """The model acts on the env's action masks."""
        self._norm = normalizer_of(model, normalizer)
        self._discrete = not batch and isinstance(getattr(model, "action_space", None), gym.spaces.Discrete)
        self._envs: list[Any] = []
        self._state: tuple[np.ndarray, ...] | None = None  # a recurrent policy's, (layers, envs, size) per array
        self._starting = np.ones(1, dtype=bool)  # per env: its next action is its episode's first

    def start(self, envs: Sequence[Any]) -> None:
        """Episodes start on ``envs`` (one env, or one per row of a batch): a recurrent state starts afresh."""
        self._envs = list(envs)
        self._state = None
        self._starting = np.ones(len(self._envs), dtype=bool)

    def __call__(self, observations: Any, rows: Sequence[int] | None = None) -> Any:
        """The action for ``observations``: of every env started, or of the envs ``rows`` (a batch's still running).

        An observation is an array, or a ``Dict`` observation's arrays by key (``Spec(observation="features+env")``;
        a batch of them stacked key by key, :func:`~specguard.construction.env.stack_observations`).

        Raises:
            SpecError: the model acts on action masks and was not told the envs (:meth:`start`).
        """
        if rows is None:
            rows = list(range(_rows(observations))) if self.batch else [0]
        rows = list(rows)
        if max(rows) >= len(self._starting):  # more envs than it was told of (no start): all start here
            self._state, self._starting = None, np.ones(max(rows) + 1, dtype=bool)
        obs = self._norm.normalize_obs(observations) if self._norm is not None else observations
        kwargs: dict[str, Any] = {}
        if self.masked:
            kwargs["action_masks"] = self._masks(rows)
        state = None if self._state is None else tuple(s[:, rows] for s in self._state)
        with _predicting(self.model):
            action, state = self.model.predict(
                obs, state=state, episode_start=self._starting[rows], deterministic=self.deterministic, **kwargs
            )
        self._starting[rows] = False
        if state is not None:  # a recurrent policy: keep each env's own state
            if self._state is None:
                n = len(self._starting)
                self._state = tuple(np.zeros((s.shape[0], n, *s.shape[2:]), dtype=s.dtype) for s in state)
            for kept, new in zip(self._state, state, strict=True):
                kept[:, rows] = new
        return int(action) if self._discrete else action

    def _masks(self, rows: list[int]) -> np.ndarray:
        if not self._envs:
            raise SpecError(
                f"{type(self.model).__name__} acts on action masks, and the policy was not told its envs",
                hint="call policy.start(envs) after each reset",
            )
        masks = [np.asarray(self._envs[i].get_wrapper_attr("action_masks")()) for i in rows]
        return np.stack(masks) if self.batch else masks[0]


def _keep_mode(mode: bool) -> None:
    """Stands for an SB3 policy's ``set_training_mode`` while :func:`_predicting`: the mode is set already."""


@contextmanager
def _predicting(model: Any) -> Iterator[None]:
    """``model.predict`` without the work that changes no action, the model and torch restored after it.

    SB3's ``predict`` (and sb3-contrib's) puts every module of the policy in eval mode at every call, walking them
    all, and torch checks the arguments of every distribution it builds (a ``Categorical``'s probabilities sum to
    one...). Here the policy is put in eval mode once, when its root module is not (SB3 switches modes on the root
    alone: ``set_training_mode``), and neither is redone during the call; the actions are the same to the bit
    (tests/test_policy.py). Measured on one core: PPO on LunarLander 123 -> 71 us a step, SAC on Pendulum
    163 -> 81 us.
    """
    policy = getattr(model, "policy", None)
    if (
        policy is None
        or not callable(getattr(policy, "set_training_mode", None))
        or "set_training_mode" in vars(policy)
    ):
        yield  # not an SB3 policy, or one of ours is predicting already (nested)
        return
    from torch.distributions import Distribution

    if getattr(policy, "training", False):
        policy.set_training_mode(False)
    validate = Distribution._validate_args
    policy.set_training_mode = _keep_mode
    Distribution._validate_args = False
    try:
        yield
    finally:
        del policy.set_training_mode
        Distribution._validate_args = validate


def _rows(observations: Any) -> int:
    """The rows of a batch of observations: an array's, or a ``Dict`` observation's (its parts', key by key)."""
    if isinstance(observations, Mapping):
        return len(next(iter(observations.values())))
    return len(observations)


def observation_rows(observations: Any) -> list[Any]:
    """A batch of observations (rows, one per env) as a list of single observations, a ``Dict``'s key by key.

    Example:
        >>> observation_rows({"a": np.zeros((2, 3)), "b": np.ones((2, 1))})[1]["b"].tolist()
        [1.0]
    """
    if isinstance(observations, Mapping):
        n = len(next(iter(observations.values())))
        return [{k: v[i] for k, v in observations.items()} for i in range(n)]
    return list(observations)


def callable_policy(fn: Callable[[Any], Any], *, batch: bool = False) -> Callable[..., Any]:
    """A callable ``obs -> action`` for one observation as a policy's step ``(observations, rows=None)``: asked once,
    or for a batch (``batch=True``) row by row, its actions stacked.

    Example:
        >>> step = callable_policy(lambda obs: int(obs[0] > 0), batch=True)
        >>> step(np.array([[1.0], [-1.0]])).tolist()
        [1, 0]
    """
    if not batch:
        return lambda observations, rows=None: fn(observations)
    return lambda observations, rows=None: np.stack([np.asarray(fn(o)) for o in observation_rows(observations)])


def policy(
    model: Any, normalizer: Any = None, *, deterministic: bool = True, batch: bool = False
) -> Callable[..., Any]:
    """``model``'s :class:`Policy` (its arguments as there); a callable without ``predict`` (a trainer's agent),
    its :func:`callable_policy`, which reads no ``VecNormalize`` statistics (a trainer normalizes on its own)."""
    if callable(model) and not callable(getattr(model, "predict", None)):
        return callable_policy(model, batch=batch)
    return Policy(model, normalizer, deterministic=deterministic, batch=batch)
