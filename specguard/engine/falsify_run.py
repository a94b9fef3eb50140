"""Falsifying a spec's trained runs, or an agent trained elsewhere: a batched policy, the spec's property and identity.

:func:`falsify_runs` falsifies the runs of a :class:`~specguard.engine.spec_result.SpecResult`, each as
:func:`falsify_run` does: it takes run ``seed``'s model from the cache (no retraining),
makes it a policy over a batch of observations (its ``VecNormalize``
statistics applied where the run used them, its deterministic action where
the spec evaluates so) and searches a start space with
:func:`specguard.falsify.search.falsify`. The property is the spec's own: the
root goal and every thresholded goal and safety rate at the end of an episode.
Counterexamples are stored in a Hypothesis example database under a key made
of the spec's identity (its fingerprint's ``spec_key``), the seed and the start space.

:func:`falsify_agent` runs the same search on an agent trained elsewhere
(:func:`specguard.agents.sources.load_agent`), in the env
:func:`~specguard.engine.check_agent.check_agent` judges it in: the baseline env
by default, whose episodes end as the initial env ends them. Its counterexamples are stored under the
spec's identity, the agent's (:attr:`~specguard.agents.agent.Agent.identity`, what it sees) and the start space.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from specguard.engine.result_models import load_run
from specguard.engine.spec_result import SpecResult
from specguard.evaluation.policy import one_torch_thread
from specguard.falsify.predictor import FailureData, from_looks
from specguard.falsify.robustness import SCORES
from specguard.falsify.search import EpisodeRunner, Falsification, falsify
from specguard.spec.spec import Spec
from specguard.starts.space import StartSpace
from specguard.validation import check_choice

__all__ = [
    "batch_policy",
    "database_key",
    "falsify_agent",
    "falsify_run",
    "falsify_runs",
    "property_keys",
    "start_space",
]


def start_space(spec: Spec, starts: StartSpace | None = None) -> StartSpace:
    """The start space searched: ``starts`` if given, else the spec's own (``Spec.starts``), else the env's.

    Example:
        >>> import specguard as sg
        >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
        >>> spec = sg.Spec(cartpole, sg.Goal("g", x=(0, 1)), budget=sg.Budget(timesteps=8), starts={"x": (-1, 1)})
        >>> start_space(spec).ranges, start_space(spec, sg.StartSpace()).ranges
        ((('x', -1.0, 1.0),), ())
    """
    if starts is not None:
        return starts
    return spec.starts if spec.starts is not None else StartSpace()


def property_keys(spec: Spec) -> list[str]:
    """The keys the falsifier asserts: the root goal, then every thresholded goal and safety rate."""
    return list(dict.fromkeys([spec.tree.name, *spec.thresholds]))


def database_key(spec_key: str, seed: int | None, space: StartSpace, *, agent: str = "") -> str:
    """The key a counterexample of run ``seed`` over ``space`` is stored under; of an agent trained elsewhere
    (``agent``: its identity and what it sees; ``seed`` is ``None``), under the agent instead.

    Example:
        >>> space = StartSpace({"x": (-1, 1)})
        >>> database_key("k", 0, space) != database_key("k", None, space, agent="a1 env")
        True
    """
    who = f"agent {agent}" if agent else str(seed)
    return hashlib.sha256(f"{spec_key}\n{who}\n{space.describe()}".encode()).hexdigest()


def batch_policy(model: Any, normalizer: Any, deterministic: bool) -> Callable[[np.ndarray], Any]:
    """``model``'s actions for a batch of observations (rows), its ``VecNormalize`` statistics applied if any."""
    from specguard.evaluation.policy import policy

    return policy(model, normalizer, deterministic=deterministic, batch=True)


def falsify_runs(
    result: SpecResult,
    starts: StartSpace | None = None,
    *,
    seeds: list[int] | None = None,
    examples: int = 200,
    uniform: int = 100,
    search_seed: int = 0,
    database: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
    score: str = "last",
    weaker: int = 0,
    importance: int = 0,
) -> dict[int, Falsification]:
    """Search ``starts`` for starts from which each of ``result``'s cached policies misses the spec (no retraining).

    Args:
        starts: the start space (:class:`~specguard.starts.space.StartSpace`); ``None``: the spec's own
            (``Spec.starts``), else the env's.
        seeds: the runs to falsify; ``None``: every run.
        examples: guided episodes per run at most; ``uniform``: uniform draws for the failure rate.
        search_seed: the seed of the search.
        database: the Hypothesis example database directory counterexamples are stored in and
            replayed from; default ``<cache_dir>/falsify``.
        progress: called with a line per round of the search; ``None`` for silence.
        score: the robustness score that steers the search: ``"last"``, each key's margin in the episode's last
            state (the default), or ``"episode"``, over the whole episode (signal temporal logic's; dearer per
            episode, not better on docs/guide/falsify.md's held-out agents).
        weaker, importance: as :func:`specguard.falsify.search.falsify`'s: episodes per level of the agent made
            weaker, for the failure predictor (0: none; each run's looks are its data without them), and episodes
            of the failure rate by importance sampling (0: none).

    Returns:
        Per seed, what was found (:class:`~specguard.falsify.search.Falsification`).

    Raises:
        SpecError: a run was not cached (:func:`specguard.engine.result_models.load_run`).
        InvalidSpec: ``score`` is not one of ``SCORES`` (:data:`specguard.falsify.robustness.SCORES`).

    Example:
        >>> import specguard as sg
        >>> result = sg.run_spec(spec)  # doctest: +SKIP
        >>> for seed, found in sg.falsify_runs(result, sg.StartSpace({"theta": (-0.2, 0.2)})).items():  # doctest: +SKIP
        ...     print(seed, found.report())
    """
    check_choice("falsify_runs", "score", score, SCORES)
    found = {}
    looks = {r.seed: r.looks for r in result.runs}
    for seed in seeds if seeds is not None else [r.seed for r in result.runs]:
        spec, model, normalizer = load_run(result, seed)
        found[seed] = falsify_run(
            spec,
            model,
            normalizer,
            seed=seed,
            spec_key=result.spec_key,
            starts=starts,
            examples=examples,
            uniform=uniform,
            search_seed=search_seed,
            database=database if database is not None else (Path(result.cache_dir or ".") / "falsify"),
            progress=progress,
            score=score,
            related=from_looks(looks.get(seed, []), property_keys(spec)),
            weaker=weaker,
            importance=importance,
        )
    return found


def falsify_run(
    spec: Spec,
    model: Any,
    normalizer: Any,
    *,
    seed: int,
    spec_key: str | None,
    starts: StartSpace | None = None,
    examples: int = 200,
    uniform: int = 100,
    search_seed: int = 0,
    database: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
    score: str = "last",
    related: FailureData | None = None,
    weaker: int = 0,
    importance: int = 0,
) -> Falsification:
    """Search the start space of run ``seed`` of ``spec`` for a start from which its policy misses the spec.

    Args:
        starts: the start space; ``None``: :func:`start_space`'s (the spec's own, else the env's).
        database: the directory of the Hypothesis example database; ``None``: nothing stored or replayed.
        related: the run's looks as failure data (:func:`~specguard.falsify.predictor.from_looks`), which
            :func:`falsify_runs` gives.
        Others: as :func:`specguard.falsify.search.falsify`.
    """
    from hypothesis.database import DirectoryBasedExampleDatabase

    from specguard.error import SpecError

    if spec.baseline:
        raise SpecError(
            f"Spec {spec.label!r}: falsify needs a spec trained on the constructed env, not a baseline spec",
            hint="falsify the spec itself; a baseline's episodes end as the initial env says",
        )
    check_choice(f"falsify_run({spec.label!r})", "score", score, SCORES)
    space = start_space(spec, starts)
    act = batch_policy(model, normalizer, spec.deterministic)
    runner = EpisodeRunner(spec.make_env, act, space, property_keys(spec), score=score)
    db = DirectoryBasedExampleDatabase(str(database)) if database is not None and spec_key else None
    key = database_key(spec_key, seed, space) if spec_key else ""
    label = f"{spec.label} seed {seed}"
    return _search(
        runner,
        spec,
        label,
        db,
        key,
        examples,
        uniform,
        search_seed,
        progress,
        related=related,
        weaker=weaker,
        importance=importance,
    )


def falsify_agent(
    spec: Spec,
    agent: Any,
    starts: StartSpace | None = None,
    *,
    examples: int = 200,
    uniform: int = 100,
    search_seed: int = 0,
    database: str | Path | None = None,
    progress: Callable[[str], None] | None = None,
    observation: str = "env",
    wrap: Callable[[Any], Any] | None = None,
    algorithm: str | type | None = None,
    score: str = "last",
    trust: bool = False,
    weaker: int = 0,
    importance: int = 0,
) -> Falsification:
    """Search ``starts`` for a start from which ``agent``, trained elsewhere, misses ``spec`` (training nothing).

    The agent acts in the env :func:`~specguard.engine.check_agent.check_agent` judges it in, each start's episode
    ending as that env ends it: by default the initial env's own observation and episodes (a root goal that holds
    until the end is missed by an episode the initial env terminates, docs/semantics.md).

    Args:
        spec: the spec; its property (:func:`property_keys`), ``confidence`` and ``deterministic`` apply.
        agent: an :class:`~specguard.agents.agent.Agent`, or anything
            :func:`~specguard.agents.sources.load_agent` takes; asked for a batch of observations at once (a callable
            for one observation is asked row by row).
        starts: the start space; ``None``: :func:`start_space`'s (the spec's own, else the env's).
        database: the directory of the Hypothesis example database; ``None``: nothing stored or replayed.
        observation, wrap, algorithm, trust: what the agent sees and how it is loaded, as for ``check_agent``.
        score: the robustness score that steers the search, as for :func:`falsify_runs`.
        weaker: episodes per level of the agent made weaker (``epsilon``-random actions), the failure predictor's
            data (:func:`specguard.falsify.search.falsify`); 0, the default: no predictor (an agent trained
            elsewhere brings no looks).
        Others: as :func:`specguard.falsify.search.falsify`.

    Raises:
        AgentError: the agent cannot be loaded or raised; :class:`~specguard.error.AgentMismatch` before any
            episode when its spaces do not fit the env's.
        InvalidSpec: an argument is out of range or not one of its choices.

    Example:
        >>> import specguard as sg
        >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
        >>> balance = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")
        >>> spec = sg.Spec(cartpole, balance, budget=sg.Budget(timesteps=1))
        >>> found = falsify_agent(spec, lambda obs: int(obs[2] > 0), sg.StartSpace({"theta": (-0.1, 0.1)}),
        ...                       examples=4, uniform=0)
        >>> found.found, found.counterexample.judgement.missed
        (True, ('balance',))
    """
    from hypothesis.database import DirectoryBasedExampleDatabase

    from specguard.agents.agent import check_fits
    from specguard.cache.fingerprint import fingerprint_spec
    from specguard.engine.check_agent import AGENT_OBSERVATIONS, agent_envs, agent_wrap, spec_agent
    from specguard.error import InvalidSpec
    from specguard.utils.text import function_text, shown

    if not isinstance(spec, Spec):
        raise InvalidSpec("falsify_agent", f"expected a Spec, got {shown(spec)}", hint="falsify_agent(spec, agent)")
    where = f"falsify_agent({spec.label!r})"
    check_choice(where, "observation", observation, AGENT_OBSERVATIONS)
    check_choice(where, "score", score, SCORES)
    acting = spec_agent(spec, agent, algorithm=algorithm, batch=True, trust=trust)
    fresh = _fresh_copy(agent) if acting.model is None else None  # a callable's, before it is ever asked
    space = start_space(spec, starts)
    make = agent_envs(spec, observation, agent_wrap(acting, wrap))  # wrap=, else its config's frame_stack, ...
    runner = EpisodeRunner(make, acting, space, property_keys(spec), score=score)
    check_fits(acting, runner.observation_space, runner.action_space)  # before any episode
    db, key = None, ""
    if database is not None:
        seen = observation + (f" through {function_text(wrap)}" if wrap is not None else "")
        key = database_key(fingerprint_spec(spec).spec_key, None, space, agent=f"{acting.identity} {seen}")
        db = DirectoryBasedExampleDatabase(str(database))
    label = f"{spec.label} agent {acting.name}"
    found = _search(
        runner, spec, label, db, key, examples, uniform, search_seed, progress, weaker=weaker, importance=importance
    )
    if found.counterexample is not None and acting.model is None:
        _replay_afresh(
            runner, found, fresh, lambda a: spec_agent(spec, a, algorithm=algorithm, batch=True, trust=trust), label
        )
    return found


def _fresh_copy(agent: Any) -> Any:
    """A deep copy of a callable agent as given, before any episode (``None``: it cannot be copied)."""
    import copy

    try:
        return copy.deepcopy(agent)
    except Exception:
        return None


def _replay_afresh(
    runner: EpisodeRunner, found: Falsification, fresh: Any, load: Callable[[Any], Any], label: str
) -> None:
    """Replay the counterexample with ``fresh``, a copy of a callable agent made before the search: a callable that
    keeps state across episodes (a step counter, a memory) acts from the counterexample as it had come to act after
    the search's episodes, not as it does from a start of its own. Where the copy meets the spec from it, or the
    agent cannot be copied, the report says so and a warning is raised. ``load`` makes the copy the agent the
    search ran (as ``falsify_agent`` loaded it)."""
    import warnings

    from specguard.agents.agent import Agent, check_fits

    c = found.counterexample
    assert c is not None
    if fresh is None:
        note = (
            "the agent could not be copied (copy.deepcopy failed), so the counterexample was not replayed with a "
            "fresh copy: a callable that keeps state across episodes may fail from it only after the search's episodes"
        )
    else:
        acting = fresh.batched(True) if isinstance(fresh, Agent) else load(fresh)
        check_fits(acting, runner.observation_space, runner.action_space)
        with runner.acting(acting):
            point = np.array([c.start[n] for n in runner.starts.names], dtype=np.float64)
            replay = runner.run(point[None, :])[0]
        if replay.failed:
            return
        note = (
            "NOT REPRODUCED: a fresh copy of the agent (copy.deepcopy, made before the search) meets the spec from "
            f"this counterexample ({replay.summary()}); the agent keeps state across episodes, and the counterexample "
            "and the failure rate are of the agent as the search's earlier episodes left it"
        )
    found.notes.append(note)
    warnings.warn(f"{label}: {note}", stacklevel=3)


def _search(
    runner: EpisodeRunner,
    spec: Spec,
    label: str,
    database: Any,
    key: str,
    examples: int,
    uniform: int,
    search_seed: int,
    progress: Callable[[str], None] | None,
    *,
    related: FailureData | None = None,
    weaker: int = 0,
    importance: int = 0,
) -> Falsification:
    """The search on ``runner`` at the spec's confidence, one torch thread, its progress lines labelled."""
    with one_torch_thread():
        return falsify(
            runner,
            examples=examples,
            uniform=uniform,
            seed=search_seed,
            database=database,
            key=key,
            confidence=spec.confidence,
            progress=(lambda line: progress(f"{label}: {line}")) if progress is not None else None,
            related=related,
            weaker=weaker,
            importance=importance,
        )
