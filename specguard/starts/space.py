"""Start spaces: the initial states a trained agent is falsified from, and how an env is put in one.

A verdict says how often an agent met its goals from the env's *default*
starts. A :class:`StartSpace` names other starts: per state variable a range
``(lo, hi)``. How a start is set depends on the env (:func:`setter_for`):

* the classic-control envs have built-in setters (:data:`BUILTIN_SETTERS`):
  CartPole ``x, v, theta, omega``; Pendulum ``theta, omega``; Acrobot
  ``theta1, theta2, omega1, omega2``; MountainCar and MountainCarContinuous
  ``position, velocity``. A range left out keeps the env's own reset range.
  Their physical parameters may be searched too (:attr:`Setter.parameters`:
  CartPole ``gravity, masscart, masspole, length, force_mag``; Pendulum
  ``g, m, l``; Acrobot ``link_length_1, link_length_2, link_mass_1,
  link_mass_2``; MountainCar ``force, gravity``; MountainCarContinuous
  ``power``); one left out keeps the env's own value;
* Gymnasium's MuJoCo envs (any ``MujocoEnv``) are set by their model's joints
  (:mod:`specguard.starts.joints`): a hinge or slide joint ``J`` gives ``J``
  and ``J_vel`` (InvertedPendulum: ``slider, hinge, slider_vel, hinge_vel``),
  set through ``set_state``. They have no default range: a variable left out
  keeps what the env's reset gave, and a space naming none searches the
  env's reset seeds;
* any env: the hook ``set_state(env, values)`` (``values`` by name; it sets
  the state of ``env.unwrapped`` and returns the observation of that state),
  or ``reset_options=True``: the values are passed as ``reset(options=values)``;
* an env whose state cannot be set (LunarLander) is searched over its reset
  seeds instead (:attr:`Starts.how` says so).

Every range is checked against the variable's bounds, and every name against
the setter's: an unknown name or a range outside the bounds is an
:class:`~specguard.error.InvalidSpec` naming the values.

Example:
    >>> import gymnasium as gym
    >>> space = StartSpace({"x": (-1.0, 1.0), "theta": (-0.1, 0.1)})
    >>> starts = space.resolve(gym.make("CartPole-v1"))
    >>> starts.names, starts.how
    (('x', 'v', 'theta', 'omega'), 'state')
    >>> starts.low.tolist(), starts.high.tolist()
    ([-1.0, -0.05, -0.1, -0.05], [1.0, 0.05, 0.1, 0.05])
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from specguard.error import InvalidSpec, UnknownFeature
from specguard.starts.joints import joint_setter
from specguard.starts.setter import Range, Setter, env_label
from specguard.validation import check_finite, check_flag, check_text

__all__ = [
    "BUILTIN_SETTERS",
    "SEED_RANGE",
    "Setter",
    "StartSpace",
    "StartWrapper",
    "Starts",
    "as_start_space",
    "setter_for",
    "start_variables",
    "starts_of",
]

SEED_RANGE: Range = (0.0, float(2**31 - 1))
"""The reset seeds searched for an env whose state cannot be set."""
START_OPTION = "specguard_start"
"""The ``reset(options=...)`` key under which :class:`StartWrapper` receives a start."""


def _settle_cartpole(u: Any) -> None:
    u.total_mass = u.masspole + u.masscart
    u.polemass_length = u.masspole * u.length


def _set_cartpole(env: gym.Env, v: Mapping[str, float]) -> Any:
    u: Any = env.unwrapped
    u.state = np.array([v["x"], v["v"], v["theta"], v["omega"]], dtype=np.float64)
    u.steps_beyond_terminated = None
    return np.array(u.state, dtype=np.float32)


def _set_pendulum(env: gym.Env, v: Mapping[str, float]) -> Any:
    u: Any = env.unwrapped
    u.state = np.array([v["theta"], v["omega"]], dtype=np.float64)
    u.last_u = None
    return u._get_obs()


def _set_acrobot(env: gym.Env, v: Mapping[str, float]) -> Any:
    u: Any = env.unwrapped
    u.state = np.array([v["theta1"], v["theta2"], v["omega1"], v["omega2"]], dtype=np.float64)
    return u._get_ob()


def _set_mountain_car(env: gym.Env, v: Mapping[str, float]) -> Any:
    u: Any = env.unwrapped
    u.state = np.array([v["position"], v["velocity"]], dtype=np.float64)
    return np.array(u.state, dtype=np.float32)


_INF = math.inf
_MOUNTAIN_CAR = Setter(
    names=("position", "velocity"),
    bounds={"position": (-1.2, 0.6), "velocity": (-0.07, 0.07)},
    default={"position": (-0.6, -0.4), "velocity": (0.0, 0.0)},
    apply=_set_mountain_car,
    parameters={"force": "force", "gravity": "gravity"},
)
_MOUNTAIN_CAR_CONTINUOUS = dataclasses.replace(_MOUNTAIN_CAR, parameters={"power": "power"})
BUILTIN_SETTERS: Mapping[str, Setter] = {
    "CartPoleEnv": Setter(
        names=("x", "v", "theta", "omega"),
        bounds={"x": (-4.8, 4.8), "v": (-_INF, _INF), "theta": (-0.41887903, 0.41887903), "omega": (-_INF, _INF)},
        default={name: (-0.05, 0.05) for name in ("x", "v", "theta", "omega")},
        apply=_set_cartpole,
        parameters={n: n for n in ("gravity", "masscart", "masspole", "length", "force_mag")},
        settle=_settle_cartpole,
    ),
    "PendulumEnv": Setter(
        names=("theta", "omega"),
        bounds={"theta": (-math.pi, math.pi), "omega": (-8.0, 8.0)},
        default={"theta": (-math.pi, math.pi), "omega": (-1.0, 1.0)},
        apply=_set_pendulum,
        parameters={"g": "g", "m": "m", "l": "l"},
    ),
    "AcrobotEnv": Setter(
        names=("theta1", "theta2", "omega1", "omega2"),
        bounds={
            "theta1": (-math.pi, math.pi),
            "theta2": (-math.pi, math.pi),
            "omega1": (-4 * math.pi, 4 * math.pi),
            "omega2": (-9 * math.pi, 9 * math.pi),
        },
        default={name: (-0.1, 0.1) for name in ("theta1", "theta2", "omega1", "omega2")},
        apply=_set_acrobot,
        parameters={n: n.upper() for n in ("link_length_1", "link_length_2", "link_mass_1", "link_mass_2")},
    ),
    "MountainCarEnv": _MOUNTAIN_CAR,
    "Continuous_MountainCarEnv": _MOUNTAIN_CAR_CONTINUOUS,
}
"""The built-in setters, by the class name of the env's ``unwrapped``."""


def setter_for(env: gym.Env) -> Setter | None:
    """The built-in setter of ``env`` (by its unwrapped class; a MuJoCo env's by its joints), or ``None``.

    ``None``: the env's state cannot be set.
    """
    builtin = BUILTIN_SETTERS.get(type(env.unwrapped).__name__)
    return builtin if builtin is not None else joint_setter(env)


def start_variables(env: gym.Env) -> tuple[str, ...]:
    """The names a start space may give ranges for on ``env``: its state variables, then its physical
    parameters; ``()`` where its state cannot be set (a hook's names are its own).

    Example:
        >>> start_variables(gym.make("Pendulum-v1"))
        ('theta', 'omega', 'g', 'm', 'l')
    """
    setter = setter_for(env)
    return () if setter is None else (*setter.names, *setter.parameters)


# -- checks: each a small named function, raising with the actual values ------------------------------


def check_range(where: str, name: str, value: object) -> Range:
    """A range ``(lo, hi)``: a pair (tuple, list or array) of finite numbers with ``lo <= hi``.

    Never coerced: ``("0", "1")``, ``(False, True)`` and the string ``"01"`` are refused, naming the value.
    """
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)) or len(value) != 2:
        raise InvalidSpec(where, f"the range of {name!r} must be a pair (lo, hi) of numbers, got {value!r}")
    lo = check_finite(where, f"the low end of {name!r}", value[0])
    hi = check_finite(where, f"the high end of {name!r}", value[1])
    if lo > hi:
        raise InvalidSpec(where, f"the range of {name!r} must be finite with lo <= hi, got ({lo!r}, {hi!r})")
    return lo, hi


def check_known(where: str, names: Mapping[str, Any], known: tuple[str, ...]) -> None:
    """Every name of a start space is a variable the setter knows."""
    unknown = [n for n in names if n not in known]
    if unknown:
        raise UnknownFeature(
            where,
            f"the start space names {', '.join(map(repr, unknown))}, which its setter does not know; "
            f"known: {', '.join(known)}",
            hint="docs/guide/falsify.md, 'The start space', says which variables each env has",
        )


def check_parameter(where: str, name: str, rng: Range) -> None:
    """A physical parameter's range lies above 0 (a mass, a length, a force)."""
    if rng[0] <= 0:
        raise InvalidSpec(
            where, f"the range of the parameter {name!r} is ({rng[0]:g}, {rng[1]:g}): expected values > 0"
        )


def check_within(where: str, name: str, rng: Range, bounds: Range) -> None:
    """A range lies within the variable's bounds."""
    if rng[0] < bounds[0] or rng[1] > bounds[1]:
        raise InvalidSpec(
            where,
            f"the range of {name!r} is ({rng[0]:g}, {rng[1]:g}), outside its bounds ({bounds[0]:g}, {bounds[1]:g})",
            hint="a start must be a state the env can be in: narrow the range",
        )


# -- the declaration ------------------------------------------------------------------------------


@dataclass(frozen=True, init=False)
class StartSpace:
    """Per state variable, the range of the initial states to falsify a trained agent from.

    Args:
        ranges: ``{variable: (lo, hi)}``; variables left out keep the env's
            own reset range (built-in setters only; a MuJoCo env's keep what its reset gave).
        set_state: ``set_state(env, values) -> observation``: the hook for an
            env without a built-in setter; ``values`` by name.
        reset_options: pass the values as ``env.reset(options=values)`` instead.

    Raises:
        InvalidSpec: a name that is not a non-empty string, a range that is not a pair
            of finite numbers ``lo <= hi`` (text and bools are refused, never coerced),
            ``reset_options`` that is not a bool, or both hooks given.
    """

    ranges: tuple[tuple[str, float, float], ...]
    set_state: Callable[[gym.Env, Mapping[str, float]], Any] | None
    reset_options: bool

    def __init__(
        self,
        ranges: Mapping[str, tuple[float, float]] | None = None,
        *,
        set_state: Callable[[gym.Env, Mapping[str, float]], Any] | None = None,
        reset_options: bool = False,
    ) -> None:
        where = "StartSpace"
        if ranges is not None and not isinstance(ranges, Mapping):
            raise InvalidSpec(where, f"expected ranges as {{variable: (lo, hi)}}, got {ranges!r}")
        if set_state is not None and not callable(set_state):
            raise InvalidSpec(where, f"expected set_state to be callable (env, values) -> obs, got {set_state!r}")
        reset_options = check_flag(where, "reset_options", reset_options)
        if set_state is not None and reset_options:
            raise InvalidSpec(where, "give set_state or reset_options=True, not both")
        names = [check_text(where, "a variable's name", n) for n in (ranges or {})]
        parsed = tuple((n, *check_range(where, n, r)) for n, r in zip(names, (ranges or {}).values(), strict=True))
        object.__setattr__(self, "ranges", parsed)
        object.__setattr__(self, "set_state", set_state)
        object.__setattr__(self, "reset_options", reset_options)

    def describe(self) -> str:
        """Exact text of the space (part of the key its counterexamples are stored under)."""
        hook = getattr(self.set_state, "__qualname__", None)
        ranges = ", ".join(f"{n}=({lo!r}, {hi!r})" for n, lo, hi in self.ranges)
        return f"StartSpace({ranges}; set_state={hook}; reset_options={self.reset_options})"

    def resolve(self, env: gym.Env) -> Starts:
        """The space over ``env``'s variables, checked against its setter's names and bounds.

        Raises:
            UnknownFeature: a name the built-in setter does not know.
            InvalidSpec: a range outside its variable's bounds; ranges for an
                env whose state cannot be set; no ranges with a hook.
        """
        where = f"StartSpace for {env_label(env)}"
        declared = {n: (lo, hi) for n, lo, hi in self.ranges}
        if self.set_state is not None or self.reset_options:
            if not declared:
                raise InvalidSpec(where, "a set_state hook or reset_options=True needs the ranges of its variables")
            names = tuple(declared)
            how = "reset options" if self.reset_options else "state"
            apply = self.set_state
            return Starts(where, names, _array(declared, names, 0), _array(declared, names, 1), how, apply)
        setter = setter_for(env)
        if setter is None:
            if declared:
                raise InvalidSpec(
                    where,
                    f"its state cannot be set (no built-in setter for {type(env.unwrapped).__name__}), "
                    f"yet the start space gives ranges for {', '.join(declared)}",
                    hint="pass set_state=fn(env, values) or reset_options=True, or no ranges to search reset seeds",
                )
            return _seeds(where, "its state cannot be set")
        check_known(where, declared, (*setter.names, *setter.parameters))
        params = tuple(n for n in setter.parameters if n in declared)
        for name, rng in declared.items():
            if name in params:
                check_parameter(where, name, rng)
            else:
                check_within(where, name, rng, setter.bounds[name])
        kept = tuple(n for n in setter.names if n in declared or n in setter.default)
        full = {n: declared[n] if n in declared else setter.default[n] for n in kept}
        full |= {n: declared[n] for n in params}
        names = (*kept, *params)
        if not names:  # no default ranges (a MuJoCo env) and none given: the env's own starts, by reset seed
            return _seeds(where, "no ranges were given for its variables")
        apply = setter.with_parameters(params)
        return Starts(where, names, _array(full, names, 0), _array(full, names, 1), "state", apply)


def _seeds(where: str, why: str) -> Starts:
    seeds = {"seed": SEED_RANGE}
    return Starts(where, ("seed",), _array(seeds, ("seed",), 0), _array(seeds, ("seed",), 1), "reset seeds", why=why)


def _array(ranges: Mapping[str, Range], names: tuple[str, ...], side: int) -> np.ndarray:
    return np.array([ranges[n][side] for n in names], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Starts:
    """A start space resolved for one env: its variables, their ranges and how a start is set.

    Attributes:
        where: the env, for messages.
        names, low, high: the variables and their ranges.
        how: ``"state"`` (a setter), ``"reset options"`` or ``"reset seeds"``
            (the env's state cannot be set: its reset seeds are searched).
        apply: the setter or hook (``None`` for reset options and seeds).
        why: for reset seeds, why they are searched (for :attr:`note`).
    """

    where: str
    names: tuple[str, ...]
    low: np.ndarray
    high: np.ndarray
    how: str
    apply: Callable[[gym.Env, Mapping[str, float]], Any] | None = None
    why: str = ""

    @property
    def center(self) -> np.ndarray:
        """The middle of every range: the simplest start, which shrinking moves towards."""
        return np.asarray((self.low + self.high) / 2.0, dtype=np.float64)

    @property
    def note(self) -> str:
        """One line saying how starts are set, for progress lines and reports."""
        if self.how == "reset seeds":
            return f"{self.where}: {self.why or 'its state cannot be set'}, so reset seeds are searched instead"
        return f"{self.where}: starts set by {self.how} over {', '.join(self.names)}"

    def values(self, point: np.ndarray) -> dict[str, float]:
        """A point of the space by variable name (a seed as an int)."""
        if self.how == "reset seeds":
            return {"seed": int(point[0])}
        return {n: float(v) for n, v in zip(self.names, point, strict=True)}

    def uniform(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` points drawn uniformly from the space (rows)."""
        if self.how == "reset seeds":
            return rng.integers(int(self.low[0]), int(self.high[0]), size=(n, 1)).astype(np.float64)
        return rng.uniform(self.low, self.high, size=(n, len(self.names)))

    def wrap(self, env: gym.Env) -> StartWrapper:
        """``env`` wrapped so that ``reset(options={START_OPTION: values})`` starts from ``values``."""
        return StartWrapper(env, self)


class StartWrapper(gym.Wrapper[Any, Any, Any, Any]):
    """Resets its env, then puts it in the start passed as ``options[START_OPTION]`` (if any).

    The env factory puts it around the base env when an env is made with a start space
    (``make_env(..., starts=space)``), under the constructed env: :func:`starts_of` finds it.
    """

    def __init__(self, env: gym.Env, starts: Starts) -> None:
        super().__init__(env)
        self.starts = starts

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        options = dict(options or {})
        values = options.pop(START_OPTION, None)
        if values is None:
            return self.env.reset(seed=seed, options=options or None)
        how = self.starts.how
        if how == "reset seeds":
            return self.env.reset(seed=int(values["seed"]), options=options or None)
        if how == "reset options":
            return self.env.reset(seed=seed, options={**options, **values})
        _, info = self.env.reset(seed=seed, options=options or None)
        assert self.starts.apply is not None
        return self.starts.apply(self.env, values), info


def starts_of(env: gym.Env) -> Starts:
    """The start space ``env`` was made with (``make_env(..., starts=space)``), resolved: its :class:`StartWrapper`'s.

    Raises:
        InvalidSpec: no wrapper of ``env`` is a :class:`StartWrapper`: it was made without a start space.

    Example:
        >>> import specguard as sg
        >>> line = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
        >>> env = sg.make_env(line, sg.Goal("right", x=(1.0, None)), starts=StartSpace({"x": (-1.0, 1.0)}))
        >>> starts_of(env).names
        ('x', 'v', 'theta', 'omega')
    """
    inner: Any = env
    while isinstance(inner, gym.Wrapper):
        if isinstance(inner, StartWrapper):
            return inner.starts
        inner = inner.env
    raise InvalidSpec(
        env_label(env),
        f"the env has no StartWrapper among its wrappers ({type(env).__name__} over {type(env.unwrapped).__name__}): "
        "it was made without a start space",
        hint="make it with make_env(..., starts=space)",
    )


def as_start_space(where: str, value: object) -> StartSpace | None:
    """A declared start space: ``None``, a :class:`StartSpace` or its ranges ``{name: (lo, hi)}``.

    Raises:
        InvalidSpec: naming ``where`` and the value given.
    """
    if value is None or isinstance(value, StartSpace):
        return value
    if not isinstance(value, Mapping):
        raise InvalidSpec(where, f"expected starts to be a StartSpace or {{name: (lo, hi)}}, got {value!r}")
    return StartSpace(dict(value))
