"""A spec: what to train (initial env + goal tree), how (its trainer), on what budget, and what to expect.

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
import os
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, cast

from specguard.construction.env import OBSERVATIONS, BaselineEnv, EnvFactory, SpecEnv
from specguard.construction.initial_env import InitialEnv
from specguard.error import InvalidSpec
from specguard.spec.budget import Budget
from specguard.spec.trainers import SB3, TRAINERS, Trainer, as_trainer
from specguard.starts.setter import Range
from specguard.starts.space import StartSpace, as_start_space
from specguard.stats.verdicts import DEFAULT_UNDECIDED, UNDECIDED_OUTCOMES
from specguard.tree.keys import check_expect, check_xfail, check_xfail_thresholded, resolve_goal
from specguard.tree.nodes import Node
from specguard.utils.numerics import NUMERICS
from specguard.utils.text import function_text
from specguard.validation import check_choice, check_count, check_open_fraction

__all__ = ["Spec", "check_spec"]


# The keywords a spec took before its trainer held them (0.1): Spec(algorithm=...) is Spec(trainer=SB3(algorithm=...)).
_MOVED_TO_SB3 = ("algorithm", "hyperparameters", "n_envs", "normalize", "policy", "callbacks", "tensorboard_log")


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
        trainer: how each run trains: :class:`~specguard.spec.trainers.SB3` (default ``sg.SB3()``: PPO with SB3's
            defaults) with an algorithm, its hyperparameters, policy, ``n_envs``, ``normalize``, callbacks and
            TensorBoard folder; or the user's own training loop, a generator function
            ``trainer(make_env, timesteps, seed)`` yielding ``(steps, agent)`` checkpoints
            (:class:`~specguard.spec.trainers.TrainingLoop`, which wraps it). Part of the spec's identity through
            the trainer's own :meth:`~specguard.spec.trainers.Trainer.identity`.
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
        observation: what the agent sees. ``"features"`` (default): the features, then the goal
            tree's own state, a flat ``Box``. ``"features+env"``: a ``Dict`` of that ``Box``
            under ``"spec"`` and the initial env's own observation beside it (a ``Dict``'s keys
            as the env gives them, any other observation under ``"observation"``), for an image
            the features leave out; the goals are judged on the features alone either way.
            Refused with ``baseline=True`` (the baseline sees the env's own observation), and
            for a key stable-baselines3 cannot take (a ``Text``, a key that is no string, an empty
            ``Box``) when the env is built.
            An SB3 trainer's ``normalize=True`` normalizes the ``"spec"`` part only, and its default policy follows
            the observation (``"MultiInputPolicy"`` for ``"features+env"``). Part of a run's key only when it is
            not the default.
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
    trainer: Trainer = field(default_factory=SB3)
    quorum: int | None = None
    deterministic: bool = True
    confidence: float = 0.95
    undecided: str = DEFAULT_UNDECIDED
    baseline: bool = False
    name: str | None = None
    xfail: Mapping[str, str] = field(default_factory=dict)
    starts: StartSpace | None = None
    observation: str = "features"
    numerics: str = "portable"

    def __post_init__(self) -> None:
        label = f"Spec {self.label!r}"
        if not isinstance(self.initial_env, InitialEnv):
            raise InvalidSpec(f"{label}.initial_env", f"expected an InitialEnv, got {self.initial_env!r}")
        if not isinstance(self.tree, Node):
            raise InvalidSpec(f"{label}.tree", f"expected a Goal or All node, got {self.tree!r}")
        if not isinstance(self.budget, Budget):
            raise InvalidSpec(f"{label}.budget", f"expected a Budget, got {self.budget!r}")
        check_choice(label, "observation", self.observation, OBSERVATIONS)
        if self.baseline and self.observation != "features":
            raise InvalidSpec(
                f"{label}.observation",
                f"baseline=True trains on the initial env's own observation; observation={self.observation!r} "
                "is for the constructed env",
            )
        trainer = as_trainer(f"{label}.trainer", self.trainer)
        trainer = trainer.checked(label, observation=self.observation, baseline=self.baseline, tree=self.tree)
        object.__setattr__(self, "trainer", trainer)
        if self.quorum is not None:
            object.__setattr__(self, "quorum", self._checked_quorum(label))
        check_open_fraction(label, "confidence", self.confidence)
        check_choice(label, "undecided", self.undecided, UNDECIDED_OUTCOMES)
        check_choice(label, "numerics", self.numerics, NUMERICS)
        object.__setattr__(self, "expect", self._resolve_thresholds(label))
        object.__setattr__(self, "xfail", self._resolve_xfail(label))
        object.__setattr__(self, "starts", as_start_space(f"{label}.starts", self.starts))

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

        ``budget_scale`` and ``checkpoints`` as for :meth:`scaled`; ``undecided`` and ``numerics``, if given, replace
        the spec's own, ``tensorboard_log`` its trainer's (:meth:`Trainer.logging_to
        <specguard.spec.trainers.Trainer.logging_to>`: a training loop of the user's logs where it likes, and says
        so). ``None`` keeps the spec's own, so that every door judges a spec the same way unless told otherwise.
        """
        spec = self.scaled(budget_scale, checkpoints=checkpoints)
        changes: dict[str, Any] = {}
        if undecided is not None and undecided != spec.undecided:
            changes["undecided"] = undecided
        if numerics is not None and numerics != spec.numerics:
            changes["numerics"] = check_choice(f"Spec {spec.label!r}", "numerics", numerics, NUMERICS)
        if tensorboard_log is not None:
            trainer = spec.trainer.logging_to(f"Spec {spec.label!r}", tensorboard_log)
            if trainer is not spec.trainer:
                changes["trainer"] = trainer
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


def _taking_moved_keywords(init: Callable[..., None]) -> Callable[..., None]:
    """``Spec.__init__`` that still takes SB3's keywords (:data:`_MOVED_TO_SB3`) into ``trainer=SB3(...)``, with a
    ``DeprecationWarning``; beside a trainer of their own they are refused, as they would be ignored."""

    @functools.wraps(init)
    def __init__(self: Spec, *args: Any, **kwargs: Any) -> None:
        moved = {key: kwargs.pop(key) for key in _MOVED_TO_SB3 if key in kwargs}
        if moved:
            names = ", ".join(f"{key}=" for key in moved)
            if kwargs.get("trainer") is not None:
                given = kwargs["trainer"]
                title = given.title if isinstance(given, TRAINERS) else f"trainer {function_text(given)}"
                raise InvalidSpec(
                    "Spec",
                    f"{names} configure SB3's training, and the spec trains with its {title}",
                    hint="give them to the trainer, sg.SB3(...), or leave them out of a spec with a trainer of its own",
                )
            warnings.warn(
                f"Spec({names}...) moved into the spec's trainer: write Spec(..., trainer=sg.SB3({names}...)); "
                "the old keywords go in a later 0.x release",
                DeprecationWarning,
                stacklevel=2,
            )
            kwargs["trainer"] = SB3(**moved)
        init(self, *args, **kwargs)

    return __init__


setattr(Spec, "__init__", _taking_moved_keywords(Spec.__init__))  # noqa: B010 (a method replaced after the class)


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
