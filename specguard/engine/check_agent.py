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
from collections.abc import Callable, Iterator, Mapping
from typing import Any

from specguard.agents.agent import Agent, check_fits
from specguard.agents.sources import load_agent
from specguard.construction.env import EnvFactory
from specguard.engine.judging import judged
from specguard.engine.spec_result import SpecResult
from specguard.error import AgentError, EvaluationError, InvalidSpec, SpecError
from specguard.spec.budget import Budget
from specguard.spec.spec import Spec
from specguard.stats.anytime import evaluation_stages, final_evaluation
from specguard.stats.intervals import failure_upper_bound
from specguard.training.policy import one_torch_thread
from specguard.training.result import RunResult
from specguard.training.train import EVAL_SEED_BASE, EVAL_SEED_STRIDE, evaluate
from specguard.tree.keys import label
from specguard.utils.text import MAX_SHOWN, elide, function_text, shown
from specguard.validation import check_choice, check_count, check_natural

__all__ = ["AGENT_OBSERVATIONS", "agent_envs", "check_agent", "spec_agent"]

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
    if not isinstance(spec, Spec):
        raise InvalidSpec(where, f"expected a Spec, got {shown(spec)}", hint="check_agent(spec, agent)")
    budget = spec.budget
    first = check_count(where, "episodes", budget.eval_episodes if episodes is None else episodes)
    assert budget.max_eval_episodes is not None
    most_default = max(first, budget.max_eval_episodes)
    most = check_count(where, "max_episodes", most_default if max_episodes is None else max_episodes)
    if most < first:
        raise InvalidSpec(where, f"expected max_episodes >= episodes, got {most} < {first}")
    check_choice(where, "observation", observation, AGENT_OBSERVATIONS)
    seed = check_natural(where, "seed", seed, "the evaluation seeds' run")
    agent = spec_agent(spec, agent, algorithm=algorithm, batch=False)
    stages = evaluation_stages(first, most)
    # The agent as one run: one seed, judged at the looks of its stages (no checkpoints), as a trained run's final
    # evaluation is judged; the quorum of one run is that run.
    one = dataclasses.replace(
        spec,
        budget=Budget(
            timesteps=1, min_seeds=1, max_seeds=1, eval_episodes=first, max_eval_episodes=most, checkpoints=1
        ),
        quorum=None,
    )
    env = agent_envs(spec, observation, wrap)()
    try:
        check_fits(agent, env.observation_space, env.action_space)  # before any episode
        base = EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE
        started_in: list[bool] = []
        terminated: list[bool] = []
        capped: list[bool] = []

        def episodes_of(start: int, count: int) -> dict[str, int]:
            try:
                return evaluate(
                    agent, env, count, range(base + start, base + start + count), started_in, terminated, capped
                )
            except SpecError:
                raise
            except Exception as e:
                raise EvaluationError(
                    f"{where}, evaluation episodes {start}..{start + count - 1} of agent {agent.name!r}: the "
                    f"environment raised {type(e).__name__}: {elide(str(e), MAX_SHOWN)}"
                ) from e

        with _threads(agent):
            counts, n = final_evaluation(episodes_of, stages, spec.thresholds, one.verdict_confidence)
    finally:
        env.close()
    run = RunResult(
        spec=spec.label,
        seed=seed,
        timesteps=0,
        episodes=n,
        successes=counts,
        train_seconds=0.0,
        started_in_goal=sum(started_in),
        terminated=sum(terminated),
        capped=sum(capped),
    )
    result = judged(one, [run])
    seen = "the constructed env's" if observation == "spec" else "the initial env's own"
    wrapped = f", through {function_text(wrap)}" if wrap is not None else ""
    result.notes[:0] = [
        f"agent {agent.name!r}: {n} evaluation episodes (env seeds {base}..{base + n - 1}), seeing {seen} "
        f"observation{wrapped}",
        *_never_failed(counts, n, spec.confidence),
    ]
    result.trained = None  # no model behind it
    result.seconds = time.perf_counter() - started
    return result


def spec_agent(spec: Spec, agent: Any, *, algorithm: str | type | None = None, batch: bool = False) -> Agent:
    """``agent`` as an :class:`~specguard.agents.agent.Agent` acting as ``spec`` says (its ``deterministic``), taking
    a batch of observations or one (``batch``): loaded by :func:`~specguard.agents.sources.load_agent` unless it is
    one already."""
    if not isinstance(agent, Agent):
        return load_agent(agent, algorithm=algorithm, deterministic=spec.deterministic, batch=batch)
    return agent if agent.batch == batch else agent.batched(batch)


def agent_envs(spec: Spec, observation: str = "env", wrap: Callable[[Any], Any] | None = None) -> Callable[..., Any]:
    """``make(*, starts=None)``: a new env the agent acts in, the baseline env (the initial env's observation) or the
    constructed env, wrapped in ``wrap`` where given, in a start space's wrapper where ``starts`` is given
    (:meth:`~specguard.construction.env.EnvFactory.__call__`); its ``info`` reports the goals, read beneath any
    wrapper. One factory for all of them (its checks run once).

    Raises:
        AgentError: ``wrap`` raised, returned no ``gymnasium.Env``, or its env's reset gives no ``info['goals']``.
    """
    if observation == "spec":
        factory = EnvFactory(spec.initial_env, spec.tree, observation=spec.observation)
    else:
        factory = EnvFactory(spec.initial_env, spec.tree, baseline=True)

    def make(*, starts: Any = None) -> Any:
        env = factory(starts=starts)
        return env if wrap is None else _wrapped(env, wrap)

    return make


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
