"""The errors and warnings a user may catch, in one place (as Gymnasium keeps its ``error.py``).

Every message says *where* the problem is (the node path, annotation or option),
*what was expected* and *what was given*, and where it helps, a hint. Callers can
catch :class:`SpecError` to handle all of them.

The signals specguard raises and catches itself, which never reach a user, live
beside the code that raises them: ``Broken`` in :mod:`specguard.contract.trees`,
``ExitAtImport`` and ``ImportFailed`` in :mod:`specguard.utils.imports`, ``NoFrames`` in
:mod:`specguard.report.gifs` and ``NoOffscreen`` in :mod:`specguard.report.offscreen`.
"""

from __future__ import annotations

import sys

__all__ = [
    "AgentError",
    "AgentMismatch",
    "BaselineError",
    "CacheLockTimeout",
    "CacheWarning",
    "EvaluationError",
    "ExecutorError",
    "FingerprintError",
    "GoalMetAtStart",
    "GoalMissed",
    "InitialEnvError",
    "InvalidSpec",
    "NumericsError",
    "PluginWarning",
    "SpecError",
    "SpecWarning",
    "StateMappingError",
    "TrainingError",
    "UnknownFeature",
    "UnreachableGoal",
    "VersionMismatch",
]


class SpecError(Exception):
    """Base class of every error specguard raises on purpose.

    The message ends with a ``Hint:`` line: the one given, else the class's
    :attr:`default_hint` (every error about a user's mistake says what to try).

    Attributes:
        message: the message without its hint.
        hint: the hint shown, or None.
    """

    default_hint: str | None = None

    def __init__(self, message: str = "", hint: str | None = None) -> None:
        self.message = message
        if hint is None and "\nHint: " not in message:
            hint = self.default_hint
        self.hint = hint
        super().__init__(f"{message}\nHint: {hint}" if hint else message)

    def __reduce__(self) -> tuple[type, tuple[str | None, ...]]:
        # Raised in worker processes: must survive pickling with its hint.
        return type(self), (self.message, self.hint)


class InvalidSpec(SpecError, ValueError):
    """A goal tree node or annotation is malformed.

    Attributes:
        where: the node path (``"pendulum/position"``) or annotation
            (``"pendulum/position:distance"``) at fault.
    """

    default_hint = (
        "the message names the node or option at fault; the tables of docs/guide/language.md and "
        "docs/guide/training.md list what each one accepts"
    )

    def __init__(self, where: str, message: str, hint: str | None = None) -> None:
        self.where = where
        super().__init__(f"{where}: {message}", hint)
        self.message = message

    def __reduce__(self) -> tuple[type, tuple[str | None, ...]]:
        # Raised in training worker processes: must survive pickling.
        return type(self), (self.where, self.message, self.hint)


class UnknownFeature(InvalidSpec):
    """A goal or annotation names a feature the initial environment does not have."""


class UnreachableGoal(InvalidSpec):
    """A goal's box lies outside the known bounds of its features: no state can ever be in it.

    Also a root goal that must hold until the end (``Always``) and holds at no
    sampled start: every episode fails it before the agent acts.

    Raised before training (by ``make_env`` and ``make_baseline_env``), so a
    spec that could only train for nothing costs nothing. The message names
    the node path, the feature, the box and the bounds.
    """


class GoalMetAtStart(InvalidSpec):
    """The root goal holds at every sampled start of the env: the spec is met before the agent acts.

    The mirror of :class:`UnreachableGoal`, raised before training (by ``make_env``
    and ``make_baseline_env``, so at every door of ``run_spec``): reaching the root
    goal ends an episode, so an env that starts inside it gives one-step episodes
    and a verdict that passes whatever the policy does. The message names the
    goal and the share of sampled starts inside it.
    """


class SpecWarning(UserWarning):
    """A spec that trains, but may not test what it says (a goal met at some starts, or only at the bounds' edge).

    Issued before training, where the env is built; ``run_spec`` issues it once, in the caller's process. Also
    issued by ``sg.zoo_settings`` for rl-zoo3 settings a spec cannot take (it trains without them), and while
    training, in the run's process, for a callback of the spec's whose ``_on_step`` returned None (SB3 stops).
    Its location is the user's line (:func:`user_stacklevel`), not specguard's.
    """


def user_stacklevel() -> int:
    """The ``stacklevel`` for a warning of the calling function: the innermost frame outside ``specguard``.

    That is the user's line that called into specguard (``make_env``, ``run_spec``, ``Spec.as_run``,
    ``zoo_settings``), however many of specguard's frames lie between.
    """
    frame, level = sys._getframe(1), 1  # level 1: the function that warns
    while frame.f_back is not None and str(frame.f_globals.get("__name__", "")).startswith("specguard."):
        frame, level = frame.f_back, level + 1
    return level


class InitialEnvError(SpecError):
    """The initial environment cannot be built or does not fit its declaration."""

    default_hint = "build it alone with gymnasium.make(id, **kwargs) (or call your factory) to see the problem directly"


class StateMappingError(InitialEnvError):
    """``state()`` returned something that is not a feature vector of the declared length."""

    default_hint = "state(obs) must return one finite number per declared feature, in the order of features="


class EvaluationError(SpecError):
    """A user function (distance, constraint, ``state``) failed or returned a bad value during a step."""

    default_hint = (
        "a distance must return a finite number >= 0 and a constraint a truth value for every state the env can reach"
    )


class FingerprintError(InvalidSpec):
    """A value in a spec cannot be fingerprinted exactly, so its runs could not be cached safely."""


class VersionMismatch(SpecError):
    """The process that was to train a run has other code than the one that keyed it.

    A run's cache key names the versions of specguard (its source digest) and
    of the RL stack (:func:`specguard.cache.versions.versions`); a worker whose own
    differ (specguard's sources edited while runs were queued, a cluster worker
    with another library) would store a result under a key that does not
    describe the code that made it, so it refuses to train.
    """

    default_hint = (
        "finish editing first, then run again (a new key trains afresh); give cluster workers the same versions"
    )


class CacheWarning(UserWarning):
    """The run cache could not be used (written, locked or created): the trained results are kept, not cached.

    Issued once per spec, naming the path and the cause; the verdict never
    depends on the cache.
    """


class TrainingError(SpecError):
    """The environment or a user function failed while a run trained or was evaluated."""

    default_hint = "reproduce it without training: build sg.make_env(...) and step it from the seed named above"


class AgentError(SpecError):
    """An agent trained elsewhere cannot be loaded or acts wrongly: a path with no model, a zip that is no
    stable-baselines3 model, an algorithm or ``VecNormalize`` statistics that do not fit it, a callable that raised,
    or an action outside its action space (:func:`specguard.agents.sources.load_agent`).

    One line naming the culprit (the path, the file or the agent) and what was expected; an agent's own exception is
    chained (``raise ... from``).
    """

    default_hint = (
        "load_agent takes an SB3 or sb3-contrib .zip, an rl-zoo3 or Hugging Face Hub folder, an object with "
        "predict(obs, state, episode_start, deterministic), or a callable obs -> action"
    )


class AgentMismatch(AgentError):
    """An agent's spaces do not fit the env it is to act in (:func:`specguard.agents.agent.check_fits`), refused
    before any episode: the message names both spaces."""

    default_hint = "judge the agent in the env it was trained in (its env id and env_kwargs), or load the agent for it"


class NumericsError(SpecError):
    """A process cannot compute with the numerics a run asks for (:mod:`specguard.utils.numerics`): its environment
    lacks the portable settings, or its torch chose its kernels before they were held (read once, at the first
    computation)."""

    default_hint = (
        "start the process with the settings in its environment (a Dask worker: ATEN_CPU_CAPABILITY=default "
        "MKL_CBWR=COMPATIBLE ONEDNN_MAX_CPU_ISA=SSE41 GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-AVX512F,-FMA,-AVX dask "
        "worker ADDRESS), or run with numerics='native' (--numerics native, ini goal_specs_numerics = native) for "
        "machine-dependent results"
    )


class CacheLockTimeout(SpecError):
    """Another process held a run's lock for longer than the timeout."""


class ExecutorError(SpecError):
    """An executor address that is malformed, or a cluster that cannot be reached."""


class BaselineError(SpecError):
    """A stored baseline cannot be read."""


class PluginWarning(UserWarning):
    """An installed specguard plugin could not be loaded; its operators are unavailable."""


class GoalMissed(AssertionError):
    """A goal missed its threshold (the failure an ``xfail`` goal expects)."""


class RunsCrashed(AssertionError):
    """Runs of a spec crashed (a worker raised, was killed or died): its items fail, even a goal expected to miss.

    Not a :class:`GoalMissed`, so a goal's ``xfail`` (which expects a miss) does not take it for one.
    """
