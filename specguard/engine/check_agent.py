"""Judging an agent trained elsewhere against a spec, training nothing: :func:`check_agent` (docs/semantics.md,
"One agent's statistics").

The agent is one run: its evaluation episodes are seeded as a trained run's are (episode ``i`` of ``seed`` on the env
seed ``EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE + i``), drawn in stages (``episodes``, doubled while an asserted goal
is undecided, up to ``max_episodes``) and judged at the confidence corrected for those looks, as a run's final
evaluation is (:mod:`specguard.stats.anytime`). The result is a :class:`~specguard.engine.spec_result.SpecResult` with
that one run: the same verdicts and words as a trained spec's, and no model.

What the agent sees:

* ``observation="env"`` (default): what it was trained on, the initial env's own observation, as the baseline env
  (:func:`~specguard.construction.env.make_baseline_env`) gives it. The goals are read from the features, ``info``
  and the env, and the episodes are the initial env's own: its termination and its horizon end them.
* ``wrap=``: the observation wrappers the agent was trained with, put around that env (``wrap(env)``). They change
  what the agent sees, not what the goals read, which the baseline env beneath them reads from the initial env.
* ``observation="spec"``: the constructed env's observation (:func:`~specguard.construction.env.make_env`), for an
  agent trained on ``sg.make_env`` by the user's own trainer; its episodes end as that env ends them.

Example:
    >>> import specguard as sg
    >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    >>> balance = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")
    >>> spec = sg.Spec(cartpole, balance, budget=sg.Budget(timesteps=1, eval_episodes=10), expect=0.5)
    >>> result = check_agent(spec, lambda obs: int(obs[2] > 0), max_episodes=10)
    >>> result.passed, result.goals["balance"].successes, result.goals["balance"].episodes
    (False, 0, 10)
"""

from __future__ import annotations

import contextlib
import dataclasses
import sys
import time
import warnings
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from specguard.agents.agent import Agent, check_fits
from specguard.agents.sources import load_agent
from specguard.cache.canonical import digest
from specguard.cache.fingerprint import fingerprint_spec
from specguard.cache.store import Cache
from specguard.construction.env import EnvFactory
from specguard.engine.judging import judged
from specguard.engine.spec_result import SpecResult
from specguard.error import (
    AgentError,
    EvaluationError,
    FingerprintError,
    InvalidSpec,
    SpecError,
    SpecWarning,
    user_stacklevel,
)
from specguard.evaluation.episodes import EVAL_SEED_BASE, EVAL_SEED_STRIDE, evaluate
from specguard.evaluation.policy import one_torch_thread
from specguard.spec.budget import AGENT_TIMESTEPS, Budget
from specguard.spec.spec import Spec
from specguard.stats.anytime import evaluation_stages, final_evaluation
from specguard.stats.intervals import failure_upper_bound
from specguard.training.result import RunResult
from specguard.tree.keys import label, result_keys
from specguard.utils.atomic import DEFAULT_CACHE_DIR
from specguard.utils.text import MAX_SHOWN, elide, function_text, shown
from specguard.validation import check_choice, check_count, check_natural

__all__ = [
    "AGENT_OBSERVATIONS",
    "AgentCheck",
    "agent_envs",
    "agent_episodes",
    "agent_stages",
    "agent_wrap",
    "check_agent",
    "evaluation_identity",
    "seed_base",
    "spec_agent",
]

AGENT_OBSERVATIONS = ("env", "spec")
"""What an agent may see: the initial env's own observation (``"env"``), or the constructed env's (``"spec"``)."""


def check_agent(
    spec: Spec,
    agent: Any,
    *,
    episodes: int | None = None,
    max_episodes: int | None = None,
    observation: str = "env",
    wrap: Callable[[Any], Any] | None = None,
    seed: int = 0,
    algorithm: str | type | None = None,
    cache_dir: str | Path | None = DEFAULT_CACHE_DIR,
    outcomes: list[dict[str, int]] | None = None,
    trust: bool = False,
) -> SpecResult:
    """Judge ``agent`` against ``spec`` on evaluation episodes, training nothing.

    Args:
        spec: the spec; its thresholds, confidence, ``undecided``, ``xfail`` and ``deterministic`` apply, its
            training settings do not.
        agent: an :class:`~specguard.agents.agent.Agent`, or anything
            :func:`~specguard.agents.sources.load_agent` takes: a saved model's ``.zip``, an rl-zoo3 or Hub folder,
            an object with SB3's ``predict``, a callable ``obs -> action``.
        episodes: the first stage's evaluation episodes (default: the spec's ``budget.eval_episodes``).
        max_episodes: the most episodes, while an asserted goal is undecided (default: the spec's
            ``budget.max_eval_episodes``).
        observation: ``"env"``, the initial env's own observation, or ``"spec"``, the constructed env's.
        wrap: ``wrap(env) -> env``, the observation wrappers the agent was trained with, around the env it sees.
        seed: which evaluation seeds the episodes take, as a trained run's seed (see the module).
        algorithm: a zip's algorithm, as for :func:`~specguard.agents.sources.load_agent`.
        cache_dir: where evaluations are kept and looked up, keyed by the agent's identity (its files' bytes, or a
            callable's code), the spec's key and these settings; ``None`` disables the cache.
        outcomes: if given, receives each episode's own counts in order (1 or 0 per goal and safety key), for a
            paired comparison (:func:`specguard.gate.agent_gate.compare_agents`); the cache is then neither read nor
            written (it keeps counts, not each episode's).
        trust: run the code the agent's files may hold, as for :func:`~specguard.agents.sources.load_agent`
            (default: decode them without running any, and refuse a file that needs more).

    Returns:
        The result, with the agent's episodes as one run (seed ``seed``, no training).

    Raises:
        AgentError: the agent cannot be loaded, raised, or gave an action outside the action space;
            :class:`~specguard.error.AgentMismatch` before any episode when its spaces do not fit the env's.
        InvalidSpec: an argument is out of range.
        EvaluationError: the env or a user function failed in an episode.
    """
    started = time.perf_counter()
    where = f"check_agent({spec.label!r})" if isinstance(spec, Spec) else "check_agent"
    stages = agent_stages(where, spec, episodes, max_episodes)
    first, most = stages[0], stages[-1]
    check_choice(where, "observation", observation, AGENT_OBSERVATIONS)
    seed = check_natural(where, "seed", seed, "the evaluation seeds' run")
    agent = spec_agent(spec, agent, algorithm=algorithm, batch=False, trust=trust)
    seen_wrap = agent_wrap(agent, wrap)  # what the agent sees through: wrap=, else its config's wrappers
    # The agent as one run: one seed, judged at the looks of its stages (no checkpoints), as a trained run's final
    # evaluation is judged; the quorum of one run is that run.
    one = dataclasses.replace(
        spec,
        budget=Budget(
            timesteps=AGENT_TIMESTEPS,
            min_seeds=1,
            max_seeds=1,
            eval_episodes=first,
            max_eval_episodes=most,
            checkpoints=1,
        ),
        quorum=None,
    )
    settings = {"first": first, "most": most, "observation": observation, "seed": seed}
    cache, key = _cache_entry(spec, agent, wrap, settings, None if outcomes is not None else cache_dir)
    run = cache.load_key(key, seed=seed, paths=result_keys(spec.tree), model=False) if cache is not None else None
    hit = run is not None
    if run is None:
        run = _evaluate(where, spec, one, agent, observation, seen_wrap, seed, stages, outcomes)
        if cache is not None:
            try:
                cache.store_evaluation(key, run)
            except OSError as e:  # fail loudly, lose nothing: the result stands, uncached
                warnings.warn(f"specguard cache: {where}'s evaluation kept, not cached: {e}", stacklevel=2)
    n = run.episodes
    base = EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE
    counts = run.successes
    # The baseline env's episodes are the env's own.
    result = judged(one, [run], ends_at_goal=observation == "spec", agent=agent.name)
    seen = "the constructed env's" if observation == "spec" else "the initial env's own"
    wrapped = f", through {function_text(seen_wrap)}" if seen_wrap is not None else ""
    result.notes[:0] = [
        *_other_env_kwargs(spec, agent),
        *_agent_notes(agent, wrap),
        f"agent {agent.name!r}: {n} evaluation episodes (env seeds {base}..{base + n - 1}), seeing {seen} "
        f"observation{wrapped}",
        *_never_failed(counts, n, spec.confidence),
    ]
    result.trained = None  # no model behind it
    result.cached = {seed: hit}
    result.spec_key = key
    result.cache_dir = cache.root if cache is not None else None
    result.seconds = time.perf_counter() - started
    return result


def _evaluate(
    where: str,
    spec: Spec,
    one: Spec,
    agent: Agent,
    observation: str,
    wrap: Callable[[Any], Any] | None,
    seed: int,
    stages: list[int],
    outcomes: list[dict[str, int]] | None = None,
) -> RunResult:
    """The agent's evaluation episodes, drawn in ``stages`` until every asserted goal is decided: one run."""
    env = agent_envs(spec, observation, wrap)()
    try:
        check_fits(agent, env.observation_space, env.action_space)  # before any episode
        base = seed_base(seed)
        started_in: list[bool] = []
        terminated: list[bool] = []
        capped: list[bool] = []

        def episodes_of(start: int, count: int) -> dict[str, int]:
            return _episodes(where, agent, env, base, start, count, started_in, terminated, capped, outcomes)

        with _threads(agent):
            counts, n = final_evaluation(episodes_of, stages, spec.thresholds, one.verdict_confidence)
    finally:
        env.close()
    return RunResult(
        spec=spec.label,
        seed=seed,
        timesteps=0,
        episodes=n,
        successes=counts,
        train_seconds=0.0,
        started_in_goal=sum(started_in),
        terminated=sum(terminated),
        capped=sum(capped),
        weights_digest=_weights_digest(agent),
    )


def _weights_digest(agent: Agent) -> str | None:
    """The agent's identity as its run's weights digest (:attr:`RunResult.weights_digest
    <specguard.training.result.RunResult>`): a model in memory digested as a trained run's is, so the two agree on
    the same weights; files by their bytes. ``None`` where it has none (a callable holding what has no exact form)."""
    try:
        return agent.identity
    except (FingerprintError, AgentError):
        return None


def _cache_entry(
    spec: Spec,
    agent: Agent,
    wrap: Callable[[Any], Any] | None,
    settings: dict[str, Any],
    cache_dir: str | Path | None,
) -> tuple[Cache | None, str]:
    """The cache and the key of this evaluation: the agent's identity, the spec's key and the evaluation's settings.

    ``(None, "")`` where nothing is cached: ``cache_dir=None``, an env that does not repeat a fixed-seed rollout, or
    an agent or ``wrap`` that cannot be fingerprinted exactly (said in a warning: its verdict stands, uncached).
    """
    if cache_dir is None:
        return None, ""
    try:
        parts, reproducible = evaluation_identity(spec, agent, wrap)
    except (FingerprintError, AgentError) as e:
        warnings.warn(f"specguard cache: agent {agent.name!r} evaluated, not cached: {e}", stacklevel=3)
        return None, ""
    if not reproducible:
        return None, ""
    return Cache(Path(cache_dir)), digest({**parts, "evaluation": settings}, "evaluation")


def evaluation_identity(spec: Spec, agent: Agent, wrap: Callable[[Any], Any] | None) -> tuple[dict[str, Any], bool]:
    """What an agent's evaluation episodes depend on beyond their settings: ``{"agent": its identity, "spec": the
    spec's key, "wrap": wrap's digest or None}``, and whether the env repeats a fixed-seed rollout (else no two
    evaluations of it are the same episodes).

    Raises:
        FingerprintError: the spec or ``wrap`` cannot be fingerprinted exactly. AgentError: the agent has no identity.
    """
    fingerprint = fingerprint_spec(spec)
    parts = {
        "agent": agent.identity,
        "spec": fingerprint.spec_key,
        "wrap": None if wrap is None else digest(wrap, "wrap"),
    }
    return parts, fingerprint.reproducible


@dataclasses.dataclass(frozen=True)
class AgentCheck:
    """A spec and an agent to judge against it, with :func:`check_agent`'s settings: what a goal spec returns to
    have ``pytest --goal-specs`` judge an agent trained elsewhere instead of training one.

    The arguments are :func:`check_agent`'s, checked here; the agent is loaded when the check runs.

    Example:
        >>> import specguard as sg
        >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
        >>> spec = sg.Spec(cartpole, sg.Goal("right", theta=(0.1, None)), budget=sg.Budget(timesteps=1), expect=0.3)
        >>> check = sg.AgentCheck(spec, lambda obs: int(obs[2] > 0), episodes=10, max_episodes=10)
        >>> check.run().goals["right"].episodes
        10
        >>> sg.AgentCheck(spec, "agent.zip", observation="pixels")
        Traceback (most recent call last):
        ...
        specguard.error.InvalidSpec: AgentCheck('right'): expected observation to be one of env, spec, got 'pixels'...
    """

    spec: Spec
    agent: Any
    _: dataclasses.KW_ONLY
    episodes: int | None = None
    max_episodes: int | None = None
    observation: str = "env"
    wrap: Callable[[Any], Any] | None = None
    seed: int = 0
    algorithm: str | type | None = None
    trust: bool = False

    def __post_init__(self) -> None:
        where = f"AgentCheck({self.spec.label!r})" if isinstance(self.spec, Spec) else "AgentCheck"
        agent_stages(where, self.spec, self.episodes, self.max_episodes)
        check_choice(where, "observation", self.observation, AGENT_OBSERVATIONS)
        check_natural(where, "seed", self.seed, "the evaluation seeds' run")
        if self.wrap is not None and not callable(self.wrap):
            raise InvalidSpec(where, f"expected wrap to be a function env -> env or None, got {shown(self.wrap)}")
        if self.algorithm is not None and not isinstance(self.algorithm, (str, type)):
            raise InvalidSpec(where, f"expected algorithm to be a name, a class or None, got {shown(self.algorithm)}")

    def run(
        self, *, cache_dir: str | Path | None = DEFAULT_CACHE_DIR, outcomes: list[dict[str, int]] | None = None
    ) -> SpecResult:
        """The agent judged against the spec: :func:`check_agent` with these settings (and ``cache_dir`` and
        ``outcomes``)."""
        return check_agent(
            self.spec,
            self.agent,
            episodes=self.episodes,
            max_episodes=self.max_episodes,
            observation=self.observation,
            wrap=self.wrap,
            seed=self.seed,
            algorithm=self.algorithm,
            cache_dir=cache_dir,
            outcomes=outcomes,
            trust=self.trust,
        )


def seed_base(seed: int) -> int:
    """The env seed of evaluation episode 0 of ``seed`` (episode ``i`` takes this plus ``i``), as a trained run's.

    Example:
        >>> seed_base(0), seed_base(1) - seed_base(0) > 10_000
        (1000000, True)
    """
    return EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE


def agent_stages(where: str, spec: Spec, episodes: int | None, max_episodes: int | None) -> list[int]:
    """The episodes evaluated after each stage of an agent's evaluation: ``episodes`` (default: the spec's
    ``budget.eval_episodes``), doubled up to ``max_episodes`` (default: ``budget.max_eval_episodes``).

    Raises:
        InvalidSpec: ``spec`` is not a Spec, or the counts are out of range.
    """
    if not isinstance(spec, Spec):
        raise InvalidSpec(where, f"expected a Spec, got {shown(spec)}", hint="check_agent(spec, agent)")
    budget = spec.budget
    first = check_count(where, "episodes", budget.eval_episodes if episodes is None else episodes)
    assert budget.max_eval_episodes is not None
    most_default = max(first, budget.max_eval_episodes)
    most = check_count(where, "max_episodes", most_default if max_episodes is None else max_episodes)
    if most < first:
        raise InvalidSpec(where, f"expected max_episodes >= episodes, got {most} < {first}")
    return evaluation_stages(first, most)


def agent_episodes(
    spec: Spec, agent: Agent, start: int, count: int, *, observation: str, wrap: Callable[[Any], Any] | None, seed: int
) -> list[dict[str, int]]:
    """Episodes ``start..start + count - 1`` of ``agent`` for seed ``seed``, as :func:`check_agent` plays them: each
    episode's own counts, in order (for a paired comparison, beyond the episodes its verdicts needed)."""
    where = f"agent_episodes({spec.label!r})"
    env = agent_envs(spec, observation, agent_wrap(agent, wrap))()
    outcomes: list[dict[str, int]] = []
    try:
        check_fits(agent, env.observation_space, env.action_space)
        with _threads(agent):
            _episodes(where, agent, env, seed_base(seed), start, count, None, None, None, outcomes)
    finally:
        env.close()
    return outcomes


def _episodes(
    where: str,
    agent: Agent,
    env: Any,
    base: int,
    start: int,
    count: int,
    *lists: Any,
) -> dict[str, int]:
    """Episodes ``start..start + count - 1`` of ``agent`` on env seeds from ``base``; an env's failure as an
    EvaluationError."""
    try:
        return evaluate(agent, env, count, range(base + start, base + start + count), *lists)
    except SpecError:
        raise
    except Exception as e:
        raise EvaluationError(
            f"{where}, evaluation episodes {start}..{start + count - 1} of agent {agent.name!r}: the "
            f"environment raised {type(e).__name__}: {elide(str(e), MAX_SHOWN)}"
        ) from e


def spec_agent(
    spec: Spec, agent: Any, *, algorithm: str | type | None = None, batch: bool = False, trust: bool = False
) -> Agent:
    """``agent`` as an :class:`~specguard.agents.agent.Agent` acting as ``spec`` says (its ``deterministic``), taking
    a batch of observations or one (``batch``): loaded by :func:`~specguard.agents.sources.load_agent` (with
    ``algorithm`` and ``trust``) unless it is one already."""
    if not isinstance(agent, Agent):
        return load_agent(agent, algorithm=algorithm, deterministic=spec.deterministic, batch=batch, trust=trust)
    return agent if agent.batch == batch else agent.batched(batch)


def agent_envs(spec: Spec, observation: str = "env", wrap: Callable[[Any], Any] | None = None) -> Callable[..., Any]:
    """``make(*, starts=None, **make_kwargs)``: a new env the agent acts in, the baseline env (the initial env's
    observation) or the constructed env, wrapped in ``wrap`` where given, in a start space's wrapper where ``starts``
    is given (:meth:`~specguard.construction.env.EnvFactory.__call__`; ``make_kwargs`` override the base env's
    ``gymnasium.make`` kwargs, e.g. ``render_mode="rgb_array"``); its ``info`` reports the goals, read beneath any
    wrapper. One factory for all of them (its checks run once).

    Raises:
        AgentError: ``wrap`` raised, returned no ``gymnasium.Env``, or its env's reset gives no ``info['goals']``.
    """
    if observation == "spec":
        factory = EnvFactory(spec.initial_env, spec.tree, observation=spec.observation)
    else:
        factory = EnvFactory(spec.initial_env, spec.tree, baseline=True)

    def make(*, starts: Any = None, **make_kwargs: Any) -> Any:
        env = factory(starts=starts, **make_kwargs)
        return env if wrap is None else _wrapped(env, wrap)

    return make


def agent_wrap(agent: Agent, wrap: Callable[[Any], Any] | None) -> Callable[[Any], Any] | None:
    """The wrappers around the env ``agent`` sees: ``wrap`` where given, else those its rl-zoo3 ``config.yml`` says
    it was trained with (``frame_stack``, ``env_wrapper``: :attr:`~specguard.agents.agent.Agent.wrappers`).

    Example:
        >>> agent_wrap(load_agent(lambda obs: 0), None) is None
        True
    """
    return wrap if wrap is not None else agent.wrappers


def _agent_notes(agent: Agent, wrap: Callable[[Any], Any] | None) -> list[str]:
    """The notes on what the agent's own files changed in what it sees: its config's wrappers (applied, or not for
    ``wrap=``, loudly) and its ``VecNormalize`` statistics."""
    notes = []
    if agent.wrappers is not None and wrap is None:
        notes.append(
            f"agent {agent.name!r}: its observations pass through its config.yml's {agent.wrappers.text} (frames "
            "stacked on the last axis as SB3's VecFrameStack does), as it was trained"
        )
    elif agent.wrappers is not None and wrap is not None:
        text = (
            f"agent {agent.name!r}: its config.yml's {agent.wrappers.text} is not applied: wrap={function_text(wrap)} "
            "replaces it"
        )
        warnings.warn(text, SpecWarning, stacklevel=3)
        notes.append(text)
    if agent.normalizer is not None:
        source = f" of {agent.normalizer_source}" if agent.normalizer_source else ""
        notes.append(
            f"agent {agent.name!r}: its observations are normalized by the VecNormalize statistics{source} "
            "(as saved, not updated) before it acts"
        )
    return notes


def _wrapped(env: Any, wrap: Callable[[Any], Any]) -> Any:
    """``wrap(env)``, checked: a ``gymnasium.Env`` whose reset still reports the goals."""
    import gymnasium as gym

    name = function_text(wrap)
    try:
        wrapped = wrap(env)
    except Exception as e:
        env.close()
        raise AgentError(f"wrap={name} raised {type(e).__name__}: {elide(str(e), MAX_SHOWN)}", hint=None) from e
    if not isinstance(wrapped, gym.Env):
        env.close()
        raise AgentError(
            f"wrap={name} returned {shown(wrapped)}, not a gymnasium.Env",
            hint="wrap takes the env and returns it wrapped, e.g. wrap=ImgObsWrapper",
        )
    _, info = wrapped.reset(seed=0)
    if not isinstance(info, Mapping) or "goals" not in info:
        wrapped.close()
        raise AgentError(
            f"wrap={name}: its env's reset gives no info['goals'], where the goals are reported",
            hint="a wrapper must pass the info of the env it wraps on",
        )
    return wrapped


def _other_env_kwargs(spec: Spec, agent: Agent) -> list[str]:
    """Loud notes (and warnings) where the agent's own files say its env was another id, or made otherwise, than the
    spec's."""
    texts = []
    ours_id = spec.initial_env.env if isinstance(spec.initial_env.env, str) else None
    if agent.env_id is not None and agent.env_id.rpartition(":")[2] != (ours_id or "").rpartition(":")[2]:
        made = repr(ours_id) if ours_id is not None else "made by a factory"
        texts.append(
            f"agent {agent.name!r} was trained on env {agent.env_id!r}, which the spec's initial env is not "
            f"({made}): the verdicts are about the spec's env; give InitialEnv {agent.env_id!r} to judge the agent "
            "in the env it was trained in"
        )
    ours = spec.initial_env.make_kwargs
    other = {k: v for k, v in agent.env_kwargs.items() if k != "render_mode" and (k not in ours or ours[k] != v)}
    if other:
        texts.append(
            f"agent {agent.name!r} was trained on an env made with {other}, which the spec's initial env is not "
            f"(its kwargs: {dict(ours)}): the verdicts are about the spec's env; give InitialEnv those kwargs to "
            "judge the agent in the env it was trained in"
        )
    for text in texts:
        warnings.warn(text, SpecWarning, stacklevel=user_stacklevel())
    return texts


def _never_failed(counts: Mapping[str, int], episodes: int, confidence: float) -> list[str]:
    """The note on the goals and safety rates that never failed: the most their failure rate can be, not 100%."""
    perfect = [label(key) for key, k in counts.items() if k == episodes]
    if not perfect:
        return []
    bound = failure_upper_bound(episodes, confidence)
    return [
        f"never failed in {episodes} episodes: {', '.join(perfect)}; a failure rate of at most {bound:.1%} each "
        f"(one-sided exact binomial bound at {confidence:.0%})"
    ]


@contextlib.contextmanager
def _threads(agent: Agent) -> Iterator[None]:
    """torch on one thread while the agent acts, where torch is in use (a model's, or a callable's network)."""
    if agent.model is None and "torch" not in sys.modules:
        yield
        return
    with one_torch_thread():
        yield
