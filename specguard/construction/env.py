"""The constructed environment: a Gymnasium wrapper built from a goal tree (docs/semantics.md, "The construction").

:class:`SpecEnv` takes the base env as its first argument and records its
other constructor arguments, so ``env.spec`` re-creates it the Gymnasium way
(``gym.make(env.spec)``, ``check_env``, ``make_vec_env``, ``SubprocVecEnv``).

Example:
    >>> import numpy as np
    >>> import specguard as sg
    >>> pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    >>> tree = sg.All(
    ...     sg.Goal("position", x=(0.966, 1.0), y=(-0.259, 0.259)),
    ...     sg.Goal("stabilization", omega=(-0.25, 0.25)),
    ...     name="pendulum",
    ... )
    >>> env = sg.make_env(pendulum, tree)
    >>> obs, info = env.reset(seed=0)
    >>> obs, reward, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
    >>> sorted(info["goals"])
    ['pendulum', 'pendulum/position', 'pendulum/stabilization']
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from copy import deepcopy
from typing import Any, Literal, SupportsFloat, cast

import gymnasium as gym
import numpy as np
from gymnasium.utils import RecordConstructorArgs

from specguard.construction.cap import capped
from specguard.construction.compiled import CompiledTree, compile_tree
from specguard.construction.evaluator import Evaluator
from specguard.construction.initial_env import InitialEnv, check_identity_observation, read_env_features
from specguard.construction.preflight import START_SAMPLES, check_goals, check_starts
from specguard.construction.reference import ReferenceEvaluator
from specguard.error import EvaluationError, InitialEnvError, InvalidSpec, SpecError, StateMappingError
from specguard.starts.setter import Range
from specguard.starts.space import StartSpace, as_start_space
from specguard.tree.nodes import Node
from specguard.utils.text import shown
from specguard.validation import check_choice

_FLOAT32 = np.dtype(np.float32)


class ScalarDict(dict[str, Any]):
    """A dict of immutable scalars (``info["goals"]``, ``["safe"]``, ``["reward_terms"]``): its deep copy is a
    shallow one, made in one call. A plain ``dict`` in every other respect::

        >>> import copy
        >>> d = ScalarDict(a=True)
        >>> c = copy.deepcopy(d)
        >>> c == d, c is d, type(c).__name__
        (True, False, 'ScalarDict')
    """

    __slots__ = ()

    def __deepcopy__(self, memo: dict[int, Any]) -> ScalarDict:
        return ScalarDict(self)


_ATOMIC = frozenset({bool, int, float, complex, str, bytes, type(None)})
"""Types whose deep copy is the object itself (``copy.deepcopy`` returns them as they are)."""


class StepInfo(dict[str, Any]):
    """The ``info`` a :class:`SpecEnv` or :class:`BaselineEnv` returns: a new dict each step, the initial env's own
    entries and the spec's.

    A plain ``dict`` in every respect but its deep copy. SB3's ``DummyVecEnv`` deep-copies every env's info at
    every step, and ``copy.deepcopy`` walks a dict key by key and value by value in Python: about 5 us an info
    for the four entries the spec adds, where this copy takes 2-4 us. Here a scalar is kept as it is, a
    :class:`ScalarDict` copied in one call, and anything else (an env's own arrays, Monitor's
    ``"episode"``) deep-copied as ``copy.deepcopy`` would, shared objects copied once::

        >>> import copy
        >>> info = StepInfo(goals=ScalarDict(a=True), frames=[[0]], base_reward=1.0)
        >>> c = copy.deepcopy(info)
        >>> c == info, type(c).__name__, c["goals"] is info["goals"], c["frames"][0] is info["frames"][0]
        (True, 'StepInfo', False, False)
    """

    __slots__ = ()

    def __deepcopy__(self, memo: dict[int, Any]) -> StepInfo:
        copy = StepInfo()
        memo[id(self)] = copy
        atomic = _ATOMIC
        for key, value in self.items():
            kind = type(value)
            if kind is ScalarDict:
                value = ScalarDict(value)
            elif kind not in atomic:
                value = deepcopy(value, memo)
            copy[key if type(key) in atomic else deepcopy(key, memo)] = value
        return copy


_isfinite = math.isfinite

__all__ = [
    "ENV_KEY",
    "OBSERVATIONS",
    "SPEC_KEY",
    "BaselineEnv",
    "EnvFactory",
    "SpecEnv",
    "action_masks_problem",
    "env_parts",
    "features_space",
    "make_baseline_env",
    "make_env",
    "preflight",
    "stack_observations",
    "starts_in_root_goal",
]

EvaluatorName = Literal["flat", "reference"]

OBSERVATIONS = ("features", "features+env")
"""What the agent sees: the features and own state (a flat ``Box``), or those beside the env's own observation
(a ``Dict``: :data:`SPEC_KEY`, then the env's keys)."""
SPEC_KEY = "spec"
"""The key of the features and own state in a ``"features+env"`` observation."""
ENV_KEY = "observation"
"""The key of the env's own observation in a ``"features+env"`` observation, where it is not a ``Dict``."""
# The spaces stable-baselines3 takes inside a Dict observation (its preprocessing handles these, and no other).
_DICT_PARTS = (gym.spaces.Box, gym.spaces.Discrete, gym.spaces.MultiDiscrete, gym.spaces.MultiBinary)


def env_parts(where: str, space: gym.Space[Any]) -> dict[str, gym.Space[Any]]:
    """The parts of the env's own observation space that a ``"features+env"`` observation holds beside
    :data:`SPEC_KEY`: a ``Dict``'s keys as the env gives them, any other space under :data:`ENV_KEY`.

    Raises:
        InvalidSpec: one line per key refused: a key named :data:`SPEC_KEY`, a key that is not a string, a space
            stable-baselines3 cannot take in a ``Dict`` observation (a ``Text``, MiniGrid's ``MissionSpace``, a
            nested ``Dict`` or ``Tuple``), or an empty one (a ``Box`` of shape ``(0,)``).
    """
    parts = dict(space.spaces) if isinstance(space, gym.spaces.Dict) else {ENV_KEY: space}
    lines = []
    for key, part in parts.items():
        seen = f"key {shown(key)}" if isinstance(space, gym.spaces.Dict) else "observation"
        if not isinstance(key, str):
            lines.append(
                f"the env's observation has a key {shown(key)} of type {type(key).__name__}, and stable-baselines3 "
                "takes only string keys in a Dict observation"
            )
        elif key == SPEC_KEY:
            lines.append(f"the env's observation has a key {SPEC_KEY!r}, where the features and own state go")
        elif not isinstance(part, _DICT_PARTS):
            lines.append(
                f"the env's {seen} is a {type(part).__name__}, which stable-baselines3 cannot take in a Dict "
                "observation (it takes Box, Discrete, MultiDiscrete and MultiBinary)"
            )
        elif math.prod(part.shape or ()) == 0:
            lines.append(f"the env's {seen} is an empty {type(part).__name__} (shape {part.shape}): it shows nothing")
    if lines:
        raise InvalidSpec(
            where,
            "\n".join(f"observation='features+env': {line}" for line in lines),
            hint="leave that part out with an observation wrapper in the initial env's factory (MiniGrid's "
            "ImgObsWrapper keeps only the image)",
        )
    return parts


def features_space(space: gym.Space[Any]) -> gym.spaces.Box:
    """The ``Box`` of the features and own state in a constructed env's observation space (either kind)."""
    return cast(gym.spaces.Box, space[SPEC_KEY] if isinstance(space, gym.spaces.Dict) else space)


def stack_observations(observations: Sequence[Any]) -> Any:
    """Observations of several envs as one batch, rows first: an array, or a ``Dict``'s arrays key by key."""
    if observations and isinstance(observations[0], Mapping):
        return {key: np.stack([o[key] for o in observations]) for key in observations[0]}
    return np.stack(observations)


def _compiled_for(tree: Node, features: tuple[str, ...], compiled: CompiledTree | None) -> CompiledTree:
    """``compiled`` when it is this very tree compiled over ``features`` with its own weights; compiled here if None."""
    if compiled is None:
        return compile_tree(tree, features)  # validates feature names, even for "reference"
    if not isinstance(compiled, CompiledTree) or compiled.nodes[0] is not tree or compiled.features != features:
        raise InvalidSpec("compiled", "expected compile_tree(tree, features) of this very tree and these features")
    if compiled.weights:
        raise InvalidSpec("compiled", "expected the tree compiled with its own weights, not adapted ones")
    return compiled


def _features(obs: Any, state: Callable[[Any], Any] | None, features: tuple[str, ...], where: str) -> list[float]:
    """``state(obs)`` as a list of finite Python floats, one per feature."""
    if state is None:
        f: list[float] = obs.tolist()
    else:
        try:
            raw = state(obs)
            f = raw.tolist() if isinstance(raw, np.ndarray) else [float(v) for v in raw]
        except Exception as e:
            raise StateMappingError(f"{where}: state() raised {type(e).__name__}: {e} on observation {obs!r}") from e
    if len(f) != len(features) or not math.isfinite(sum(f)):
        raise StateMappingError(
            f"{where}: state() must return {len(features)} finite numbers for features "
            f"{features}, got {f!r} (from observation {obs!r})"
        )
    return f


class FeatureReader:
    """The features of one reset or step: ``state(obs)``'s, then those read from ``info`` and from the env.

    Args:
        where: the tree's name, for messages.
        features: every feature name; the first ones are ``state``'s, the last ones ``from_info``'s and
            ``from_env``'s.
        state: ``state(obs)``; ``None`` for the identity (or no feature from the observation).
        from_info, from_env: as :attr:`InitialEnv.from_info` and :attr:`InitialEnv.from_env`.
    """

    def __init__(
        self,
        where: str,
        features: tuple[str, ...],
        state: Callable[[Any], Any] | None,
        from_info: Sequence[tuple[str, str]] = (),
        from_env: Sequence[tuple[str, Callable[[Any], Any]]] = (),
    ) -> None:
        self.where = where
        self.from_info = tuple(from_info)
        self.from_env = tuple(from_env)
        self.observed = features[: len(features) - len(self.from_info) - len(self.from_env)]
        """The features of the observation (``state``'s, or its components)."""
        self.state = state
        self.extra = bool(self.from_info or self.from_env)
        """Whether some feature is read from ``info`` or the env."""

    @classmethod
    def of(cls, where: str, initial_env: InitialEnv) -> FeatureReader:
        """The reader of ``initial_env``'s features."""
        return cls(where, initial_env.features, initial_env.state, initial_env.from_info, initial_env.from_env)

    def check(self, space: gym.Space[Any]) -> None:
        """With the identity ``state``, the observation's features label its components one to one."""
        if self.state is None and self.observed:
            check_identity_observation(self.where, self.observed, space)

    def __call__(self, obs: Any, info: Mapping[str, Any], env: gym.Env, step: int) -> list[float]:
        """The feature vector after a reset (``step`` 0) or the ``step``-th step of an episode."""
        f = _features(obs, self.state, self.observed, self.where) if self.observed else []
        if self.extra:
            f += read_env_features(self.where, self.from_info, self.from_env, info, env, step)
        return f


class SpecEnv(gym.Wrapper[Any, Any, Any, Any], RecordConstructorArgs):
    """Wraps an initial env into the environment Algorithm 1 constructs from ``tree``.

    * observation: ``state(obs*)`` followed by the own state of the nodes and
      annotations that have one (constraint counters, sequence stages), in
      Algorithm 1's order, a float32 ``Box`` with finite bounds where known;
      with ``observation="features+env"``, a ``Dict`` of that ``Box`` under
      :data:`SPEC_KEY` and the base env's own observation (its keys where it is
      a ``Dict``, else under :data:`ENV_KEY`, :func:`env_parts`);
    * reward: the root requirements' ``R_G``, a Python float;
    * ``terminated``: the base env's, or the root goal reached, or a counter at
      0, or a node's own termination;
      ``truncated``: the base env's;
    * ``info["goals"]``: ``{path: bool}`` membership of ``s'`` in every node's
      goal (also after ``reset``); ``info["safe"]``: per constraint-like
      annotation (``path:name``), whether the episode has had no violation
      so far; ``info["reward_terms"]``: every weighted
      component by key, summing to the reward; ``info["base_reward"]``: the
      initial env's own reward;
    * :meth:`action_masks`: the initial env's, where it has them and the agent acts
      in its action space (sb3-contrib's MaskablePPO reads them).

    Args:
        env: the base (initial) env.
        tree: the goal tree.
        features: the feature names.
        state: ``state(obs*)``; ``None`` for the identity.
        execute: ``execute(a)``; ``None`` for the identity.
        feature_low, feature_high: bounds of the features, ``None`` for
            unbounded (see :meth:`InitialEnv.feature_bounds`).
        action_space: ``A_G``; ``None`` for the base env's.
        evaluator: ``"flat"`` (compiled, fast) or ``"reference"`` (Algorithm 1 as written).
        from_info, from_env: the features read from ``info`` and from the env, the last of
            ``features`` (:attr:`InitialEnv.from_info`, :attr:`InitialEnv.from_env`).
        compiled: ``compile_tree(tree, features)`` when the caller has it (envs of one
            tree share it, :class:`EnvFactory`); ``None`` compiles the tree here.
        observation: ``"features"`` (the ``Box``) or ``"features+env"`` (the ``Dict``), :data:`OBSERVATIONS`.
    """

    def __init__(
        self,
        env: gym.Env,
        tree: Node,
        features: Sequence[str],
        state: Callable[[Any], Any] | None = None,
        execute: Callable[[Any], Any] | None = None,
        feature_low: Sequence[float] | None = None,
        feature_high: Sequence[float] | None = None,
        action_space: gym.Space[Any] | None = None,
        evaluator: EvaluatorName = "flat",
        *,
        from_info: Sequence[tuple[str, str]] = (),
        from_env: Sequence[tuple[str, Callable[[Any], Any]]] = (),
        compiled: CompiledTree | None = None,
        observation: str = "features",
    ) -> None:
        # Not ``compiled``: the spec re-creates the env from the tree. Not deep-copied: nodes are immutable
        # values and the functions the user's own (a copy of a tree cost 0.8 ms of a 1.3 ms CartPole build).
        RecordConstructorArgs.__init__(
            self,
            _disable_deepcopy=True,
            tree=tree,
            features=tuple(features),
            state=state,
            execute=execute,
            feature_low=feature_low,
            feature_high=feature_high,
            action_space=action_space,
            evaluator=evaluator,
            from_info=tuple(from_info),
            from_env=tuple(from_env),
            observation=observation,
        )
        gym.Wrapper.__init__(self, env)
        if not isinstance(tree, Node):
            raise InvalidSpec("tree", f"expected a goal-tree node (Goal, All, ...), got {tree!r}")
        check_choice(tree.name, "observation", observation, OBSERVATIONS)
        self.tree = tree
        self.features = tuple(features)
        self.compiled = _compiled_for(tree, self.features, compiled)
        if evaluator == "flat":
            self.evaluator: Evaluator = self.compiled.evaluator()
        elif evaluator == "reference":
            self.evaluator = ReferenceEvaluator(tree, self.features)
        else:
            raise InvalidSpec("evaluator", f"expected 'flat' or 'reference', got {evaluator!r}")
        self._state = state
        self._execute = execute
        self._n = len(self.features)
        self._read = FeatureReader(tree.name, self.features, state, from_info, from_env)
        self._identity = state is None and not self._read.extra  # the observation is the features
        self._t = 0  # steps since the reset, for messages
        self.start_features: tuple[float, ...] = ()
        """The features of the episode's first state, as the last ``reset`` read them (the start a falsifier's
        failure predictor learns from: :attr:`RunResult.looks <specguard.training.result.RunResult.looks>`)."""
        self._safety_keys = self.evaluator.safety_keys
        base_space = env.observation_space
        self._read.check(base_space)
        slots = [slot for _, slot in self.evaluator.slots]
        low = np.full(self._n, -np.inf) if feature_low is None else np.asarray(feature_low, dtype=np.float64)
        high = np.full(self._n, np.inf) if feature_high is None else np.asarray(feature_high, dtype=np.float64)
        box = gym.spaces.Box(
            np.concatenate([low, [s.low for s in slots]]).astype(np.float32),
            np.concatenate([high, [s.high for s in slots]]).astype(np.float32),
            dtype=np.float32,
        )
        self.observation = observation
        """What the agent sees, one of :data:`OBSERVATIONS`."""
        self._with_env = observation == "features+env"
        self._whole = not isinstance(base_space, gym.spaces.Dict)  # the env's observation goes under ENV_KEY
        if self._with_env:
            self.observation_space = gym.spaces.Dict({SPEC_KEY: box, **env_parts(tree.name, base_space)})
        else:
            self.observation_space = box
        if action_space is not None:
            self.action_space = action_space
        self._own_actions = execute is not None or action_space is not None  # the agent's are not the base env's
        # The base observation can be handed on untouched when nothing is added or converted.
        self._passthrough = self._identity and not slots and base_space.dtype == np.float32 and not self._with_env
        self._pending: Any = None  # (weights, CompiledTree) adapted, in force from the next reset
        self.info_shares = False
        """The last step's ``info`` holds entries of the initial env's own info (which the env may still hold)."""
        self.adapted_weights: dict[str, tuple[float, ...]] = {}
        """The adapted weights in force this episode (:meth:`set_weights`); empty while the tree's own."""

    def set_weights(self, weights: Mapping[str, Sequence[float]]) -> None:
        """Adapt the weights of the ``All(weights="auto")`` nodes, from the next episode on.

        Args:
            weights: per path of a node with ``weights="auto"``, one weight per
                child, then one per constraint of the node left at its default
                weight (:mod:`specguard.training.auto_weights`).

        Raises:
            InvalidSpec: a path without ``weights="auto"``, a wrong count of
                weights, or the ``"reference"`` evaluator (its weights are the tree's).
        """
        if isinstance(self.evaluator, ReferenceEvaluator):
            raise InvalidSpec(
                "evaluator", "adapted weights need the 'flat' evaluator; 'reference' is the tree as written"
            )
        # Compiled now, so a bad path fails at the call; swapped in at reset, as shaping telescopes and
        # enter/exit rewards cancel only under weights constant over an episode (docs/semantics.md, "Potential-based
        # shaping").
        adapted = {path: tuple(float(w) for w in ws) for path, ws in weights.items()}
        self._pending = adapted, compile_tree(self.tree, self.features, weights=adapted)

    def action_masks_problem(self) -> str | None:
        """Why this env has no action masks to give (:meth:`action_masks`), or ``None`` when it has them."""
        if self._own_actions:
            return (
                "the agent's actions go through execute() (or act in another action space), so the initial env's "
                "masks do not say which of them are valid"
            )
        try:
            self.env.get_wrapper_attr("action_masks")
        except AttributeError:
            return f"the initial env ({type(self.env.unwrapped).__name__}) has no action_masks() method"
        return None

    def action_masks(self) -> np.ndarray:
        """The initial env's ``action_masks()``: which actions are valid in the current state.

        Raises:
            InitialEnvError: the initial env has none, or the agent does not act in its action space
                (:meth:`action_masks_problem`).
        """
        problem = self.action_masks_problem()
        if problem is not None:
            raise InitialEnvError(f"{self.tree.name}: no action masks: {problem}")
        return np.asarray(self.env.get_wrapper_attr("action_masks")())

    # -- gymnasium API -------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if self._pending is not None:
            (self.adapted_weights, self.compiled), self._pending = self._pending, None
            self.evaluator = self.compiled.evaluator()
        obs, info = self.env.reset(seed=seed, options=options)
        self._t = 0
        f = self._read(obs, info, self.env, 0)
        self.start_features = tuple(f)
        ev = self.evaluator
        ev.reset(f)
        info = StepInfo(
            info, goals=ScalarDict(ev.goals), safe=ScalarDict(ev.safe_info()) if self._safety_keys else ScalarDict()
        )
        observation = obs if self._passthrough else np.array(f + ev.own_state, _FLOAT32)
        return (self._beside(obs, observation) if self._with_env else observation), info

    def _beside(self, obs: Any, observation: np.ndarray) -> dict[str, Any]:
        """The ``"features+env"`` observation: ``observation`` under :data:`SPEC_KEY`, the env's ``obs`` beside."""
        return {SPEC_KEY: observation, ENV_KEY: obs} if self._whole else {SPEC_KEY: observation, **obs}

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info, row = self.advance(action)
        # A new array each step (a consumer may keep it, e.g. SB3's terminal_observation); or, when
        # nothing is added or converted, the base env's own observation untouched.
        observation: Any = obs if row is obs else np.array(row, _FLOAT32)
        if self._with_env:
            observation = self._beside(obs, observation)
        return observation, reward, terminated, truncated, info

    @property
    def flat(self) -> bool:
        """The observation is the features and own state, a flat ``Box`` (``observation="features"``): a vectorised
        env may write the ``row`` of :meth:`advance` into its buffer rather than ask for the observation."""
        return not self._with_env

    def advance(self, action: Any) -> tuple[Any, float, bool, bool, StepInfo, list[float]]:
        """:meth:`step`, with the observation's values in place of the observation: ``(obs, reward, terminated,
        truncated, info, row)``, ``obs`` the initial env's own.

        ``row`` is the new features, then the own state (a list); or ``obs`` itself where nothing is added or
        converted (``row is obs``). :meth:`step` makes its observation of it (float32, or the features under
        :data:`SPEC_KEY`); a vectorised env (:class:`~specguard.training.vec_env.SpecVecEnv`) writes it into its
        own buffer instead. ``info`` holds new dicts of the spec's, and the initial env's own entries as they
        came (:attr:`info_shares`).
        """
        # The hot path: every call of a user's training runs it, so it is written out in one function.
        base_action = action
        if self._execute is not None:
            try:
                base_action = self._execute(action)
            except Exception as e:
                raise InitialEnvError(
                    f"{self.tree.name}: execute() raised {type(e).__name__}: {e} on action {action!r}",
                    hint="execute(a) maps the agent's action to one the initial env accepts",
                ) from e
        obs, base_reward, terminated, truncated, info = self.env.step(base_action)
        self._t += 1
        if self._identity:  # _features inlined
            f = obs.tolist()
            if len(f) != self._n or not _isfinite(sum(f)):
                _features(obs, None, self.features, self.tree.name)  # raises, naming the observation
        else:
            f = self._read(obs, info, self.env, self._t)
        self.info_shares = bool(info)
        ev = self.evaluator
        # The last state is judged too; a termination by the initial env is one before the horizon.
        result = ev.step(action, f, terminated or truncated, terminated)
        # A new info each step, the initial env's own left as it was, and new dicts in it.
        info = StepInfo(
            info,
            goals=ScalarDict(ev.goals),
            safe=ScalarDict(ev.safe_info()) if self._safety_keys else ScalarDict(),
            reward_terms=ScalarDict(result.terms),
            base_reward=float(base_reward),
        )
        row = obs if self._passthrough else f + ev.own_state
        return obs, result.reward, bool(terminated or result.terminated), bool(truncated), info, row


class BaselineEnv(gym.Wrapper[Any, Any, Any, Any], RecordConstructorArgs):
    """Reports ``info["goals"]`` and ``info["safe"]`` of a goal tree and changes nothing else.

    The paper's *baseline*: the initial env keeps its own observation, reward
    and termination, and its episodes are judged by the same goals.

    Args:
        env: the base (initial) env.
        tree: the goal tree.
        features: the feature names.
        state: ``state(obs*)``; ``None`` for the identity.
        from_info, from_env: the features read from ``info`` and from the env (see :class:`SpecEnv`).
        compiled: ``compile_tree(tree, features)`` when the caller has it; ``None`` compiles the tree here.
        feature_low, feature_high: bounds of the features, ``None`` for unbounded (as :class:`SpecEnv`'s); the
            observation does not show them, the falsifier's margins are measured in them.
    """

    def __init__(
        self,
        env: gym.Env,
        tree: Node,
        features: Sequence[str],
        state: Callable[[Any], Any] | None = None,
        *,
        from_info: Sequence[tuple[str, str]] = (),
        from_env: Sequence[tuple[str, Callable[[Any], Any]]] = (),
        compiled: CompiledTree | None = None,
        feature_low: Sequence[float] | None = None,
        feature_high: Sequence[float] | None = None,
    ) -> None:
        RecordConstructorArgs.__init__(  # not deep-copied, as SpecEnv's
            self,
            _disable_deepcopy=True,
            tree=tree,
            features=tuple(features),
            state=state,
            from_info=tuple(from_info),
            from_env=tuple(from_env),
        )
        gym.Wrapper.__init__(self, env)
        if not isinstance(tree, Node):
            raise InvalidSpec("tree", f"expected a goal-tree node (Goal, All, ...), got {tree!r}")
        self.tree = tree
        self.features = tuple(features)
        self.evaluator = _compiled_for(tree, self.features, compiled).evaluator()
        self._read = FeatureReader(tree.name, self.features, state, from_info, from_env)
        self._read.check(env.observation_space)
        n = len(self.features)
        self.feature_low = np.full(n, -np.inf) if feature_low is None else np.asarray(feature_low, dtype=np.float64)
        self.feature_high = np.full(n, np.inf) if feature_high is None else np.asarray(feature_high, dtype=np.float64)
        """The features' bounds (``-inf``/``inf`` where unknown)."""
        self._t = 0
        self.start_features: tuple[float, ...] = ()
        """The features of the episode's first state, as the last ``reset`` read them."""

    def _info(self, info: dict[str, Any], members: tuple[bool, ...]) -> dict[str, Any]:
        ev = self.evaluator
        return StepInfo(info, goals=ScalarDict(zip(ev.paths, members)), safe=ScalarDict(zip(ev.safety_keys, ev.safe)))

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._t = 0
        f = self._read(obs, info, self.env, 0)
        self.start_features = tuple(f)
        return obs, self._info(info, self.evaluator.reset(f))

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not math.isfinite(reward):
            raise EvaluationError(f"{self.tree.name}: the initial env returned a non-finite reward {reward!r}")
        self._t += 1
        f = self._read(obs, info, self.env, self._t)
        # Own state (stages, counters) follows the episode, though the spec's reward and termination do not
        # apply; without own state, membership of one state is all there is (no rewards computed for nothing),
        # and the evaluator starts afresh in it: its state is the episode's last, as the falsifier reads it.
        members = (
            self.evaluator.step(action, f, terminated or truncated, terminated).goals
            if self.evaluator.slots
            else self.evaluator.reset(f)
        )
        return obs, reward, terminated, truncated, self._info(info, members)


def action_masks_problem(env: gym.Env) -> str | None:
    """Why ``env`` (a :class:`SpecEnv` or :class:`BaselineEnv`, wrapped or not) has no action masks, or ``None``.

    A ``SpecEnv`` has its initial env's where the agent acts in the initial env's action space
    (:meth:`SpecEnv.action_masks_problem`); any other env has them when it or a wrapper has ``action_masks()``.
    """
    inner: Any = env
    while not isinstance(inner, SpecEnv) and isinstance(inner, gym.Wrapper):
        inner = inner.env
    if isinstance(inner, SpecEnv):
        return inner.action_masks_problem()
    try:
        env.get_wrapper_attr("action_masks")
    except AttributeError:
        return f"the initial env ({type(env.unwrapped).__name__}) has no action_masks() method"
    return None


def preflight(where: str, initial_env: object, tree: object) -> CompiledTree:
    """The checks of the arguments of ``make_env`` and ``make_baseline_env``, before any env is built.

    One function for both (and every :class:`EnvFactory`): the baseline refuses what the constructed env refuses.

    Args:
        where: the function the user called, for the messages.
        initial_env: should be an :class:`InitialEnv`.
        tree: should be a goal-tree node whose goals name only the initial env's features.

    Returns:
        ``tree`` compiled over the initial env's features.

    Raises:
        InitialEnvError: ``initial_env`` is not an :class:`InitialEnv`.
        InvalidSpec: ``tree`` is not a node, or a weight makes a coefficient overflow.
        UnknownFeature: a goal names a feature the initial env lacks.
    """
    if not isinstance(initial_env, InitialEnv):
        raise InitialEnvError(f"{where}: expected an InitialEnv as first argument, got {initial_env!r}")
    if not isinstance(tree, Node):
        raise InvalidSpec(where, f"expected a goal-tree node (Goal, All, ...) as tree, got {tree!r}")
    return compile_tree(tree, initial_env.features)


def starts_in_root_goal(
    initial_env: InitialEnv, compiled: CompiledTree, samples: int = START_SAMPLES, **make_kwargs: Any
) -> int | None:
    """How many of ``samples`` seeded resets (seeds ``0 .. samples - 1``) start inside the root goal.

    The resets are of a base env of their own, closed after: an env handed out stays as unseeded as a
    fresh one. None when a start cannot be judged (the env or a goal's function raised): the env's own reset
    reports that, with its message, where it happens. A feature that cannot be read at a reset (``state()``
    raised or gave no finite numbers, a missing ``info`` key, a ``from_env`` function that raised) is
    raised here, before anything trains.

    Raises:
        StateMappingError: a feature cannot be read at a reset.
    """
    base = initial_env.make(**make_kwargs)
    evaluator = compiled.evaluator()
    read = FeatureReader.of(compiled.paths[0], initial_env)
    inside = 0
    try:
        for seed in range(samples):
            obs, info = base.reset(seed=seed)
            inside += evaluator.reset(read(obs, info, base, 0))[0]
    except StateMappingError:
        raise  # the user's mapping, not the env: refused before any seed trains
    except Exception:
        return None
    finally:
        base.close()
    return inside


class EnvFactory:
    """Builds the envs of one goal tree over one initial env, compiling the tree and checking it once for all of them.

    ``make_env(initial_env, tree, ...)`` is ``EnvFactory(initial_env, tree, ...)()``. A spec keeps one factory
    (:meth:`Spec.env_factory <specguard.spec.spec.Spec.env_factory>`): its training envs, its evaluation env, the
    falsifier's and the fingerprint's share the compiled tree and its generated code, each with an evaluator
    (episode state) of its own. The factory holds the tree object itself, so what it compiled is exactly that tree.

    As Gymnasium's env checker, the checks run once: :meth:`check` (the goals against the bounds of the
    observation space, and the root goal judged on seeded resets of an env of its own, :func:`starts_in_root_goal`,
    :func:`~specguard.construction.preflight.check_starts`); the first call that builds an env runs them unless
    ``check=False``, and no later call of the same factory does. Every call runs :func:`preflight` (compiled once;
    a failure is raised again) and builds a base env (under :func:`~specguard.construction.cap.capped` where it
    declares no episode limit, so every episode ends) before wrapping it.

    Args:
        initial_env: the initial environment and its mappings.
        tree: the goal tree.
        baseline: build :class:`BaselineEnv` envs (the initial env's own reward) rather than :class:`SpecEnv`.
        evaluator: the :class:`SpecEnv` evaluator, ``"flat"`` or ``"reference"``.
        observation: what a :class:`SpecEnv`'s agent sees, one of :data:`OBSERVATIONS`.
    """

    def __init__(
        self,
        initial_env: InitialEnv,
        tree: Node,
        *,
        baseline: bool = False,
        evaluator: EvaluatorName = "flat",
        observation: str = "features",
    ) -> None:
        self.initial_env = initial_env
        self.tree = tree
        self.baseline = baseline
        self.evaluator: EvaluatorName = evaluator
        self.observation = observation
        self.compiled: CompiledTree | None = None
        """The compiled tree, once the first call's preflight passed."""
        self.checked = False
        """:meth:`check` ran and passed: the goals against the bounds, the root goal on the sampled starts."""
        self._bounds: tuple[np.ndarray, np.ndarray] | None = None  # the features' bounds, read once

    def _compiled(self) -> CompiledTree:
        if self.compiled is None:
            self.compiled = preflight("make_baseline_env" if self.baseline else "make_env", self.initial_env, self.tree)
        return self.compiled

    def check(self, base: gym.Env | None = None, **make_kwargs: Any) -> None:
        """Run the checks of the construction once: a goal no state can be in, a root goal met (or, held until
        the end, failed) before the agent acts, a feature that cannot be read at a start.

        ``base``: a base env already built, whose observation space gives the bounds (else one is built).

        Raises:
            SpecError: a check refuses the spec; the message names the node path.
        """
        if self.checked:
            return
        compiled, initial_env = self._compiled(), self.initial_env
        own = base is None
        env = initial_env.make(**make_kwargs) if base is None else base
        try:
            low, high = self._bounds_of(env)
            check_goals(compiled, low, high)  # refuse a goal no state can be in, before training
        finally:
            if own:
                env.close()
        inside = starts_in_root_goal(initial_env, compiled, START_SAMPLES, **make_kwargs)
        if inside is not None:  # and a root goal met (or, held until the end, failed) before the agent acts
            check_starts(compiled, inside, START_SAMPLES)
        self.checked = True

    def _bounds_of(self, base: gym.Env) -> tuple[np.ndarray, np.ndarray]:
        if self._bounds is None:
            self._bounds = self.initial_env.feature_bounds(base.observation_space)  # the features fit the observation
        return self._bounds

    def __call__(
        self, *, check: bool = True, starts: StartSpace | Mapping[str, Range] | None = None, **make_kwargs: Any
    ) -> SpecEnv | BaselineEnv:
        """A new env; ``make_kwargs`` override the base env's ``gymnasium.make`` kwargs.

        ``check=False`` builds it without the checks (:meth:`check`), as ``gymnasium.make(...,
        disable_env_checker=True)`` does; they run at most once per factory anyway.

        ``starts``: a start space (a :class:`~specguard.starts.space.StartSpace` or its ranges ``{name: (lo, hi)}``)
        the env's episodes may begin in. It is resolved over the base env and the base
        env wrapped in its :class:`~specguard.starts.space.StartWrapper` before the constructed env is put
        around it, so ``reset(options={START_OPTION: values})`` starts the episode from ``values``
        (:func:`~specguard.starts.space.starts_of` gives the resolved space); other resets are the env's own.

        Raises:
            SpecError: the tree or the initial env is invalid, or ``starts`` does not fit the env; the message
                names the node path or the env.
        """
        compiled, initial_env = self._compiled(), self.initial_env
        space = as_start_space("make_baseline_env" if self.baseline else "make_env", starts)
        base = capped(initial_env.make(**make_kwargs))  # every episode ends (specguard.construction.cap)
        try:
            low, high = self._bounds_of(base)
            if check:
                self.check(base, **make_kwargs)
            if space is not None:  # under the constructed env, as the falsifier's episodes begin
                base = space.resolve(base).wrap(base)
            if self.baseline:
                return BaselineEnv(
                    base,
                    tree=self.tree,
                    features=initial_env.features,
                    state=initial_env.state,
                    from_info=initial_env.from_info,
                    from_env=initial_env.from_env,
                    compiled=compiled,
                    feature_low=tuple(low.tolist()),
                    feature_high=tuple(high.tolist()),
                )
            return SpecEnv(
                base,
                tree=self.tree,
                features=initial_env.features,
                state=initial_env.state,
                execute=initial_env.execute,
                feature_low=None if np.all(np.isinf(low)) else tuple(low.tolist()),
                feature_high=None if np.all(np.isinf(high)) else tuple(high.tolist()),
                action_space=initial_env.action_space,
                evaluator=self.evaluator,
                from_info=initial_env.from_info,
                from_env=initial_env.from_env,
                compiled=compiled,
                observation=self.observation,
            )
        except SpecError:
            base.close()
            raise


def make_baseline_env(
    initial_env: InitialEnv,
    tree: Node,
    *,
    check: bool = True,
    starts: StartSpace | Mapping[str, Range] | None = None,
    **make_kwargs: Any,
) -> BaselineEnv:
    """The initial env with its own reward, reporting the goals of ``tree`` (the paper's baseline).

    It runs the preflight and the checks of :func:`make_env` (``check=False``: the preflight alone), and takes
    its start space (``starts``).
    """
    factory = EnvFactory(initial_env, tree, baseline=True)
    return cast(BaselineEnv, factory(check=check, starts=starts, **make_kwargs))


def make_env(
    initial_env: InitialEnv,
    tree: Node,
    *,
    evaluator: EvaluatorName = "flat",
    observation: str = "features",
    check: bool = True,
    starts: StartSpace | Mapping[str, Range] | None = None,
    **make_kwargs: Any,
) -> SpecEnv:
    """Construct the trainable env of ``tree`` over ``initial_env`` (Algorithm 1).

    Args:
        initial_env: the initial environment and its mappings.
        tree: the goal tree; its root goal ends the episode.
        evaluator: ``"flat"`` (default, compiled) or ``"reference"``.
        observation: ``"features"`` (default: the features and own state, a ``Box``) or ``"features+env"``
            (a ``Dict`` of those and the initial env's own observation, :class:`SpecEnv`).
        check: run the checks of the construction (:meth:`EnvFactory.check`: a goal no state can be in, a
            root goal met before the agent acts); ``False`` skips them, as ``disable_env_checker`` does.
        starts: a start space the episodes may begin in (:class:`~specguard.starts.space.StartSpace`, or its
            ranges): the base env is put in its wrapper, and ``reset(options={START_OPTION: values})`` starts
            from ``values`` (:meth:`EnvFactory.__call__`); ``None`` (default): the env's own starts only.
        **make_kwargs: overrides for the base env's ``gymnasium.make`` kwargs
            (e.g. ``render_mode="human"``).

    Returns:
        A :class:`SpecEnv`, a ``gymnasium.Env``. The tree is compiled once
        (:class:`EnvFactory` builds several envs of one tree on one compilation).

    Raises:
        SpecError: the tree or the initial env is invalid, or ``starts`` does not fit the env; the message
            names the node path or the env.
    """
    factory = EnvFactory(initial_env, tree, evaluator=evaluator, observation=observation)
    return cast(SpecEnv, factory(check=check, starts=starts, **make_kwargs))
