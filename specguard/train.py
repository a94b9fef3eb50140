"""Training one run (one seed) of a spec and measuring every goal's success (SPEC.md section 3).

A run trains ``spec.algorithm`` for ``spec.budget.timesteps`` steps on the
constructed env (or, for a baseline spec, on the initial env's own reward),
then evaluates the policy on episodes whose seeds are disjoint from training:
training envs are seeded ``seed .. seed + n_envs - 1`` (as ``make_vec_env``
does), evaluation episode ``i`` of run ``seed`` uses
``EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE + i``.

A goal succeeds in an episode when the episode's last state lies in it,
whether the episode terminated or was truncated. A safety annotation
(``Constraint``, ``Avoid``: ``role == "safety"``) counts the episodes without a
violation, read from the last step's ``info["safe"]``; its count is stored
beside the goals' under its key ``path:name`` (:mod:`specguard.goals`), so
verdicts, intervals, caches and baselines treat both alike.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

import gymnasium as gym

from specguard.env import make_baseline_env, make_env
from specguard.error import InvalidSpec, SpecError
from specguard.progress import decode_update, encode_update, format_event
from specguard.spec import ALGORITHMS, Spec
from specguard.stats import RunVerdict, run_verdict
from specguard.workers import Report

__all__ = [
    "EVAL_SEED_BASE",
    "EVAL_SEED_STRIDE",
    "RunResult",
    "TrainingError",
    "evaluate",
    "make_single_env",
    "train_run",
]

EVAL_SEED_BASE = 1_000_000
EVAL_SEED_STRIDE = 100_000
CURVE_POINTS = 10


class TrainingError(SpecError):
    """The environment or a user function failed while a run trained or was evaluated."""

    default_hint = "reproduce it without training: build sg.make_env(...) and step it from the seed named above"


@dataclass
class RunResult:
    """What one run measured; plain data (``to_dict`` is JSON-serialisable).

    Attributes:
        spec: the spec's label.
        seed: the training seed.
        timesteps: environment steps actually trained.
        episodes: evaluation episodes.
        successes: per node path, evaluation episodes whose last state lies in the goal;
            then per safety key (``path:name``), evaluation episodes without a violation.
        train_seconds: wall-clock training time.
        stopped_early: training hit the budget's wall-clock cap.
        curve: success per goal (and safety rate per safety key) over training
            episodes (stochastic policy),
            ``[{"timesteps": t, "episodes": n, "success": {key: rate}}, ...]``.
    """

    spec: str
    seed: int
    timesteps: int
    episodes: int
    successes: dict[str, int]
    train_seconds: float
    stopped_early: bool = False
    curve: list[dict[str, Any]] = field(default_factory=list)

    def verdicts(self, thresholds: Mapping[str, float], confidence: float = 0.95) -> dict[str, RunVerdict]:
        return {p: run_verdict(self.successes[p], self.episodes, t, confidence) for p, t in thresholds.items()}

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _policy_action(space: gym.Space[Any], action: Any) -> Any:
    return int(action) if isinstance(space, gym.spaces.Discrete) else action


def _count_episode(counts: dict[str, int], info: Mapping[str, Any]) -> None:
    """Add one finished episode's last ``info``: its goals (by path), then its safety (by ``path:name``)."""
    for key, ok in info["goals"].items():
        counts[key] = counts.get(key, 0) + int(ok)
    for key, ok in info.get("safe", {}).items():
        counts[key] = counts.get(key, 0) + int(ok)


def evaluate(policy: Callable[[Any], Any], env: gym.Env, episodes: int, seeds: list[int] | range) -> dict[str, int]:
    """Run ``episodes`` episodes of ``policy`` on ``env`` (which reports ``info["goals"]`` and ``info["safe"]``).

    Returns:
        Per node path, the number of episodes whose last state lies in the
        goal; then per safety key (``path:name``), the number of episodes
        without a violation (the last step's ``info["safe"]``).
    """
    counts: dict[str, int] = {}
    for i in range(episodes):
        obs, info = env.reset(seed=seeds[i])
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(_policy_action(env.action_space, policy(obs)))
            done = terminated or truncated
        _count_episode(counts, info)
    return counts


def make_single_env(spec: Spec) -> gym.Env:
    """The env one run trains on: the constructed env, or for a baseline spec the initial env with goal info."""
    if spec.baseline:
        return make_baseline_env(spec.initial_env, spec.tree)
    return make_env(spec.initial_env, spec.tree)


TICKS = 100  # step reports per run (cheap; they tell where a run was when it died)


class _GoalCurve:
    """An SB3 callback body: success per goal (and safety rate) over finished training episodes, and the cap."""

    def __init__(self, every: int, wall_clock_s: float | None, total: int, report: Report | None) -> None:
        self.every = max(1, every)
        self.total = total
        self.report = report
        self._tick = max(1, total // TICKS)
        self._next_tick = self._tick
        self.start = time.perf_counter()
        self.deadline = None if wall_clock_s is None else time.perf_counter() + wall_clock_s
        self.points: list[dict[str, Any]] = []
        self._counts: dict[str, int] = {}
        self._episodes = 0
        self._next = self.every
        self.stopped_early = False

    def on_step(self, num_timesteps: int, dones: Any, infos: list[dict[str, Any]]) -> bool:
        for done, info in zip(dones, infos):
            if done and "goals" in info:
                self._episodes += 1
                _count_episode(self._counts, info)
        if self.report is not None and num_timesteps >= self._next_tick:
            self._next_tick = num_timesteps + self._tick
            self.report("train", num_timesteps, None)
        if num_timesteps >= self._next:
            self._next += self.every
            if self._episodes:
                rates = {p: c / self._episodes for p, c in self._counts.items()}
                self.points.append({"timesteps": num_timesteps, "episodes": self._episodes, "success": rates})
            if self.report is not None:  # numbers, as JSON: the parent makes the event (specguard.progress)
                root = next(iter(rates.values())) if self._episodes else None  # goals come first, the root first
                elapsed = time.perf_counter() - self.start
                line = encode_update(num_timesteps, self.total, elapsed, root, self._episodes)
                self.report("train", num_timesteps, line)
            self._counts, self._episodes = {}, 0
        if self.deadline is not None and time.perf_counter() > self.deadline:
            self.stopped_early = True
            return False
        return True


def train_run(
    spec: Spec,
    seed: int,
    progress: Callable[[str], None] | None = None,
    *,
    report: Report | None = None,
) -> tuple[RunResult, Any]:
    """Train and evaluate one run of ``spec`` with ``seed``.

    ``progress``, if given, receives a formatted line (:mod:`specguard.progress`)
    at each of the learning curve's points (every tenth of the budget). ``report``, if given,
    receives ``(phase, step, line)`` as the run moves through building the
    env, training and evaluation (worker processes pass it to the parent).

    Returns:
        The result and the trained model (an SB3 ``BaseAlgorithm``).

    Raises:
        InvalidSpec: the algorithm does not fit the action space, or SB3
            rejects the hyperparameters (its message, attributed to the spec).
        TrainingError: the env or a user function failed; the message has the
            seed and the training step.
    """
    import stable_baselines3
    import torch
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(1)
    label = f"Spec {spec.label!r}"

    def emit(phase: str, step: int | None, line: str | None) -> None:
        if report is not None:
            report(phase, step, line)
        if progress is not None and line is not None:
            progress(format_event(decode_update(spec.label, seed, line)))

    emit("build", None, None)
    try:
        venv = make_vec_env(lambda: make_single_env(spec), n_envs=spec.n_envs, seed=seed)
    except SpecError:
        raise
    except Exception as e:
        raise TrainingError(f"{label}, seed {seed}, building the env: {type(e).__name__}: {e}") from e
    space = type(venv.action_space).__name__
    if space not in ALGORITHMS[spec.algorithm]:
        venv.close()
        raise InvalidSpec(
            f"{label}.algorithm",
            f"{spec.algorithm} cannot act in a {space} action space; "
            f"it handles {', '.join(ALGORITHMS[spec.algorithm])}",
        )
    if spec.normalize:
        venv = VecNormalize(venv)
    try:
        algorithm = getattr(stable_baselines3, spec.algorithm)
        model = algorithm("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **dict(spec.hyperparameters))
    except (TypeError, ValueError, AssertionError) as e:
        venv.close()
        raise InvalidSpec(f"{label}.hyperparameters", f"{spec.algorithm} rejected them: {e}") from e

    budget = spec.budget
    curve = _GoalCurve(budget.timesteps // CURVE_POINTS, budget.wall_clock_s, budget.timesteps, emit)

    class Callback(BaseCallback):  # type: ignore[misc]
        def _on_step(self) -> bool:
            return curve.on_step(self.num_timesteps, self.locals["dones"], self.locals["infos"])

    emit("train", 0, None)
    start = time.perf_counter()
    try:
        model.learn(total_timesteps=budget.timesteps, callback=Callback())
    except SpecError as e:
        raise TrainingError(f"{label}, seed {seed}, training step {model.num_timesteps}: {e}") from e
    except Exception as e:
        raise TrainingError(
            f"{label}, seed {seed}, training step {model.num_timesteps}: the environment raised {type(e).__name__}: {e}"
        ) from e
    train_seconds = time.perf_counter() - start

    normalizer = venv if isinstance(venv, VecNormalize) else None
    if normalizer is not None:
        normalizer.training = False

    def policy(obs: Any) -> Any:
        if normalizer is not None:
            obs = normalizer.normalize_obs(obs)
        return model.predict(obs, deterministic=spec.deterministic)[0]

    eval_env = make_single_env(spec)
    seeds = range(EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE, EVAL_SEED_BASE + (seed + 1) * EVAL_SEED_STRIDE)
    counts: dict[str, int] = {}
    episodes = 0
    chunk = budget.eval_episodes
    assert budget.max_eval_episodes is not None
    emit("evaluate", 0, None)
    try:
        while True:
            more = evaluate(policy, eval_env, chunk, seeds[episodes : episodes + chunk])
            emit("evaluate", episodes + chunk, None)
            counts = {p: counts.get(p, 0) + c for p, c in more.items()}
            episodes += chunk
            undecided = [
                p
                for p, t in spec.thresholds.items()
                if run_verdict(counts[p], episodes, t, spec.confidence) is RunVerdict.UNDECIDED
            ]
            # An undecided run first gets more (cheap) evaluation episodes before it is called.
            chunk = min(episodes, budget.max_eval_episodes - episodes)
            if not undecided or chunk <= 0:
                break
    except SpecError as e:
        raise TrainingError(f"{label}, seed {seed}, evaluation episode {episodes}: {e}") from e
    except Exception as e:
        raise TrainingError(
            f"{label}, seed {seed}, evaluation episode {episodes}: the environment raised {type(e).__name__}: {e}"
        ) from e
    finally:
        eval_env.close()
    result = RunResult(
        spec=spec.label,
        seed=seed,
        timesteps=int(model.num_timesteps),
        episodes=episodes,
        successes=counts,
        train_seconds=train_seconds,
        stopped_early=curve.stopped_early,
        curve=curve.points,
    )
    return result, model
