"""Training one run (one seed) of a spec and measuring every goal's success (docs/semantics.md, "Success").

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
beside the goals' under its key ``path:name`` (:mod:`specguard.tree.keys`), so
verdicts, intervals, caches and baselines treat both alike.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym

from specguard.construction.env import EnvFactory
from specguard.error import InvalidSpec, SpecError, TrainingError
from specguard.parallel.protocol import Report
from specguard.spec.algorithms import ALGORITHMS, algorithm_class
from specguard.spec.spec import Spec
from specguard.stats.anytime import checkpoint_steps, final_evaluation, interim_look
from specguard.training.auto_weights import WeightAdapter
from specguard.training.progress import ProgressEvent, decode_update, encode_update
from specguard.training.result import RunResult

__all__ = [
    "EVAL_SEED_BASE",
    "EVAL_SEED_STRIDE",
    "RunResult",
    "TrainingError",
    "env_factory",
    "evaluate",
    "make_single_env",
    "train_run",
]

EVAL_SEED_BASE = 1_000_000
EVAL_SEED_STRIDE = 100_000
CURVE_POINTS = 10


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


def env_factory(spec: Spec) -> EnvFactory:
    """Builds the envs of one run (:func:`make_single_env`'s), compiling the spec's tree once for all of them."""
    return EnvFactory(spec.initial_env, spec.tree, baseline=spec.baseline)


def make_single_env(spec: Spec) -> gym.Env:
    """The env one run trains on: the constructed env, or for a baseline spec the initial env with goal info."""
    return env_factory(spec)()


TICKS = 100  # step reports per run (cheap; they tell where a run was when it died)


Look = Callable[[int], bool]
"""An interim checkpoint: evaluates the policy at a training step; True when every threshold is met."""


class _GoalCurve:
    """An SB3 callback body: success per goal over finished training episodes, checkpoints, and the cap.

    A curve point is made at every tenth of the budget and at every interim
    checkpoint (:mod:`specguard.stats.anytime`); a checkpoint's evaluation is stored
    in its point under ``"evaluation"``, and a met one stops training. An
    ``adapter`` (``weights="auto"``) sees every finished training episode, and
    each point records the weights in force (:mod:`specguard.training.auto_weights`).
    """

    def __init__(
        self,
        every: int,
        wall_clock_s: float | None,
        total: int,
        report: Report | None,
        checkpoints: list[int] | None = None,
        look: Look | None = None,
        adapter: WeightAdapter | None = None,
    ) -> None:
        self.every = max(1, every)
        self.total = total
        self.report = report
        self.checkpoints = list(checkpoints or [])
        self.look = look
        self.adapter = adapter
        self._tick = max(1, total // TICKS)
        self._next_tick = self._tick
        self.start = time.perf_counter()
        self.deadline = None if wall_clock_s is None else time.perf_counter() + wall_clock_s
        self.points: list[dict[str, Any]] = []
        self._counts: dict[str, int] = {}
        self._episodes = 0
        self._next = self.every
        self.hit_wall_clock = False
        self.met_early = False

    def on_step(self, num_timesteps: int, dones: Any, infos: list[dict[str, Any]]) -> bool:
        for done, info in zip(dones, infos):
            if done and "goals" in info:
                self._episodes += 1
                _count_episode(self._counts, info)
                if self.adapter is not None:
                    self.adapter.observe(info["goals"], info.get("safe"))
        if self.report is not None and num_timesteps >= self._next_tick:
            self._next_tick = num_timesteps + self._tick
            self.report("train", num_timesteps, None)
        looking = bool(self.checkpoints) and num_timesteps >= self.checkpoints[0]
        if num_timesteps >= self._next or looking:
            while self._next <= num_timesteps:
                self._next += self.every
            self._point(num_timesteps)
        if looking:
            while self.checkpoints and self.checkpoints[0] <= num_timesteps:
                self.checkpoints.pop(0)
            assert self.look is not None
            if self.look(num_timesteps):
                self.met_early = True
                return False
        if self.deadline is not None and time.perf_counter() > self.deadline:
            self.hit_wall_clock = True
            return False
        return True

    def _point(self, num_timesteps: int) -> None:
        rates = {p: c / self._episodes for p, c in self._counts.items()} if self._episodes else {}
        self._append(num_timesteps, self._episodes, rates)
        if self.report is not None:  # numbers, as JSON: the parent makes the event (specguard.training.progress)
            root = next(iter(rates.values())) if rates else None  # goals come first, the root first
            elapsed = time.perf_counter() - self.start
            line = encode_update(num_timesteps, self.total, elapsed, root, self._episodes)
            self.report("train", num_timesteps, line)
        self._counts, self._episodes = {}, 0

    def _append(self, num_timesteps: int, episodes: int, rates: dict[str, float]) -> None:
        point: dict[str, Any] = {"timesteps": num_timesteps, "episodes": episodes, "success": rates}
        if self.adapter is not None:
            point["weights"] = self.adapter.in_force_lists()
        self.points.append(point)

    def evaluated(self, num_timesteps: int, counts: Mapping[str, int], episodes: int) -> None:
        """Record an evaluation at ``num_timesteps`` in the curve (a point of its own if none is there)."""
        if not self.points or self.points[-1]["timesteps"] != num_timesteps:
            self._append(num_timesteps, 0, {})
        self.points[-1]["evaluation"] = {p: c / episodes for p, c in counts.items()}
        self.points[-1]["evaluation_episodes"] = episodes


def train_run(
    spec: Spec,
    seed: int,
    progress: Callable[[ProgressEvent], None] | None = None,
    *,
    report: Report | None = None,
) -> tuple[RunResult, Any]:
    """Train and evaluate one run of ``spec`` with ``seed``.

    ``progress``, if given, receives a :class:`~specguard.training.progress.ProgressEvent`
    at each of the learning curve's points (every tenth of the budget), as
    ``run_spec``'s ``progress`` does (``print_event`` prints it). ``report``, if given,
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
            progress(decode_update(spec.label, seed, line))

    emit("build", None, None)
    build = env_factory(spec)  # the training envs and the evaluation env share one compiled tree
    try:
        venv = make_vec_env(build, n_envs=spec.n_envs, seed=seed)
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
        algorithm = algorithm_class(spec.algorithm)
        model = algorithm("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **dict(spec.hyperparameters))
    except (TypeError, ValueError, AssertionError) as e:
        venv.close()
        raise InvalidSpec(f"{label}.hyperparameters", f"{spec.algorithm} rejected them: {e}") from e

    budget = spec.budget
    confidence = spec.verdict_confidence  # corrected for every look (specguard.stats.anytime)
    eval_env = build()
    seeds = range(EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE, EVAL_SEED_BASE + (seed + 1) * EVAL_SEED_STRIDE)
    normalizer = venv if isinstance(venv, VecNormalize) else None

    def policy(obs: Any) -> Any:
        if normalizer is not None:
            obs = normalizer.normalize_obs(obs)
        return model.predict(obs, deterministic=spec.deterministic)[0]

    at = {"episode": 0}  # where an evaluation was, for an error's message

    def episodes_of(start: int, count: int) -> dict[str, int]:
        at["episode"] = start
        return evaluate(policy, eval_env, count, seeds[start : start + count])

    looked: dict[str, Any] = {}

    def look(step: int) -> bool:
        counts, episodes, ok = interim_look(episodes_of, budget.eval_episodes, spec.thresholds, confidence)
        curve.evaluated(step, counts, episodes)
        if ok:
            looked.update(counts=counts, episodes=episodes)
        return ok

    checkpoints = checkpoint_steps(budget.timesteps, budget.checkpoints) if spec.thresholds else []
    # weights="auto" adapts on the constructed env's reward; a baseline trains on the initial env's own.
    adapter = None if spec.baseline else WeightAdapter.of(spec.tree)
    curve = _GoalCurve(
        budget.timesteps // CURVE_POINTS,
        budget.wall_clock_s,
        budget.timesteps,
        emit,
        checkpoints,
        look,
        adapter=adapter,
    )

    class Callback(BaseCallback):  # type: ignore[misc]
        def _on_step(self) -> bool:
            return curve.on_step(self.num_timesteps, self.locals["dones"], self.locals["infos"])

        def _on_rollout_end(self) -> None:
            # Between rollouts, so every env switches at its next reset (specguard.training.auto_weights).
            if adapter is not None and adapter.update() is not None:
                self.training_env.env_method("set_weights", adapter.in_force)

    emit("train", 0, None)
    start = time.perf_counter()
    try:
        model.learn(total_timesteps=budget.timesteps, callback=Callback())
    except SpecError as e:
        eval_env.close()
        raise TrainingError(f"{label}, seed {seed}, training step {model.num_timesteps}: {e}") from e
    except Exception as e:
        eval_env.close()
        raise TrainingError(
            f"{label}, seed {seed}, training step {model.num_timesteps}: the environment raised {type(e).__name__}: {e}"
        ) from e
    train_seconds = time.perf_counter() - start

    if normalizer is not None:
        normalizer.training = False

    emit("evaluate", 0, None)
    try:
        if curve.met_early:
            counts, episodes = looked["counts"], looked["episodes"]
        else:
            counts, episodes = final_evaluation(episodes_of, budget.evaluation_stages, spec.thresholds, confidence)
            curve.evaluated(int(model.num_timesteps), counts, episodes)
        emit("evaluate", episodes, None)
    except SpecError as e:
        raise TrainingError(f"{label}, seed {seed}, evaluation episode {at['episode']}: {e}") from e
    except Exception as e:
        raise TrainingError(
            f"{label}, seed {seed}, evaluation episode {at['episode']}: the environment raised {type(e).__name__}: {e}"
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
        hit_wall_clock=curve.hit_wall_clock,
        curve=curve.points,
        met_early=curve.met_early,
        weights={} if adapter is None else adapter.in_force_lists(),
    )
    return result, model
