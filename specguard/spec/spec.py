"""A spec: what to train (initial env + goal tree + algorithm), on what budget, and what to expect.

Example:
    >>> import specguard as sg
    >>> pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    >>> tree = sg.All(
    ...     sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)),
    ...     sg.Goal("stabilization", omega=(-0.25, 0.25)),
    ...     name="pendulum",
    ...     weights=(0.8, 0.2),
    ... )
    >>> spec = sg.Spec(
    ...     pendulum,
    ...     tree,
    ...     budget=sg.Budget(timesteps=100_000),
    ...     expect={"pendulum": 0.8, "position": 0.9},
    ... )
    >>> spec.thresholds
    {'pendulum': 0.8, 'pendulum/position': 0.9}
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
from typing import Any, cast

from specguard.construction.env import OBSERVATIONS, BaselineEnv, EnvFactory, SpecEnv
from specguard.construction.initial_env import InitialEnv
from specguard.error import InvalidSpec, SpecWarning, user_stacklevel
from specguard.spec.algorithms import check_hyperparameters, check_policy, default_policy, resolve_algorithm
from specguard.spec.budget import Budget
from specguard.spec.zoo import SCHEDULED, LinearSchedule
from specguard.starts.setter import Range
from specguard.starts.space import StartSpace, as_start_space
from specguard.stats.verdicts import DEFAULT_UNDECIDED, UNDECIDED_OUTCOMES
from specguard.tree.keys import check_expect, check_xfail, check_xfail_thresholded, resolve_goal
from specguard.tree.nodes import Node
from specguard.utils.numerics import NUMERICS
from specguard.utils.text import function_text, shown
from specguard.validation import check_choice, check_count, check_folder, check_open_fraction, is_finite

__all__ = ["Spec", "check_spec", "check_tensorboard_log"]


def _checked_callbacks(where: str, callbacks: object) -> tuple[Callable[[], Any], ...]:
    """The spec's callback factories as a tuple, each callable (a class, a partial, a function)."""
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


# What a trainer of the user's (Spec(trainer=...)) makes meaningless: the fields that only configure SB3's training.
_SB3_ONLY = (
    ("callbacks", "are SB3 callbacks; a trainer runs its own loop", lambda spec: bool(spec.callbacks)),
    ("hyperparameters", "are the SB3 algorithm's; give them to the trainer", lambda spec: bool(spec.hyperparameters)),
    ("normalize", "wraps SB3's training envs in VecNormalize; normalize in the trainer", lambda spec: spec.normalize),
    (
        "n_envs",
        "is SB3's number of training envs; the trainer calls make_env as often as it needs",
        lambda spec: spec.n_envs != 1,
    ),
    ("algorithm", "names an SB3 algorithm, which a trainer replaces", lambda spec: spec.algorithm != "PPO"),
    ("policy", "is the SB3 algorithm's policy; the trainer builds its own", lambda spec: not _default_policy(spec)),
    (
        "tensorboard_log",
        "is SB3's logger folder; a trainer writes its own logs",
        lambda spec: spec.tensorboard_log is not None,
    ),
)


def _default_policy(spec: Spec) -> bool:
    """The spec's policy is left out, or is the one it defaults to (a spec made again by ``dataclasses.replace``)."""
    with_env = spec.observation == "features+env"
    return spec.policy is None or spec.policy == default_policy(spec.algorithm, dict_observation=with_env)


def _checked_trainer(where: str, trainer: object) -> Callable[..., Any]:
    """A trainer: callable as ``trainer(make_env, timesteps, seed)``; a plain function (or a partial of one) must be
    a generator function. Another callable (an object with ``__call__``) must return an iterator when called, which
    the run checks (:mod:`specguard.training.trainer`)."""
    if not callable(trainer):
        raise InvalidSpec(
            where,
            f"expected a generator function trainer(make_env, timesteps, seed) yielding (steps, agent), got "
            f"{shown(trainer)}",
        )
    inner = trainer.func if isinstance(trainer, functools.partial) else trainer
    if inspect.isfunction(inner) and not inspect.isgeneratorfunction(inner):
        raise InvalidSpec(
            where,
            f"expected a generator function, got the function {function_text(inner)}, which does not yield",
            hint="a trainer yields (steps, agent) as it trains: write `yield steps, agent` at each checkpoint",
        )
    return trainer


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


@dataclass(frozen=True)
class Spec:
    """A goal tree over an initial env, trained and judged against per-goal thresholds.

    Args:
        initial_env: the initial environment.
        tree: the goal tree.
        budget: training and evaluation budget.
        expect: ``{node path or unique node name: minimum success}``, or one
            number for the root goal (read by :func:`specguard.tree.keys.check_expect`).
            Empty: measure only, or take the thresholds of ``@goal_spec(expect=...)``.
        algorithm: the algorithm, fitting the action space: a stable-baselines3 or
            sb3-contrib name (``"PPO"``, ``"TQC"``, ...), or any ``BaseAlgorithm``
            subclass, as a class or ``"module:Class"``
            (:func:`~specguard.spec.algorithms.resolve_algorithm`; a named class is kept as its name).
        hyperparameters: keyword arguments for the algorithm (``n_steps``, ...); a name its
            constructor does not take is refused here, before anything trains, and so is a
            schedule (``learning_rate``, ``clip_range``, ...) that is not a finite number or schedule.
        n_envs: parallel environments per run, stepped together in one process (a ``DummyVecEnv``:
            :class:`~specguard.training.vec_env.SpecVecEnv` for the constructed env).
        normalize: wrap the training env in ``VecNormalize``.
        quorum: runs that must meet each threshold; default every run
            (``budget.max_seeds``).
        deterministic: evaluate the policy's deterministic action.
        confidence: the confidence of the success intervals.
        undecided: what a goal counts as when it failed only through runs that
            stayed undecided (none missed, no seed failed): "fail" (default),
            "xfail" (expected to miss: pytest XFAIL, ``specguard run`` exit 0)
            or "pass" (with a warning under pytest). Every door reads it
            here; their ``--undecided`` options override it
            (:meth:`as_run`).
        baseline: train on the initial env's own reward, termination and
            observation, and evaluate the same goals (the paper's baseline).
        name: a label for reports; defaults to the root's name.
        xfail: ``{goal: reason}`` (or a list of goals, as for ``@goal_spec``)
            for thresholded goals the spec is expected to miss (e.g. a
            negative result of the paper): pytest reports them
            XFAIL (XPASS once they pass), ``specguard run`` does not count
            their miss as a failure. Under anytime verdicts their runs are
            never cut short: a goal not met keeps its run training.
        starts: the start space the falsifier searches by default
            (:class:`~specguard.starts.space.StartSpace` or its ranges
            ``{variable: (lo, hi)}``; ``None``: the env's own reset ranges):
            ``specguard falsify``, :func:`~specguard.engine.falsify_run.falsify_runs` and
            ``falsify=True`` read it. Not part of the spec's identity: it
            changes no run and no verdict of its goals.
        policy: the algorithm's policy: one of its names (``"MlpPolicy"``, ``"CnnPolicy"``, ...)
            or a subclass of one of its policy classes; ``None`` (default): ``"MlpPolicy"``, or the algorithm's
            only MLP policy where it has no ``MlpPolicy`` (RecurrentPPO's ``"MlpLstmPolicy"``);
            with ``observation="features+env"``, ``"MultiInputPolicy"`` (RecurrentPPO's
            ``"MultiInputLstmPolicy"``). A name must take what the agent sees: neither a ``Dict`` nor
            an image (``"CnnPolicy"``) policy for the flat ``Box`` of ``"features"``, a ``Dict`` policy for
            ``"features+env"`` (a baseline's, the env's own, is SB3's to check when it builds the model).
            Part of a run's key only when it is not that default.
        observation: what the agent sees. ``"features"`` (default): the features, then the goal
            tree's own state, a flat ``Box``. ``"features+env"``: a ``Dict`` of that ``Box``
            under ``"spec"`` and the initial env's own observation beside it (a ``Dict``'s keys
            as the env gives them, any other observation under ``"observation"``), for an image
            the features leave out; the goals are judged on the features alone either way.
            Refused with ``baseline=True`` (the baseline sees the env's own observation), and
            for a key stable-baselines3 cannot take (a ``Text``, a key that is no string, an empty
            ``Box``) when the env is built.
            ``normalize=True`` normalizes the ``"spec"`` part only. Part of a run's key only
            when it is not the default.
        callbacks: the user's own SB3 callbacks, as factories: each a callable (a ``BaseCallback`` subclass, a
            ``functools.partial`` of one, a function) that returns a new ``BaseCallback``, called in every
            training process, once per run, and composed after specguard's own through SB3's ``CallbackList``.
            Part of the spec's identity (a callback may change training, as a curriculum does): a changed callback
            retrains. One that raises fails its seed in one line naming it.
        tensorboard_log: a TensorBoard folder the runs write to, as SB3's ``tensorboard_log``: SB3's own curves
            and every goal's success and safety rate (``specguard/goal/<path>``, ``specguard/safe/<path>/<name>``;
            :class:`~specguard.training.callback.LogGoals`), one subfolder per spec and seed
            (``<label>/seed_<seed>_<n>``). A run option (:meth:`as_run`), not part of the spec's identity: a run
            found in the cache trained nothing, and writes nothing.
        trainer: the user's own training loop in place of SB3's: a generator function
            ``trainer(make_env, timesteps, seed)`` that trains on envs made by ``make_env()`` (the constructed env,
            as SB3 trains on), for ``timesteps`` steps from ``seed``, and **yields** ``(steps, agent)`` checkpoints
            as it trains: ``steps`` the steps trained so far (increasing ints), ``agent`` a callable
            ``obs -> action``, an object with SB3's ``predict``, or an SB3 model. The checkpoints are judged with
            the anytime looks of SB3's training, the generator closed once a look meets every threshold, and the last
            agent gets the final evaluation (:mod:`specguard.training.trainer`). Part of the spec's identity (its
            code, as the tree's functions); the SB3 fields mean nothing with it and are refused (``algorithm``
            left at its default is not used, ``callbacks``, ``hyperparameters``, ``normalize``, ``n_envs``,
            ``policy``, ``tensorboard_log``, a tree with ``weights="auto"``).
        numerics: what the runs compute with (:mod:`specguard.utils.numerics`): ``"portable"`` (default), torch's
            and MKL's kernels held to those every x86-64 CPU computes alike, so that the same spec and seed train
            the same weights, and reach the same verdict, on any x86-64 machine with the same versions; or
            ``"native"``, the kernels each library picks for this CPU (faster where vector kernels pay, and
            machine-dependent). Part of a run's key (a native run's names this CPU). A run option too
            (:meth:`as_run`: ``--numerics``, ini ``goal_specs_numerics``).
    """

    initial_env: InitialEnv
    tree: Node
    budget: Budget
    expect: Mapping[str, float] | float = field(default_factory=dict)
    algorithm: str | type = "PPO"
    hyperparameters: Mapping[str, Any] = field(default_factory=dict)
    n_envs: int = 1
    normalize: bool = False
    quorum: int | None = None
    deterministic: bool = True
    confidence: float = 0.95
    undecided: str = DEFAULT_UNDECIDED
    baseline: bool = False
    name: str | None = None
    xfail: Mapping[str, str] = field(default_factory=dict)
    starts: StartSpace | None = None
    policy: str | type | None = None
    observation: str = "features"
    callbacks: Sequence[Callable[[], Any]] = ()
    tensorboard_log: str | None = None
    trainer: Callable[..., Any] | None = None
    numerics: str = "portable"

    def __post_init__(self) -> None:
        label = f"Spec {self.label!r}"
        if not isinstance(self.initial_env, InitialEnv):
            raise InvalidSpec(f"{label}.initial_env", f"expected an InitialEnv, got {self.initial_env!r}")
        if not isinstance(self.tree, Node):
            raise InvalidSpec(f"{label}.tree", f"expected a Goal or All node, got {self.tree!r}")
        if not isinstance(self.budget, Budget):
            raise InvalidSpec(f"{label}.budget", f"expected a Budget, got {self.budget!r}")
        if self.trainer is not None:  # before the SB3 fields take their defaults (policy, ...)
            self._check_trainer(label)
        algorithm = resolve_algorithm(f"{label}.algorithm", self.algorithm)
        object.__setattr__(self, "algorithm", algorithm)
        if not isinstance(self.hyperparameters, Mapping):
            raise InvalidSpec(f"{label}.hyperparameters", f"expected a mapping, got {self.hyperparameters!r}")
        check_hyperparameters(f"{label}.hyperparameters", algorithm, self.hyperparameters)
        self._check_schedules(f"{label}.hyperparameters")
        check_choice(label, "observation", self.observation, OBSERVATIONS)
        if self.baseline and self.observation != "features":
            raise InvalidSpec(
                f"{label}.observation",
                f"baseline=True trains on the initial env's own observation; observation={self.observation!r} "
                "is for the constructed env",
            )
        with_env = self.observation == "features+env"
        policy = default_policy(algorithm, dict_observation=with_env) if self.policy is None else self.policy
        seen = None if self.baseline else self.observation  # a baseline's is the env's own, unknown until it is built
        object.__setattr__(self, "policy", check_policy(f"{label}.policy", algorithm, policy, seen))
        object.__setattr__(self, "n_envs", check_count(label, "n_envs", self.n_envs, "parallel environments per run"))
        if self.quorum is not None:
            object.__setattr__(self, "quorum", self._checked_quorum(label))
        check_open_fraction(label, "confidence", self.confidence)
        check_choice(label, "undecided", self.undecided, UNDECIDED_OUTCOMES)
        check_choice(label, "numerics", self.numerics, NUMERICS)
        object.__setattr__(self, "expect", self._resolve_thresholds(label))
        object.__setattr__(self, "xfail", self._resolve_xfail(label))
        object.__setattr__(self, "starts", as_start_space(f"{label}.starts", self.starts))
        object.__setattr__(self, "callbacks", _checked_callbacks(f"{label}.callbacks", self.callbacks))
        if self.tensorboard_log is not None:
            object.__setattr__(self, "tensorboard_log", check_tensorboard_log(label, self.tensorboard_log))

    def _check_trainer(self, label: str) -> None:
        """A trainer, and none of the fields that only configure SB3's training (:data:`_SB3_ONLY`)."""
        name = function_text(_checked_trainer(f"{label}.trainer", self.trainer))
        for field_name, meaning, given in _SB3_ONLY:
            if given(self):
                raise InvalidSpec(
                    f"{label}.{field_name}",
                    f"{field_name}={shown(getattr(self, field_name))} {meaning}, and the spec trains with the "
                    f"trainer {name}",
                    hint=f"leave {field_name} out of a spec with a trainer",
                )
        adapting = [path for path, node in self.tree.walk() if node.adapts_weights]
        if adapting:
            raise InvalidSpec(
                f"{label}.tree",
                f"weights='auto' at {', '.join(adapting)} adapts SB3's training envs' weights, and the spec trains "
                f"with the trainer {name}",
                hint="give the node fixed weights in a spec with a trainer",
            )

    @property
    def label(self) -> str:
        return self.name or str(getattr(self.tree, "name", "?"))

    def env_factory(self) -> EnvFactory:
        """Builds the envs this spec trains on: one factory per spec, so its tree is compiled and checked once in
        a process (and a worker that receives the spec receives it checked)."""
        factory = self.__dict__.get("_factory")
        if factory is None:  # not a field: neither the spec's identity, nor its key
            factory = EnvFactory(self.initial_env, self.tree, baseline=self.baseline, observation=self.observation)
            object.__setattr__(self, "_factory", factory)
        return cast(EnvFactory, factory)

    def make_env(
        self, *, check: bool = True, starts: StartSpace | Mapping[str, Range] | None = None, **make_kwargs: Any
    ) -> SpecEnv | BaselineEnv:
        """The env this spec trains on, built afresh, as Gymnasium's ``EnvSpec.make`` builds a registered env.

        The constructed env (:class:`~specguard.construction.env.SpecEnv`), or for a
        baseline spec the initial env with goal info (:class:`~specguard.construction.env.BaselineEnv`);
        ``make_kwargs`` override the base env's ``gymnasium.make`` kwargs (e.g. ``render_mode="rgb_array"``).
        The spec's checks (:func:`check_spec`) run on the first call unless ``check=False``, and never again.
        ``starts``: a start space its episodes may begin in, given to the factory
        (:meth:`EnvFactory.__call__ <specguard.construction.env.EnvFactory.__call__>`); not the spec's own
        :attr:`starts`, which the falsifier passes when it searches them.
        """
        return self.env_factory()(check=check, starts=starts, **make_kwargs)

    def scaled(self, factor: float, *, checkpoints: int | None = None) -> Spec:
        """This spec with its training budget multiplied by ``factor`` (the one place budgets are scaled).

        ``checkpoints``, if given, replaces the budget's own (1 trains every
        run's whole budget; more makes it a ceiling, :mod:`specguard.stats.anytime`).
        Nothing to change returns the spec itself, so its identity (and cache key) is unchanged.
        """
        if factor == 1 and checkpoints in (None, self.budget.checkpoints):
            return self
        return dataclasses.replace(self, budget=self.budget.scaled(factor, checkpoints=checkpoints))

    def as_run(
        self,
        budget_scale: float = 1.0,
        *,
        checkpoints: int | None = None,
        undecided: str | None = None,
        tensorboard_log: str | os.PathLike[str] | None = None,
        numerics: str | None = None,
    ) -> Spec:
        """This spec as a door (``specguard run``, ``pytest --goal-specs``) runs it, with the door's options.

        ``budget_scale`` and ``checkpoints`` as for :meth:`scaled`; ``undecided``, ``tensorboard_log`` and
        ``numerics``, if given, replace the spec's own (``tensorboard_log`` is SB3's folder: a spec with a
        ``trainer`` keeps none). ``None`` keeps the spec's own, so that every door judges a spec the same way unless
        told otherwise.
        """
        spec = self.scaled(budget_scale, checkpoints=checkpoints)
        if tensorboard_log is not None:
            tensorboard_log = check_tensorboard_log(f"Spec {spec.label!r}", tensorboard_log)
        changes: dict[str, Any] = {}
        if undecided is not None and undecided != spec.undecided:
            changes["undecided"] = undecided
        if numerics is not None and numerics != spec.numerics:
            changes["numerics"] = check_choice(f"Spec {spec.label!r}", "numerics", numerics, NUMERICS)
        if tensorboard_log is not None and spec.trainer is not None:  # kept as it is, but not in silence
            warnings.warn(
                f"Spec {spec.label!r} trains with its own trainer ({function_text(spec.trainer)}): the TensorBoard "
                f"folder {os.fspath(tensorboard_log)!r} gets nothing from it (a trainer logs where it likes)",
                SpecWarning,
                stacklevel=user_stacklevel(),  # the user's call: as_run, or a door's run_spec
            )
        elif tensorboard_log is not None and os.fspath(tensorboard_log) != spec.tensorboard_log:
            changes["tensorboard_log"] = os.fspath(tensorboard_log)
        return dataclasses.replace(spec, **changes) if changes else spec

    @property
    def verdict_confidence(self) -> float:
        """The confidence each look at a run judges at: ``confidence`` corrected for ``budget.looks`` looks.

        Intervals shown in tables stay at ``confidence``; run verdicts (met,
        missed, undecided) use this one, so that a run whose true success is
        its threshold is called met (or missed) with probability at most
        ``(1 - confidence) / 2`` over all its looks (:mod:`specguard.stats.anytime`).
        """
        from specguard.stats.anytime import look_confidence

        return look_confidence(self.confidence, self.budget.looks)

    @property
    def thresholds(self) -> dict[str, float]:
        """The thresholds by full node path."""
        assert isinstance(self.expect, Mapping)
        return dict(self.expect)

    @property
    def required_runs(self) -> int:
        """Runs that must meet each threshold."""
        assert self.budget.max_seeds is not None
        return self.quorum if self.quorum is not None else self.budget.max_seeds

    def _check_schedules(self, where: str) -> None:
        """A scheduled hyperparameter (``learning_rate``, ``clip_range``, ...) as a number or rl-zoo3's linear
        schedule is finite; written as rl-zoo3's text (``"lin_3e-4"``), it is ``sg.zoo_settings``'s to read.

        Its other values (a callable, ``None``) are the algorithm's to check.
        """
        for key in SCHEDULED:
            value = self.hyperparameters.get(key)
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

    def _checked_quorum(self, label: str) -> int:
        """A quorum is a count of runs (validation.check_count) that the budget can train."""
        quorum = check_count(label, "quorum", self.quorum, "runs that must meet each threshold")
        assert self.budget.max_seeds is not None
        if quorum > self.budget.max_seeds:
            raise InvalidSpec(
                label, f"expected quorum <= budget.max_seeds={self.budget.max_seeds} (the runs trained), got {quorum}"
            )
        return quorum

    def _resolve_xfail(self, label: str) -> dict[str, str]:
        reasons = check_xfail(label, self.xfail)
        resolved = {resolve_goal(self.tree, k, f"{label}.xfail[{k!r}]"): reason for k, reason in reasons.items()}
        check_xfail_thresholded(label, resolved, self.thresholds)
        return resolved

    def _resolve_thresholds(self, label: str) -> dict[str, float]:
        thresholds = check_expect(label, self.expect)
        return {resolve_goal(self.tree, k, f"{label}.expect[{k!r}]"): t for k, t in thresholds.items()}


def check_spec(spec: Spec) -> None:
    """Check a spec's construction once, as Gymnasium's ``check_env`` checks an env: before anything trains.

    A goal no state can be in (``UnreachableGoal``), a root goal met at every sampled start
    (``GoalMetAtStart``) or, held until the end, at none; a feature that cannot be read at a start. A root
    goal met (or failed) at some starts warns once (``SpecWarning``). Every door (``run_spec``,
    ``specguard run``, ``pytest --goal-specs``) calls it; the spec's envs then build without repeating it.

    Example:
        >>> import specguard as sg
        >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
        >>> spec = sg.Spec(cartpole, sg.Goal("far", x=(10, None)), budget=sg.Budget(timesteps=1000))
        >>> check_spec(spec)
        Traceback (most recent call last):
        ...
        specguard.error.UnreachableGoal: far: goal box x in [10, inf] lies outside the bounds of x, [-4.8, 4.8]: ...
        Hint: ...

    Raises:
        SpecError: the spec's env cannot be built, or a check refuses it (the message names the node path).
    """
    spec.env_factory().check()
