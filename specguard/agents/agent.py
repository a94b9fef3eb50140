"""An agent trained elsewhere as one policy: :class:`Agent`, and :func:`check_fits`, its spaces against an env's.

Whatever it was loaded from (:func:`specguard.agents.sources.load_agent`: a
saved model, an rl-zoo3 or Hub folder, a model in memory, a callable), an
:class:`Agent` acts as an
:class:`~specguard.construction.episode_policy.EpisodePolicy`: told as episodes
start, then asked once per step. How it acts is decided once, when it is made;
a step adds one call and one flag to the agent's own.

Example:
    >>> import gymnasium as gym
    >>> agent = Agent(lambda obs: int(obs[2] > 0), name="lean")
    >>> check_fits(agent, gym.spaces.Box(-1, 1, (4,)), gym.spaces.Discrete(2))
    >>> agent.start([None]); agent([0.0, 0.0, 0.1, 0.0])
    1
    >>> agent.start([None]); agent([0.0, 0.0, -0.1, 0.0]), agent.name, agent.action_space
    (0, 'lean', None)
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from specguard.error import AgentError, AgentMismatch, SpecError, SpecWarning
from specguard.evaluation.policy import observation_rows
from specguard.utils.text import MAX_SHOWN, elide, shown

__all__ = ["Agent", "action_problem", "check_fits", "observation_kind", "observation_rows", "space_text"]


class Agent:
    """An agent as a policy: its action for an observation (or a batch of them, one row per env), and what it is.

    It satisfies :class:`specguard.construction.episode_policy.EpisodePolicy`: call :meth:`start` with the envs as
    their episodes start, then the agent once per step. Made by :func:`~specguard.agents.sources.load_agent`.

    Args:
        act: the action for ``(observations, rows)``: a :class:`specguard.evaluation.policy.Policy` (a model's, which
            keeps a recurrent state and reads action masks), or a callable ``obs -> action`` for one observation
            (``per_observation=True``, the default for a callable).
        name: a short name for reports.
        identity: computes the agent's :attr:`identity` on first use.
        observation_space: what the agent reads, when it says (a model's); ``None``: unknown (a callable's).
        action_space: what it gives, when it says.
        normalizer: ``VecNormalize`` statistics applied to every observation before a callable sees it (a model's
            policy applies its own).
        batch: take a batch of observations (rows, one per env) and give their actions; a callable for one
            observation is asked row by row.
        check_actions: check every action against the action space (:func:`check_fits` names it for an agent that
            does not say), and clip a ``Box`` action to its bounds as SB3's ``predict`` clips a model's (warned
            once): for an agent whose actions may be of another type, shape or range (a callable's, a ``predict``
            of another library's).
        model: the SB3 model (or ``predict`` object) behind the agent, if any.
        algorithm: its algorithm's class, if known.
        path: the file it was loaded from, if any.
        env_kwargs: what its ``env_kwargs.yml`` (or rl-zoo3's ``args.yml`` and ``config.yml``) says the env was
            made with; empty where nothing says.
        env_id: the env id its rl-zoo3 ``args.yml`` says it was trained on (``env:``), if any.
        config: what its ``config.yml`` says it was trained with (rl-zoo3's hyperparameters); empty where none.
        wrappers: the env wrappers its ``config.yml`` says it was trained with (``frame_stack``, ``env_wrapper``:
            :func:`specguard.agents.wrappers.zoo_wrappers`), put around the env it is judged in unless ``wrap=`` is
            given; ``None``: none.
        normalizer_source: where its ``VecNormalize`` statistics came from (a file's path), for notes.
    """

    def __init__(
        self,
        act: Callable[..., Any],
        *,
        name: str,
        identity: Callable[[], str] | None = None,
        observation_space: Any = None,
        action_space: Any = None,
        normalizer: Any = None,
        batch: bool = False,
        check_actions: bool = True,
        model: Any = None,
        algorithm: type | None = None,
        path: Any = None,
        env_kwargs: Mapping[str, Any] | None = None,
        config: Mapping[str, Any] | None = None,
        wrappers: Any = None,
        normalizer_source: str | None = None,
        env_id: str | None = None,
    ) -> None:
        from specguard.evaluation.policy import Policy

        self.name = name
        self.observation_space = observation_space
        self.action_space = action_space
        self.normalizer = normalizer
        self.batch = batch
        self.model = model
        self.algorithm = algorithm
        self.path = path
        self.env_kwargs: dict[str, Any] = dict(env_kwargs or {})
        self.config: dict[str, Any] = dict(config or {})
        self.wrappers = wrappers
        self.normalizer_source = normalizer_source
        self.env_id = env_id
        self._source = act
        self._identity = identity
        self._check_actions = check_actions
        self._convert: Callable[[Any], Any] | None = None  # a callable's action as the env takes it (_expect)
        self._expected = action_space  # the space actions are checked against (check_fits names it)
        self._policy = act if isinstance(act, Policy) else None
        self._act = self._policy if self._policy is not None else self._callable_act(act)
        self._unchecked = check_actions
        self._clipped = False  # a Box action was clipped (warned once)

    # -- what it is ----------------------------------------------------------------------------------------

    @functools.cached_property
    def identity(self) -> str:
        """A stable hex digest of what the agent computes, for cache keys: a file's bytes (a zip and its
        ``vecnormalize.pkl``), a model's parameters, a callable's code (as a spec's functions are fingerprinted).

        Raises:
            FingerprintError: a callable holds something that cannot be fingerprinted exactly.
        """
        if self._identity is None:
            raise AgentError(f"agent {self.name!r} has no identity: it was made without one", hint=None)
        return self._identity()

    def batched(self, batch: bool = True) -> Agent:
        """The same agent taking a batch of observations (``batch=True``) or one: it shares the model, with its own
        per-env state."""
        from specguard.evaluation.policy import Policy

        act = self._source
        if self._policy is not None:
            act = Policy(self._policy.model, self.normalizer, deterministic=self._policy.deterministic, batch=batch)
        twin = Agent(
            act,
            name=self.name,
            identity=self._identity,
            observation_space=self.observation_space,
            action_space=self.action_space,
            normalizer=self.normalizer,
            batch=batch,
            check_actions=self._check_actions,
            model=self.model,
            algorithm=self.algorithm,
            path=self.path,
            env_kwargs=self.env_kwargs,
            config=self.config,
            wrappers=self.wrappers,
            normalizer_source=self.normalizer_source,
            env_id=self.env_id,
        )
        twin._expect(self._expected)
        return twin

    def __repr__(self) -> str:
        return f"Agent({self.name!r})"

    # -- acting ---------------------------------------------------------------------------------------------

    def start(self, envs: Sequence[Any]) -> None:
        """Episodes start on ``envs`` (one env, or one per row of a batch): a recurrent state starts afresh, and the
        actions are checked from the first (for an agent whose actions are checked)."""
        if self._policy is not None:
            self._policy.start(envs)
        self._unchecked = self._check_actions

    def __call__(self, observations: Any, rows: Sequence[int] | None = None) -> Any:
        """The action for ``observations`` (of every env started, or of the envs ``rows``), as the agent gives it
        (a discrete one as a Python ``int`` unless batched).

        Raises:
            AgentError: the agent raised (its exception chained), called ``sys.exit``, or gave an action that is not
                one of the action space (checked at every step for an agent whose actions are checked; a ``Box``
                action out of its bounds is clipped instead, as SB3's ``predict`` clips a model's).
        """
        try:
            action = self._act(observations, rows)
        except SpecError:
            raise
        except SystemExit as e:  # would end the judging process as if it had finished: the agent's failure
            raise AgentError(
                f"agent {self.name!r} called sys.exit({e.code!r}) while acting",
                hint="a policy returns an action; it must not exit the process",
            ) from e
        except Exception as e:
            first = str(e).strip().splitlines()[0] if str(e).strip() else ""
            raise AgentError(f"agent {self.name!r} raised {type(e).__name__}: {elide(first, MAX_SHOWN)}") from e
        if self._unchecked:
            action = self._check(action)
        return action if self._convert is None else self._convert(action)

    def _callable_act(self, fn: Callable[[Any], Any]) -> Callable[[Any, Sequence[int] | None], Any]:
        """``fn`` (one observation to one action) as the agent's step, decided once: normalized or not, batched or
        not (its actions stacked)."""
        from specguard.evaluation.policy import callable_policy

        norm = self.normalizer
        one = fn if norm is None else (lambda obs: fn(norm.normalize_obs(obs)))
        return callable_policy(one, batch=self.batch)

    def _expect(self, action_space: Any) -> None:
        """Check actions against ``action_space`` (the env's, where the agent names none); a callable's discrete
        action is then given as a Python ``int``."""
        import gymnasium as gym

        if action_space is None:
            return
        self._expected = action_space
        self._unchecked = self._check_actions
        if self._policy is None and not self.batch:
            self._convert = int if isinstance(action_space, gym.spaces.Discrete) else np.asarray

    def _check(self, action: Any) -> Any:
        """``action``, checked against the action space; a ``Box`` action clipped to its bounds (warned once)."""
        import gymnasium as gym

        space = self._expected
        if space is None:  # nothing to check against (no check_fits): not checked until start
            self._unchecked = False
            return action
        for row in np.asarray(action) if self.batch else (action,):
            problem = action_problem(space, row)
            if problem:
                raise AgentError(
                    f"agent {self.name!r} gave the action {shown(row)} ({problem}), which is not one of {space}",
                    hint="an agent's action must be one of the env's action space, as env.action_space.contains says",
                )
        if isinstance(space, gym.spaces.Box):
            array = np.asarray(action)
            clipped = np.clip(array, space.low, space.high)
            if not np.array_equal(clipped, array):
                if not self._clipped:
                    self._clipped = True
                    warnings.warn(
                        f"agent {self.name!r} gave the action {shown(array)} outside {space}: its actions are "
                        "clipped to the bounds, as SB3's predict clips a model's",
                        SpecWarning,
                        stacklevel=3,
                    )
                return clipped
        return action


def action_problem(space: Any, action: Any) -> str:
    """What is wrong with ``action`` for ``space`` in a few words: its shape, its type, its range; ``""``: nothing.

    A ``Box`` action is checked for its shape, a number type and finite values (what lies outside its bounds is
    clipped by :class:`Agent`, as SB3's ``predict`` clips a model's); any other space asks ``space.contains``.

    Example:
        >>> import gymnasium as gym
        >>> action_problem(gym.spaces.Discrete(2), 1), action_problem(gym.spaces.Discrete(2), 2.0)
        ('', 'a float64, not an integer')
        >>> action_problem(gym.spaces.Box(-1, 1, (2,)), [0.5]), action_problem(gym.spaces.Discrete(2), 5)
        ('shape (1,), not (2,)', 'outside the space')
    """
    import gymnasium as gym

    try:
        array = np.asarray(action)
    except Exception as e:  # a tensor that needs .detach(), an object numpy cannot read: in its own words
        text = str(e).strip().splitlines()[0] if str(e).strip() else ""
        many = isinstance(action, (tuple, list))  # (action, log_prob, ...) of an actor
        return (
            f"numpy cannot read it: {type(e).__name__}"
            + (f": {elide(text, MAX_SHOWN)}" if text else "")
            + (f"; a {type(action).__name__} of {len(action)} values: give the action alone" if many else "")
        )
    if isinstance(space, (gym.spaces.Box, gym.spaces.Discrete, gym.spaces.MultiDiscrete, gym.spaces.MultiBinary)):
        if array.shape != space.shape:
            return f"shape {array.shape}, not {space.shape}"
        numbers = "iuf" if isinstance(space, gym.spaces.Box) else "iu"
        if array.dtype.kind not in numbers:
            return f"a{'n' if array.dtype.name[0] in 'aeiou' else ''} {array.dtype}, not " + (
                "a number" if numbers == "iuf" else "an integer"
            )
        if isinstance(space, gym.spaces.Box):
            return "" if np.isfinite(array).all() else "not finite"
        action = array.astype(space.dtype) if array.dtype != space.dtype else array
        if isinstance(space, gym.spaces.Discrete):
            action = action.item()
    return "" if space.contains(action) else "outside the space"


def observation_kind(space: Any) -> tuple[Any, ...]:
    """What a network reads of an observation space: its kind and shape (a ``Dict``'s key by key)."""
    import gymnasium as gym

    if isinstance(space, gym.spaces.Dict):
        return ("Dict", tuple((key, observation_kind(part)) for key, part in space.spaces.items()))
    return (type(space).__name__, getattr(space, "shape", None))


def check_fits(agent: Agent, observation_space: Any, action_space: Any) -> None:
    """Refuse an agent whose spaces do not fit an env's, before any episode; an agent that names no action space
    (a callable) has its first action after each start checked against ``action_space`` instead.

    The observation must be of the same kind and shape as the agent's (what its network reads; its bounds may
    differ); the action space must equal the agent's (what the env is given), as SB3's ``check_for_correct_spaces``
    asks.

    Raises:
        AgentMismatch: one line naming the agent's space and the env's.
    """
    wanted = observation_kind(observation_space)
    if agent.observation_space is not None and observation_kind(agent.observation_space) != wanted:
        raise AgentMismatch(
            f"agent {agent.name!r} reads observations of {space_text(agent.observation_space)}, and the env gives "
            f"{space_text(observation_space)}",
            hint=_observation_hint(agent, agent.observation_space, observation_space),
        )
    norm = agent.normalizer
    if agent.observation_space is None and norm is not None and observation_kind(norm.observation_space) != wanted:
        raise AgentMismatch(
            f"agent {agent.name!r} normalizes observations of {space_text(norm.observation_space)}, and the env "
            f"gives {space_text(observation_space)}",
            hint=_observation_hint(agent, norm.observation_space, observation_space),
        )
    if agent.action_space is not None and agent.action_space != action_space:
        raise AgentMismatch(f"agent {agent.name!r} acts in {agent.action_space}, and the env takes {action_space}")
    agent._expect(action_space)


def space_text(space: Any) -> str:
    """An observation space in a few words: what a network reads of it (its kind, shape and dtype), not its bounds.

    Example:
        >>> import gymnasium as gym
        >>> space_text(gym.spaces.Box(-1, 1, (16,))), space_text(gym.spaces.Discrete(3))
        ('Box(shape=(16,), float32)', 'Discrete(3)')
        >>> space_text(gym.spaces.Dict({"a": gym.spaces.Box(0, 255, (3, 2), "uint8")}))
        'Dict(a: Box(shape=(3, 2), uint8))'
    """
    import gymnasium as gym

    if isinstance(space, gym.spaces.Dict):
        return "Dict(" + ", ".join(f"{key}: {space_text(part)}" for key, part in space.spaces.items()) + ")"
    if isinstance(space, gym.spaces.Box):
        return f"Box(shape={space.shape}, {space.dtype})"
    return elide(str(space), MAX_SHOWN)


def _observation_hint(agent: Agent, reads: Any, gives: Any) -> str:
    """What to try when the agent reads other observations than the env gives: the config's ``frame_stack``, a
    stack the shapes suggest, the wrappers it was trained with (``wrap=``)."""
    import gymnasium as gym

    stack = agent.config.get("frame_stack")
    where = "from specguard.agents.wrappers import FrameStack"
    if stack is not None:
        return (
            f"its config.yml says frame_stack: {stack}, which check_agent applies unless wrap= is given; a wrap= must "
            f"stack as SB3's VecFrameStack does: wrap=lambda env: FrameStack(env, {stack}) ({where})"
        )
    if isinstance(reads, gym.spaces.Box) and isinstance(gives, gym.spaces.Box) and reads.shape and gives.shape:
        n, rest = divmod(reads.shape[-1], gives.shape[-1])
        if n > 1 and not rest and reads.shape[:-1] == gives.shape[:-1]:
            return (
                f"trained on {n} stacked frames (SB3's VecFrameStack)? wrap=lambda env: FrameStack(env, {n}) ({where}) "
                "stacks them as it does (rl-zoo3's config.yml frame_stack is applied on its own)"
            )
    return (
        "judge the agent in the env it was trained in (its env id and env_kwargs), through the observation wrappers "
        "it was trained with (check_agent(..., wrap=...))"
    )
