"""How a spec's runs train: a :class:`Trainer`, apart from what the spec asks.

A :class:`~specguard.spec.spec.Spec` says what it asks (the env, the tree, the thresholds, the budget); its
``trainer`` says how each run trains. Two trainers implement the one :class:`Trainer` protocol:

* :class:`SB3` (the default): a stable-baselines3 or sb3-contrib algorithm with its hyperparameters, policy, training
  envs, ``VecNormalize``, callbacks and TensorBoard folder (:mod:`specguard.training.train` runs it);
* :class:`TrainingLoop`: the user's own generator function ``trainer(make_env, timesteps, seed)`` yielding
  ``(steps, agent)`` checkpoints (:mod:`specguard.training.user_loop` drives it). ``Spec(trainer=my_loop)`` wraps a
  function in one.

Each trainer checks its own arguments where it is made, checks itself against the spec that holds it
(:meth:`Trainer.checked`: a policy against what the agent sees, a loop against ``weights="auto"``), and gives its own
part of the run cache's key (:meth:`Trainer.identity`).

Example:
    >>> import specguard as sg
    >>> trainer = sg.SB3("SAC", hyperparameters={"learning_starts": 100}, n_envs=2)
    >>> trainer.algorithm, trainer.n_envs
    ('SAC', 2)
    >>> sg.SB3("PPO", hyperparameters={"n_step": 64})
    Traceback (most recent call last):
    ...
    specguard.error.InvalidSpec: SB3.hyperparameters: PPO takes no hyperparameter 'n_step'; did you mean 'n_steps'?
    Hint: ...
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import inspect
import os
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from numbers import Real
from typing import Any, Protocol

from specguard.error import InvalidSpec, SpecWarning, user_stacklevel
from specguard.spec.algorithms import (
    SB3 as SB3_NAMES,
)
from specguard.spec.algorithms import (
    algorithm_class,
    algorithm_name,
    check_hyperparameters,
    check_policy,
    collect_steps,
    collection_unit,
    default_policy,
    resolve_algorithm,
)
from specguard.spec.budget import trained_timesteps
from specguard.spec.schedules import SCHEDULED, LinearSchedule
from specguard.tree.nodes import Node
from specguard.utils.text import function_text, shown
from specguard.validation import check_count, check_folder, is_finite

__all__ = ["SB3", "TRAINERS", "Trainer", "TrainingLoop", "as_trainer", "check_tensorboard_log"]


class Trainer(Protocol):
    """How a spec's runs train. :class:`SB3` and :class:`TrainingLoop` are the two specguard runs.

    A trainer is an immutable value (a frozen dataclass): part of the spec's identity through :meth:`identity`,
    and sent to the processes that train, as the spec is.
    """

    def checked(self, where: str, *, observation: str, baseline: bool, tree: Node | None) -> Trainer:
        """This trainer as the spec at ``where`` trains with it: its defaults taken for that spec, checked against
        what the agent sees (``observation``, ``baseline``) and the tree.

        Raises:
            InvalidSpec: the trainer cannot train this spec (one line, naming ``where``).
        """
        ...

    def identity(self, *, observation: str) -> dict[str, Any]:
        """What of this trainer decides a run, as fields of the run cache's key (:mod:`specguard.cache.fingerprint`);
        ``observation`` is the spec's (a default that follows it is left out)."""
        ...

    def logging_to(self, where: str, folder: str | os.PathLike[str]) -> Trainer:
        """This trainer writing its TensorBoard logs under ``folder`` (a door's ``--tensorboard-log``), or itself,
        with a :class:`~specguard.error.SpecWarning`, when it logs where it likes."""
        ...

    @property
    def title(self) -> str:
        """The trainer in a few words, for reports: ``"PPO"``, ``"trainer reinforce"``."""
        ...

    def steps_text(self, timesteps: int) -> str:
        """The steps a run of a ``timesteps`` budget trains, in words, for ``specguard show``."""
        ...


# -- stable-baselines3 ---------------------------------------------------------------------------------


def check_tensorboard_log(where: str, folder: object) -> str:
    """A TensorBoard folder option: a path, with the ``tensorboard`` package installed to write it.

    Raises:
        InvalidSpec: not a folder that can be made (:func:`~specguard.validation.check_folder`), or ``tensorboard``
            is not installed.
    """
    folder = check_folder(where, "tensorboard_log", folder)  # checked before training: every seed would fail
    if importlib.util.find_spec("tensorboard") is None:
        raise InvalidSpec(
            where,
            f"tensorboard_log={os.fspath(folder)!r} needs the tensorboard package, which is not installed",
            hint="pip install tensorboard (or specguard's tensorboard extra)",
        )
    return str(os.fspath(folder))


def _checked_callbacks(where: str, callbacks: object) -> tuple[Callable[[], Any], ...]:
    """The callback factories as a tuple, each callable (a class, a partial, a function)."""
    if isinstance(callbacks, (str, bytes)) or not isinstance(callbacks, Sequence):
        raise InvalidSpec(where, f"expected a list of callback factories, got {shown(callbacks)}")
    for i, factory in enumerate(callbacks):
        if not callable(factory):
            raise InvalidSpec(
                f"{where}[{i}]",
                f"expected a callable returning an SB3 BaseCallback (its class, a functools.partial), got "
                f"{shown(factory)}",
                hint="pass the class, not an instance: callbacks=[MyCallback] or [functools.partial(MyCallback, n=5)]",
            )
    return tuple(callbacks)


def _check_schedules(where: str, hyperparameters: Mapping[str, Any]) -> None:
    """A scheduled hyperparameter (``learning_rate``, ``clip_range``, ...) as a number or rl-zoo3's linear
    schedule is finite; written as rl-zoo3's text (``"lin_3e-4"``), it is ``sg.zoo_settings``'s to read.

    Its other values (a callable, ``None``) are the algorithm's to check.
    """
    for key in SCHEDULED:
        value = hyperparameters.get(key)
        start = value.initial_value if isinstance(value, LinearSchedule) else value
        if isinstance(start, str):
            raise InvalidSpec(
                where,
                f"expected {key} to be a number or a schedule (a callable), got the text {shown(value)}",
                hint="rl-zoo3's 'lin_<x>' is sg.zoo_settings's to read, or write LinearSchedule(x) "
                "(from specguard.spec.zoo)",
            )
        if isinstance(start, Real) and not is_finite(start):
            raise InvalidSpec(where, f"expected {key} to be a finite number, got {shown(value)}")


@dataclass(frozen=True)
class SB3:
    """A stable-baselines3 (or sb3-contrib) algorithm trains each run: the default trainer of a spec.

    Args:
        algorithm: the algorithm, fitting the action space: a stable-baselines3 or sb3-contrib name (``"PPO"``,
            ``"TQC"``, ...), or any ``BaseAlgorithm`` subclass, as a class or ``"module:Class"``
            (:func:`~specguard.spec.algorithms.resolve_algorithm`; a named class is kept as its name).
        hyperparameters: keyword arguments for the algorithm (``n_steps``, ...); a name its constructor does not take
            is refused here, before anything trains, and so is a schedule (``learning_rate``, ``clip_range``, ...)
            that is not a finite number or schedule.
        policy: the algorithm's policy: one of its names (``"MlpPolicy"``, ``"CnnPolicy"``, ...) or a subclass of one
            of its policy classes; ``None`` (default): ``"MlpPolicy"``, or the algorithm's only MLP policy where it
            has no ``MlpPolicy`` (RecurrentPPO's ``"MlpLstmPolicy"``); for a spec with
            ``observation="features+env"``, ``"MultiInputPolicy"`` (RecurrentPPO's ``"MultiInputLstmPolicy"``). A name
            must take what the agent sees: neither a ``Dict`` nor an image (``"CnnPolicy"``) policy for the flat
            ``Box`` of ``"features"``, a ``Dict`` policy for ``"features+env"`` (checked when the spec takes the
            trainer; a baseline's observation, the env's own, is SB3's to check when it builds the model). Part of a
            run's key only when it is not that default.
        n_envs: parallel environments per run, stepped together in one process (a ``DummyVecEnv``:
            :class:`~specguard.training.vec_env.SpecVecEnv` for the constructed env).
        normalize: wrap the training envs in ``VecNormalize`` (a ``Dict`` observation's ``"spec"`` part only).
        callbacks: the user's own SB3 callbacks, as factories: each a callable (a ``BaseCallback`` subclass, a
            ``functools.partial`` of one, a function) that returns a new ``BaseCallback``, called in every training
            process, once per run, and composed after specguard's own through SB3's ``CallbackList``; a factory whose
            signature names ``seed`` or ``spec`` is given the run's. Part of the run's key (a callback may change
            training, as a curriculum does): a changed callback retrains. One that raises fails its seed in one line
            naming it.
        tensorboard_log: a TensorBoard folder the runs write to, as SB3's ``tensorboard_log``: SB3's own curves and
            every goal's success and safety rate (``specguard/goal/<path>``, ``specguard/safe/<path>/<name>``;
            :class:`~specguard.training.callback.LogGoals`), one subfolder per spec and seed
            (``<label>/seed_<seed>_<n>``). Not part of the run's key: a run found in the cache trained nothing, and
            writes nothing. A door's ``--tensorboard-log`` replaces it (:meth:`logging_to`).

    Example:
        >>> import specguard as sg
        >>> sg.SB3().title
        'PPO'
        >>> sg.SB3("RecurrentPPO").checked("Spec 'x'", observation="features", baseline=False, tree=None).policy
        'MlpLstmPolicy'
    """

    algorithm: str | type = "PPO"
    hyperparameters: Mapping[str, Any] = field(default_factory=dict)
    policy: str | type | None = None
    n_envs: int = 1
    normalize: bool = False
    callbacks: Sequence[Callable[[], Any]] = ()
    tensorboard_log: str | None = None

    def __post_init__(self) -> None:
        where = "SB3"
        algorithm = resolve_algorithm(f"{where}.algorithm", self.algorithm)
        object.__setattr__(self, "algorithm", algorithm)
        if not isinstance(self.hyperparameters, Mapping):
            raise InvalidSpec(f"{where}.hyperparameters", f"expected a mapping, got {shown(self.hyperparameters)}")
        check_hyperparameters(f"{where}.hyperparameters", algorithm, self.hyperparameters)
        _check_schedules(f"{where}.hyperparameters", self.hyperparameters)
        if self.policy is not None:  # against the algorithm here; against what the agent sees in checked()
            object.__setattr__(self, "policy", check_policy(f"{where}.policy", algorithm, self.policy))
        object.__setattr__(self, "n_envs", check_count(where, "n_envs", self.n_envs, "parallel environments per run"))
        if not isinstance(self.normalize, bool):
            raise InvalidSpec(f"{where}.normalize", f"expected True or False, got {shown(self.normalize)}")
        object.__setattr__(self, "callbacks", _checked_callbacks(f"{where}.callbacks", self.callbacks))
        if self.tensorboard_log is not None:
            object.__setattr__(self, "tensorboard_log", check_tensorboard_log(where, self.tensorboard_log))

    def checked(self, where: str, *, observation: str, baseline: bool, tree: Node | None) -> SB3:
        """The policy taken for the spec (its default follows ``observation``) and checked against what the agent
        sees: the constructed env's observation (a baseline's, the env's own, is SB3's to check)."""
        with_env = observation == "features+env"
        policy = default_policy(self.algorithm, dict_observation=with_env) if self.policy is None else self.policy
        seen = None if baseline else observation
        policy = check_policy(f"{where}.trainer.policy", self.algorithm, policy, seen)
        return self if policy == self.policy else dataclasses.replace(self, policy=policy)

    def identity(self, *, observation: str) -> dict[str, Any]:
        """The algorithm (a stable-baselines3 name, whose version is in every key already; any other by its class),
        the hyperparameters, ``n_envs`` and ``normalize``; the policy and the callbacks where they are not the
        default."""
        out: dict[str, Any] = {
            "algorithm": self.algorithm,
            "hyperparameters": self.hyperparameters,
            "n_envs": self.n_envs,
            "normalize": self.normalize,
        }
        if not (isinstance(self.algorithm, str) and self.algorithm in SB3_NAMES):
            out["algorithm"] = algorithm_class(self.algorithm)
        policy = self.policy
        if policy is not None and policy != default_policy(self.algorithm, dict_observation=observation != "features"):
            out["policy"] = policy
        if self.callbacks:
            out["callbacks"] = self.callbacks
        return out

    def logging_to(self, where: str, folder: str | os.PathLike[str]) -> SB3:
        """This trainer writing to ``folder`` instead of its own ``tensorboard_log``.

        Raises:
            InvalidSpec: ``folder`` cannot be made, or ``tensorboard`` is not installed (:func:`check_tensorboard_log`).
        """
        checked = check_tensorboard_log(where, folder)
        return self if checked == self.tensorboard_log else dataclasses.replace(self, tensorboard_log=checked)

    @property
    def title(self) -> str:
        return algorithm_name(self.algorithm)

    def steps_text(self, timesteps: int) -> str:
        """The budget rounded up to whole collections of the algorithm on ``n_envs`` envs, as SB3 trains it.

        Example:
            >>> SB3(hyperparameters={"n_steps": 1024}, n_envs=4).steps_text(12_000)
            '12288 timesteps per seed (12000 asked, rounded up to whole PPO rollouts of 4096 = 1024 steps x 4 envs)'
        """
        trained = trained_timesteps(timesteps, self.algorithm, self.hyperparameters, self.n_envs)
        envs = f"{self.n_envs} env{'s' if self.n_envs != 1 else ''}"
        if trained == timesteps:
            return f"{trained} timesteps per seed ({envs})"
        per_env = collect_steps(self.algorithm, self.hyperparameters)
        return (
            f"{trained} timesteps per seed ({timesteps} asked, rounded up to whole {self.title} "
            f"{collection_unit(self.algorithm)} of {per_env * self.n_envs} = {per_env} steps x {envs})"
        )


# -- the user's own training loop ----------------------------------------------------------------------


def _checked_loop(where: str, function: object) -> Callable[..., Any]:
    """A training loop: callable as ``function(make_env, timesteps, seed)``; a plain function (or a partial of one)
    must be a generator function. Another callable (an object with ``__call__``) must return an iterator when
    called, which the run checks (:mod:`specguard.training.user_loop`)."""
    if not callable(function):
        raise InvalidSpec(
            where,
            "expected sg.SB3(...) or a generator function trainer(make_env, timesteps, seed) yielding "
            f"(steps, agent), got {shown(function)}",
        )
    inner = function.func if isinstance(function, functools.partial) else function
    if inspect.isfunction(inner) and not inspect.isgeneratorfunction(inner):
        raise InvalidSpec(
            where,
            f"expected a generator function, got the function {function_text(inner)}, which does not yield",
            hint="a trainer yields (steps, agent) as it trains: write `yield steps, agent` at each checkpoint",
        )
    return function


@dataclass(frozen=True)
class TrainingLoop:
    """The user's own training loop trains each run: ``Spec(trainer=my_loop)`` makes one of ``my_loop``.

    ``function`` is a generator function ``function(make_env, timesteps, seed)`` that trains on envs made by
    ``make_env()`` (the constructed env, as SB3 trains on), for ``timesteps`` steps from ``seed``, and **yields**
    ``(steps, agent)`` checkpoints as it trains: ``steps`` the steps trained so far (increasing ints), ``agent`` a
    callable ``obs -> action``, an object with SB3's ``predict``, or an SB3 model. The checkpoints are judged with the
    anytime looks of SB3's training, the generator closed once a look meets every threshold, and the last agent gets
    the final evaluation (:mod:`specguard.training.user_loop`). Part of the run's key by its code, as the tree's
    functions. A tree with ``weights="auto"`` (which adapts SB3's training envs) is refused.
    """

    function: Callable[..., Any]

    def __post_init__(self) -> None:
        _checked_loop("TrainingLoop.function", self.function)

    def checked(self, where: str, *, observation: str, baseline: bool, tree: Node | None) -> TrainingLoop:
        """Refused over a tree that adapts its weights (``weights="auto"`` adapts SB3's training envs)."""
        adapting = [] if tree is None else [path for path, node in tree.walk() if node.adapts_weights]
        if adapting:
            raise InvalidSpec(
                f"{where}.tree",
                f"weights='auto' at {', '.join(adapting)} adapts SB3's training envs' weights, and the spec trains "
                f"with the {self.title}",
                hint="give the node fixed weights in a spec with a trainer of its own",
            )
        return self

    def identity(self, *, observation: str) -> dict[str, Any]:
        """The function, by its code (as the tree's functions enter the key)."""
        return {"trainer": self.function}

    def logging_to(self, where: str, folder: str | os.PathLike[str]) -> TrainingLoop:
        """Itself: a loop logs where it likes; the folder is named in a warning, not dropped in silence."""
        warnings.warn(
            f"{where} trains with its own {self.title}: the TensorBoard folder {shown(folder)} gets nothing "
            "from it (a trainer logs where it likes)",
            SpecWarning,
            stacklevel=user_stacklevel(),  # the user's call: as_run, or a door's run_spec
        )
        return self

    @property
    def title(self) -> str:
        return f"trainer {function_text(self.function)}"

    def steps_text(self, timesteps: int) -> str:
        """The budget, which the loop is given and trains as it likes."""
        return f"{timesteps} timesteps per seed (given to the {self.title})"


TRAINERS = (SB3, TrainingLoop)
"""The trainers specguard runs (:mod:`specguard.training.train` has one implementation for each)."""


def as_trainer(where: str, trainer: object) -> Trainer:
    """``trainer`` as a :class:`Trainer`: one of :data:`TRAINERS`, or a training loop's function in a
    :class:`TrainingLoop`.

    Raises:
        InvalidSpec: neither a trainer specguard runs nor a generator function (one line, naming ``where``):
            refused where the spec is made, not when its first run starts.
    """
    if isinstance(trainer, TRAINERS):
        return trainer
    return TrainingLoop(_checked_loop(where, trainer))
