"""The constructed environment: a Gymnasium wrapper built from a goal tree (SPEC.md section 2).

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
from typing import Any, Literal, SupportsFloat

import gymnasium as gym
import numpy as np
from gymnasium.utils import RecordConstructorArgs

from specguard.build.checks import check_goals
from specguard.build.compiled import compile_tree
from specguard.error import EvaluationError, InitialEnvError, InvalidSpec, SpecError, StateMappingError
from specguard.build.initial_env import InitialEnv, check_identity_observation
from specguard.tree.nodes import Node
from specguard.build.reference import ReferenceEvaluator

__all__ = ["GoalInfo", "SpecEnv", "make_baseline_env", "make_env"]

EvaluatorName = Literal["flat", "reference"]


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


class SpecEnv(gym.Wrapper[np.ndarray, Any, Any, Any], RecordConstructorArgs):
    """Wraps an initial env into the environment Algorithm 1 constructs from ``tree``.

    * observation: ``state(obs*)`` followed by the own state of the nodes and
      annotations that have one (constraint counters, sequence stages), in
      Algorithm 1's order, a float32 ``Box`` with finite bounds where known;
    * reward: the root requirements' ``R_G``, a Python float;
    * ``terminated``: the base env's, or the root goal reached, or a counter at
      0, or a node's own termination;
      ``truncated``: the base env's;
    * ``info["goals"]``: ``{path: bool}`` membership of ``s'`` in every node's
      goal (also after ``reset``); ``info["safe"]``: per constraint-like
      annotation (``path:name``), whether the episode has had no violation
      so far; ``info["reward_terms"]``: every weighted
      component by key, summing to the reward; ``info["base_reward"]``: the
      initial env's own reward.

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
    ) -> None:
        RecordConstructorArgs.__init__(
            self,
            tree=tree,
            features=tuple(features),
            state=state,
            execute=execute,
            feature_low=feature_low,
            feature_high=feature_high,
            action_space=action_space,
            evaluator=evaluator,
        )
        gym.Wrapper.__init__(self, env)
        if not isinstance(tree, Node):
            raise InvalidSpec("tree", f"expected a goal-tree node (Goal, All, ...), got {tree!r}")
        self.tree = tree
        self.features = tuple(features)
        self.compiled = compile_tree(tree, self.features)  # validates feature names, even for "reference"
        if evaluator == "flat":
            self.evaluator: Any = self.compiled.evaluator()
        elif evaluator == "reference":
            self.evaluator = ReferenceEvaluator(tree, self.features)
        else:
            raise InvalidSpec("evaluator", f"expected 'flat' or 'reference', got {evaluator!r}")
        self._state = state
        self._execute = execute
        self._n = len(self.features)
        self._paths, self._safety_keys = self.evaluator.paths, self.evaluator.safety_keys
        base_space = env.observation_space
        if state is None:
            check_identity_observation(tree.name, self.features, base_space)
        slots = [slot for _, slot in self.evaluator.slots]
        low = np.full(self._n, -np.inf) if feature_low is None else np.asarray(feature_low, dtype=np.float64)
        high = np.full(self._n, np.inf) if feature_high is None else np.asarray(feature_high, dtype=np.float64)
        self.observation_space = gym.spaces.Box(
            np.concatenate([low, [s.low for s in slots]]).astype(np.float32),
            np.concatenate([high, [s.high for s in slots]]).astype(np.float32),
            dtype=np.float32,
        )
        if action_space is not None:
            self.action_space = action_space
        # The base observation can be handed on untouched when nothing is added or converted.
        self._passthrough = state is None and not slots and base_space.dtype == np.float32
        self._pending: Any = None  # (weights, CompiledTree) adapted, in force from the next reset
        self.adapted_weights: dict[str, tuple[float, ...]] = {}
        """The adapted weights in force this episode (:meth:`set_weights`); empty while the tree's own."""

    def set_weights(self, weights: Mapping[str, Sequence[float]]) -> None:
        """Adapt the weights of the ``All(weights="auto")`` nodes, from the next episode on.

        Args:
            weights: per path of a node with ``weights="auto"``, one weight per
                child, then one per constraint of the node left at its default
                weight (:mod:`specguard.engine.auto_weights`).

        Raises:
            InvalidSpec: a path without ``weights="auto"``, a wrong count of
                weights, or the ``"reference"`` evaluator (its weights are the tree's).
        """
        if isinstance(self.evaluator, ReferenceEvaluator):
            raise InvalidSpec(
                "evaluator", "adapted weights need the 'flat' evaluator; 'reference' is the tree as written"
            )
        # Compiled now, so a bad path fails at the call; swapped in at reset, as shaping telescopes
        # and enter/exit rewards cancel only under weights constant over an episode (SPEC.md section 6).
        adapted = {path: tuple(float(w) for w in ws) for path, ws in weights.items()}
        self._pending = adapted, compile_tree(self.tree, self.features, weights=adapted)

    # -- mapping ---------------------------------------------------------------

    def _observation(self, obs: Any, f: list[float]) -> np.ndarray:
        if self._passthrough:
            return obs  # type: ignore[no-any-return]
        return np.array(f + self.evaluator.own_state, dtype=np.float32)

    # -- gymnasium API -------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        if self._pending is not None:
            (self.adapted_weights, self.compiled), self._pending = self._pending, None
            self.evaluator = self.compiled.evaluator()
        obs, info = self.env.reset(seed=seed, options=options)
        f = _features(obs, self._state, self.features, self.tree.name)
        members = self.evaluator.reset(f)
        info["goals"] = dict(zip(self._paths, members))
        info["safe"] = self._safe()
        return self._observation(obs, f), info

    def _safe(self) -> dict[str, bool]:
        return dict(zip(self._safety_keys, self.evaluator.safe)) if self._safety_keys else {}

    def step(self, action: Any) -> tuple[np.ndarray, SupportsFloat, bool, bool, dict[str, Any]]:
        base_action = action if self._execute is None else self._execute(action)
        obs, base_reward, terminated, truncated, info = self.env.step(base_action)
        f = _features(obs, self._state, self.features, self.tree.name)
        reward, ended, members, terms = self.evaluator.step(action, f)
        info["goals"] = dict(zip(self._paths, members))
        info["safe"] = self._safe()
        info["reward_terms"] = terms
        info["base_reward"] = float(base_reward)
        return self._observation(obs, f), reward, bool(terminated or ended), bool(truncated), info


class GoalInfo(gym.Wrapper[Any, Any, Any, Any], RecordConstructorArgs):
    """Reports ``info["goals"]`` and ``info["safe"]`` of a goal tree and changes nothing else.

    The paper's *baseline*: the initial env keeps its own observation, reward
    and termination, and its episodes are judged by the same goals.

    Args:
        env: the base (initial) env.
        tree: the goal tree.
        features: the feature names.
        state: ``state(obs*)``; ``None`` for the identity.
    """

    def __init__(
        self, env: gym.Env, tree: Node, features: Sequence[str], state: Callable[[Any], Any] | None = None
    ) -> None:
        RecordConstructorArgs.__init__(self, tree=tree, features=tuple(features), state=state)
        gym.Wrapper.__init__(self, env)
        self.tree = tree
        self.features = tuple(features)
        self.evaluator = compile_tree(tree, self.features).evaluator()
        self._state = state
        if state is None:
            check_identity_observation(tree.name, self.features, env.observation_space)

    def _info(self, info: dict[str, Any], members: tuple[bool, ...]) -> dict[str, Any]:
        info["goals"] = dict(zip(self.evaluator.paths, members))
        info["safe"] = dict(zip(self.evaluator.safety_keys, self.evaluator.safe))
        return info

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        f = _features(obs, self._state, self.features, self.tree.name)
        return obs, self._info(info, self.evaluator.reset(f))

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not math.isfinite(reward):
            raise EvaluationError(f"{self.tree.name}: the initial env returned a non-finite reward {reward!r}")
        f = _features(obs, self._state, self.features, self.tree.name)
        # Own state (stages, counters) follows the episode, though the spec's reward and termination do not
        # apply; without own state, membership of one state is all there is (no rewards computed for nothing).
        members = self.evaluator.step(action, f)[2] if self.evaluator.slots else self.evaluator.members(f)
        return obs, reward, terminated, truncated, self._info(info, members)


def make_baseline_env(initial_env: InitialEnv, tree: Node, **make_kwargs: Any) -> GoalInfo:
    """The initial env with its own reward, reporting the goals of ``tree`` (the paper's baseline)."""
    if not isinstance(initial_env, InitialEnv):
        raise InitialEnvError(f"make_baseline_env: expected an InitialEnv as first argument, got {initial_env!r}")
    compile_tree(tree, initial_env.features)
    base = initial_env.make(**make_kwargs)
    try:
        low, high = initial_env.feature_bounds(base.observation_space)  # checks the features fit the observation
        check_goals(tree, initial_env.features, low, high)  # refuse a goal no state can be in, before training
        return GoalInfo(base, tree=tree, features=initial_env.features, state=initial_env.state)
    except SpecError:
        base.close()
        raise


def make_env(initial_env: InitialEnv, tree: Node, *, evaluator: EvaluatorName = "flat", **make_kwargs: Any) -> SpecEnv:
    """Construct the trainable env of ``tree`` over ``initial_env`` (Algorithm 1).

    Args:
        initial_env: the initial environment and its mappings.
        tree: the goal tree; its root goal ends the episode.
        evaluator: ``"flat"`` (default, compiled) or ``"reference"``.
        **make_kwargs: overrides for the base env's ``gymnasium.make`` kwargs
            (e.g. ``render_mode="human"``).

    Returns:
        A :class:`SpecEnv`, a ``gymnasium.Env``.

    Raises:
        SpecError: the tree or the initial env is invalid; the message names the node path.
    """
    if not isinstance(initial_env, InitialEnv):
        raise InitialEnvError(f"make_env: expected an InitialEnv as first argument, got {initial_env!r}")
    if not isinstance(tree, Node):
        raise InvalidSpec("make_env", f"expected a goal-tree node (Goal, All, ...) as tree, got {tree!r}")
    compile_tree(tree, initial_env.features)  # fail before building the base env
    base = initial_env.make(**make_kwargs)
    try:
        low, high = initial_env.feature_bounds(base.observation_space)  # checks the features fit the observation
        check_goals(tree, initial_env.features, low, high)  # refuse a goal no state can be in, before training
        return SpecEnv(
            base,
            tree=tree,
            features=initial_env.features,
            state=initial_env.state,
            execute=initial_env.execute,
            feature_low=None if np.all(np.isinf(low)) else tuple(low.tolist()),
            feature_high=None if np.all(np.isinf(high)) else tuple(high.tolist()),
            action_space=initial_env.action_space,
            evaluator=evaluator,
        )
    except SpecError:
        base.close()
        raise


def __getattr__(name: str) -> Any:
    # GoalEnv was this class's name until 0.1; it clashed with gymnasium-robotics' goal-conditioned GoalEnv.
    if name == "GoalEnv":
        import warnings

        warnings.warn(
            "specguard.GoalEnv is renamed SpecEnv (GoalEnv is gymnasium-robotics' goal-conditioned env); "
            "the old name goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        return SpecEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
