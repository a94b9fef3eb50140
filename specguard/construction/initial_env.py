"""The initial environment ``(S*, A*, P*)`` and its mappings.

Their semantics: docs/semantics.md, "Features and the initial environment".

An :class:`InitialEnv` names a Gymnasium env (by id or factory), the features
of the goal state space ``S_G`` and the two mappings ``state: S* -> S_G`` and
``execute: A_G -> A*``. It builds nothing until :meth:`InitialEnv.make` is
called, so declaring one is cheap (pytest fixtures, module constants).

Example:
    >>> import specguard as sg
    >>> pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    >>> pendulum
    InitialEnv('Pendulum-v1', features=('x', 'y', 'omega'))
"""

from __future__ import annotations

import keyword
import math
from collections import namedtuple
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from numbers import Integral, Real
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec

from specguard.error import InitialEnvError, StateMappingError
from specguard.utils.imports import ImportFailed, import_module
from specguard.utils.text import MAX_SHOWN, elide, shown

__all__ = ["InitialEnv", "check_identity_observation", "read_env_features", "registered_spec", "state_type"]


@cache
def state_type(features: tuple[str, ...]) -> Any:
    """The namedtuple class that user functions receive as ``s`` (``s.x`` by feature name).

    One class per feature tuple, so building a state each step costs one
    ``_make`` call. In batch evaluation each attribute holds a column array.
    """
    return namedtuple("State", features)  # type: ignore[misc]


def _check_features(features: object, others: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The observation's feature names, then ``others`` (``from_info``'s and ``from_env``'s): all the features."""
    if isinstance(features, str) or not isinstance(features, Sequence) or not (features or others):
        raise InitialEnvError(
            f"InitialEnv features: expected a non-empty sequence of feature names, got {features!r}"
            + (" (and no from_info= or from_env= features)" if not others else "")
        )
    features = (*features, *others)
    for f in features:
        if not isinstance(f, str) or not f.isidentifier() or keyword.iskeyword(f) or f.startswith("_"):
            raise InitialEnvError(
                f"InitialEnv features: {f!r} is not a usable feature name; expected a Python "
                "identifier that is not a keyword and does not start with '_' (goals name it as s.<name>)"
            )
    dup = sorted({f for f in features if list(features).count(f) > 1})
    if dup:
        raise InitialEnvError(f"InitialEnv features: names must be unique, {dup} appear more than once")
    return tuple(features)


def check_identity_observation(where: str, features: tuple[str, ...], space: gym.Space[Any]) -> None:
    """With the identity ``state()``, the features label the observation's components one to one.

    Raises:
        StateMappingError: ``space`` is not a flat ``Box`` with one component per feature.
    """
    n = len(features)
    if isinstance(space, gym.spaces.Box) and space.shape == (n,):
        return
    if isinstance(space, gym.spaces.Box) and len(space.shape) == 1:
        size = space.shape[0]
        seen = f"the observation has {size} components"
        hint = f"name exactly {size} features, or compute the features in state=... (InitialEnv's third argument)"
    elif isinstance(space, gym.spaces.Box) and int(np.prod(space.shape)) == n:
        seen = f"the observation space is {space} of shape {space.shape}"
        hint = "flatten the observation in state=lambda o: o.ravel()"
    else:
        seen = f"the observation space is {space}"
        hint = "compute the features in state=... (InitialEnv's third argument), e.g. from the observation's parts"
    raise StateMappingError(
        f"{where}: the identity state() needs a flat Box observation of {n} features {features}, "
        f"one per component, but {seen}\nHint: {hint}"
    )


def _check_from_info(label: str, from_info: object) -> tuple[tuple[str, str], ...]:
    """``from_info`` as ``((feature, info key), ...)``: ``{feature: key}``, or keys that name their features."""
    if from_info is None:
        return ()
    if isinstance(from_info, Mapping):
        pairs = list(from_info.items())
    elif isinstance(from_info, Sequence) and not isinstance(from_info, str):
        pairs = [(k, k) for k in from_info]
    else:
        raise InitialEnvError(
            f"InitialEnv {label}: from_info: expected {{feature: info key}} or a sequence of info keys, "
            f"got {from_info!r}"
        )
    for feature, key in pairs:
        if not isinstance(key, str) or not key:
            raise InitialEnvError(
                f"InitialEnv {label}: from_info: expected feature {feature!r} to name an info key (a string), "
                f"got {key!r}"
            )
    return tuple(pairs)


def _check_from_env(label: str, from_env: object) -> tuple[tuple[str, Callable[[Any], Any]], ...]:
    """``from_env`` as ``((feature, fn), ...)``, each ``fn`` callable as ``fn(env.unwrapped)``."""
    if from_env is None:
        return ()
    if not isinstance(from_env, Mapping):
        raise InitialEnvError(f"InitialEnv {label}: from_env: expected {{feature: fn(env)}}, got {from_env!r}")
    for feature, fn in from_env.items():
        if not callable(fn):
            raise InitialEnvError(
                f"InitialEnv {label}: from_env: expected feature {feature!r} to be callable as fn(env.unwrapped), "
                f"got {fn!r}"
            )
    return tuple(from_env.items())


def _feature_value(where: str, feature: str, source: str, value: object, when: str) -> float:
    """A value read for a feature as a float: a finite real number (one a float holds) or a bool (numpy's too)."""
    if isinstance(value, (bool, np.bool_)):
        return float(value)
    if isinstance(value, Real):
        try:
            number = float(value)
        except OverflowError:  # an int (or Fraction) past a float's range
            number = math.inf
        if math.isfinite(number):
            return number
    raise StateMappingError(
        f"{where}: feature {feature!r} {source} {_value_text(value)} {when}: expected a finite real number or a bool",
        hint="a feature is one number; read a part of a composite value with from_env=fn(env) or state(obs)",
    )


def _value_text(value: object) -> str:
    """A refused value for a message, bounded; an int (refused only past a float's range) by its digits, as Python
    refuses the repr of one past 4300 digits."""
    if isinstance(value, Integral):
        digits = math.floor(int(value).bit_length() * math.log10(2)) + 1
        return f"an int of about {digits} digits, past a float's range,"
    return shown(value)


def read_env_features(
    where: str,
    from_info: tuple[tuple[str, str], ...],
    from_env: tuple[tuple[str, Callable[[Any], Any]], ...],
    info: Mapping[str, Any],
    env: gym.Env,
    step: int,
) -> list[float]:
    """The features read from ``info`` and from ``env.unwrapped``, in declaration order.

    Args:
        where: the tree or env, for messages.
        from_info, from_env: :attr:`InitialEnv.from_info` and :attr:`InitialEnv.from_env`.
        info: the base env's ``info`` of this reset or step.
        env: the base env (its ``unwrapped`` is what ``from_env``'s functions receive).
        step: the steps since the reset (0: the reset itself), for messages.

    Raises:
        StateMappingError: a missing ``info`` key, a function that raised, or a value that is not a
            finite real number or a bool, naming the feature and ``when``.
    """
    when = f"at step {step}" if step else "at reset"
    out = []
    for feature, key in from_info:
        if key not in info:
            raise StateMappingError(
                f"{where}: feature {feature!r} reads info[{key!r}], but the info {when} has no such key "
                f"(its keys: {', '.join(map(repr, info)) or 'none'})",
                hint="check the key against the env's documentation, or read the value with from_env=fn(env)",
            )
        out.append(_feature_value(where, feature, f"reads info[{key!r}] =", info[key], when))
    if from_env:
        unwrapped = env.unwrapped
        for feature, fn in from_env:
            try:
                value = fn(unwrapped)
            except Exception as e:
                raise StateMappingError(
                    f"{where}: feature {feature!r} reads from_env[{feature!r}](env), which raised "
                    f"{type(e).__name__}: {e} {when} "
                    f"(it receives the unwrapped env, a {type(unwrapped).__name__})",
                    hint="from_env={feature: fn} calls fn(env.unwrapped) after every reset and step",
                ) from e
            out.append(_feature_value(where, feature, f"reads from_env[{feature!r}](env) =", value, when))
    return out


def registered_spec(env_id: str) -> EnvSpec:
    """The ``EnvSpec`` that ``gymnasium.make(env_id)`` would build, read from the registry of this process.

    ``env_id`` is a registered id (``"Pendulum-v1"``) or Gymnasium's ``"module:Id"``, whose module is
    imported first (it registers the id), as ``gymnasium.make`` does.

    Example:
        >>> registered_spec("gymnasium.envs.classic_control:Pendulum-v1").entry_point
        'gymnasium.envs.classic_control.pendulum:PendulumEnv'

    Raises:
        InitialEnvError: the module cannot be imported (an empty or relative name, or importing it raised or
            tried to end the process), or the id is not registered.
    """
    module, colon, name = env_id.rpartition(":")
    if colon:
        try:
            import_module(module)
        except ImportFailed as e:  # an empty or relative name, or the module's own code failing or exiting
            raise InitialEnvError(
                f"InitialEnv {shown(env_id)}: cannot import its module: {e}",
                hint="'module:Id' imports the module that registers Id (an absolute name, installed and importable "
                "here), as gymnasium.make does",
            ) from None
    try:
        return gym.spec(name)
    except gym.error.Error as e:
        where = f" after importing {shown(module)}" if module else ""
        raise InitialEnvError(
            f"InitialEnv {shown(env_id)}: no such Gymnasium environment id{where} ({elide(str(e), MAX_SHOWN)})",
            hint="import the package that registers it in the spec module, or write 'package:Id'",
        ) from None


@dataclass(frozen=True, init=False)
class InitialEnv:
    """An initial environment with named features.

    Args:
        env: a registered Gymnasium env id (``"Pendulum-v1"``; ``"module:Id"``
            imports ``module`` first, as ``gymnasium.make`` does) or a factory
            returning a ``gymnasium.Env``. An id is looked up in Gymnasium's
            registry here, so one that a package registers on import (after
            ``import minigrid`` in the spec module) builds in every process.
        features: the names of the features ``state`` computes from the
            observation, in order (may be empty when ``from_info`` or
            ``from_env`` give every feature).
        state: ``state(obs) -> feature vector``; ``None`` for the identity,
            in which case the names label the observation's components.
        from_info: features read from the base env's ``info`` after every
            reset and step: ``{feature: info key}``, or a sequence of keys
            that name their features (``("crashed",)``). A bool counts as
            0 or 1.
        from_env: features read from the env itself: ``{feature: fn}``, with
            ``fn(env.unwrapped)`` called after every reset and step (e.g.
            ``lambda env: env.agent_pos[0]``).
        execute: ``execute(action) -> base action``; ``None`` for the identity.
        bounds: ``{feature: (lo, hi)}`` for features whose range is known but
            not given by the base observation space (e.g. a feature computed
            by ``state`` or read by ``from_info`` or ``from_env``); others
            default to the base space (identity ``state``) or to an unbounded
            interval.
        action_space: the agent's action space ``A_G`` when ``execute`` changes
            it; defaults to the base env's action space.
        **make_kwargs: keyword arguments for ``gymnasium.make`` (or the factory).

    The features are those of ``state``, then ``from_info``'s, then
    ``from_env``'s, in that order: :attr:`features` names them all, the goals
    name any of them, and the constructed env's observation carries them all,
    so it stays Markov when the observation alone would not be.

    Raises:
        InitialEnvError: an unknown env id, bad feature names, or a mapping
            that is not callable.

    Example:
        >>> import specguard as sg
        >>> cart = sg.InitialEnv(
        ...     "CartPole-v1",
        ...     features=("x", "v", "theta", "omega"),
        ...     from_env={"steps": lambda env: env.steps_beyond_terminated or 0},
        ... )
        >>> cart.features
        ('x', 'v', 'theta', 'omega', 'steps')
    """

    env: str | Callable[..., gym.Env]
    features: tuple[str, ...]
    """Every feature: ``state``'s (:attr:`observed`), then ``from_info``'s, then ``from_env``'s."""
    state: Callable[[Any], Any] | None
    execute: Callable[[Any], Any] | None
    bounds: tuple[tuple[str, float, float], ...]
    action_space: gym.Space[Any] | None
    observed: tuple[str, ...] = ()
    """The features ``state`` computes from the observation (the identity: its components)."""
    from_info: tuple[tuple[str, str], ...] = ()
    """``(feature, info key)`` per feature read from ``info``."""
    from_env: tuple[tuple[str, Callable[[Any], Any]], ...] = ()
    """``(feature, fn)`` per feature read as ``fn(env.unwrapped)``."""
    make_kwargs: Mapping[str, Any] = field(default_factory=dict)
    registered: EnvSpec | None = None
    """The id's ``EnvSpec``, taken from Gymnasium's registry where the ``InitialEnv`` was made (None for a factory).

    Every process builds the env from it (``gymnasium.make`` accepts an ``EnvSpec``), so an id that a package
    registers on import builds in processes that never imported the package: training workers, cluster
    workers, the falsifier. It is part of the spec's identity: the entry point, kwargs and episode limit
    that the id names.
    """

    def __init__(
        self,
        env: str | Callable[..., gym.Env],
        features: Sequence[str] = (),
        state: Callable[[Any], Any] | None = None,
        execute: Callable[[Any], Any] | None = None,
        *,
        from_info: Mapping[str, str] | Sequence[str] | None = None,
        from_env: Mapping[str, Callable[[Any], Any]] | None = None,
        bounds: Mapping[str, tuple[float, float]] | None = None,
        action_space: gym.Space[Any] | None = None,
        **make_kwargs: Any,
    ) -> None:
        if isinstance(env, str):
            registered: EnvSpec | None = registered_spec(env)
        elif not callable(env):
            raise InitialEnvError(f"InitialEnv: expected an env id or a factory returning a gymnasium.Env, got {env!r}")
        else:
            registered = None
        info_pairs = _check_from_info(self._label(env), from_info)
        env_pairs = _check_from_env(self._label(env), from_env)
        names = _check_features(features, tuple(f for f, _ in (*info_pairs, *env_pairs)))
        observed = names[: len(names) - len(info_pairs) - len(env_pairs)]
        if state is not None and not observed:
            raise InitialEnvError(
                f"InitialEnv {self._label(env)}: state is given but features= names no features for it to compute",
                hint="name state()'s features in features=, or leave state out when from_info/from_env give them all",
            )
        for label, fn in (("state", state), ("execute", execute)):
            if fn is not None and not callable(fn):
                raise InitialEnvError(f"InitialEnv {self._label(env)}: expected {label} to be callable, got {fn!r}")
        if action_space is not None and not isinstance(action_space, gym.spaces.Space):
            raise InitialEnvError(
                f"InitialEnv {self._label(env)}: expected action_space to be a gymnasium Space, got {action_space!r}"
            )
        parsed_bounds = []
        for f, b in (bounds or {}).items():
            if f not in names:
                raise InitialEnvError(
                    f"InitialEnv {self._label(env)}: bounds name unknown feature {f!r}; "
                    f"known features: {', '.join(names)}"
                )
            try:
                lo, hi = (float(v) for v in b)
            except (TypeError, ValueError):
                raise InitialEnvError(
                    f"InitialEnv {self._label(env)}: bounds for {f!r} must be a pair (lo, hi), got {b!r}"
                ) from None
            if math.isnan(lo) or math.isnan(hi) or lo > hi:
                raise InitialEnvError(
                    f"InitialEnv {self._label(env)}: bounds for {f!r} must satisfy lo <= hi, got {b!r}"
                )
            parsed_bounds.append((f, lo, hi))
        object.__setattr__(self, "env", env)
        object.__setattr__(self, "features", names)
        object.__setattr__(self, "observed", observed)
        object.__setattr__(self, "from_info", info_pairs)
        object.__setattr__(self, "from_env", env_pairs)
        object.__setattr__(self, "state", state)
        object.__setattr__(self, "execute", execute)
        object.__setattr__(self, "bounds", tuple(parsed_bounds))
        object.__setattr__(self, "action_space", action_space)
        object.__setattr__(self, "make_kwargs", dict(make_kwargs))
        object.__setattr__(self, "registered", registered)

    @staticmethod
    def _label(env: object) -> str:
        return repr(env) if isinstance(env, str) else getattr(env, "__qualname__", repr(env))

    @property
    def label(self) -> str:
        """The env id, or the factory's name."""
        return self._label(self.env)

    def make(self, **overrides: Any) -> gym.Env:
        """Build the base environment (``gymnasium.make`` for an id).

        Raises:
            InitialEnvError: the env cannot be built (e.g. a missing optional
                dependency such as ``box2d``), with Gymnasium's message.
        """
        kwargs = {**self.make_kwargs, **overrides}
        try:
            if isinstance(self.env, str):  # from the registration taken where the InitialEnv was made
                return gym.make(self.registered if self.registered is not None else self.env, **kwargs)
            built = self.env(**kwargs)
        except gym.error.DependencyNotInstalled as e:
            raise InitialEnvError(
                f"InitialEnv {self.label}: a dependency is missing ({e}); "
                'for Box2D envs such as LunarLander install "gymnasium[box2d]"'
            ) from e
        except Exception as e:  # the factory, or gymnasium.make with a keyword the env does not take
            how = "gymnasium.make" if isinstance(self.env, str) else "its factory"
            raise InitialEnvError(
                f"InitialEnv {self.label}: building it with {how}"
                + (f" and {kwargs}" if kwargs else "")
                + f" raised {type(e).__name__}: {e}"
            ) from e
        if not isinstance(built, gym.Env):
            raise InitialEnvError(
                f"InitialEnv {self.label}: the factory returned {type(built).__name__}, expected a gymnasium.Env"
            )
        return built

    def check_observation_space(self, observation_space: gym.Space[Any]) -> None:
        """Check that the features fit the base env's observations (only the identity ``state`` can be checked).

        Raises:
            StateMappingError: with the identity ``state``, the observation
                space is not a flat ``Box`` with one component per feature.
        """
        if self.state is None and self.observed:
            check_identity_observation(f"InitialEnv {self.label}", self.observed, observation_space)

    def feature_bounds(self, observation_space: gym.Space[Any]) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of every feature, finite wherever they are known.

        Raises:
            StateMappingError: see :meth:`check_observation_space`.
        """
        self.check_observation_space(observation_space)
        n = len(self.features)
        lo = np.full(n, -np.inf)
        hi = np.full(n, np.inf)
        m = len(self.observed)
        if self.state is None and m and isinstance(observation_space, gym.spaces.Box):
            lo[:m] = observation_space.low
            hi[:m] = observation_space.high
        index = {f: i for i, f in enumerate(self.features)}
        for f, b_lo, b_hi in self.bounds:
            lo[index[f]], hi[index[f]] = b_lo, b_hi
        return lo, hi

    def __repr__(self) -> str:
        extra = "".join(
            f", {k}={getattr(v, '__qualname__', v)!s}"
            for k, v in (("state", self.state), ("execute", self.execute))
            if v is not None
        )
        if self.from_info:
            extra += f", from_info={dict(self.from_info)!r}"
        if self.from_env:
            fns = ", ".join(f"{f!r}: {getattr(fn, '__qualname__', fn)!s}" for f, fn in self.from_env)
            extra += f", from_env={{{fns}}}"
        kwargs = "".join(f", {k}={v!r}" for k, v in self.make_kwargs.items())
        return f"InitialEnv({self.label}, features={self.observed!r}{extra}{kwargs})"
