"""Training one run (one seed) of a spec and measuring every goal's success (docs/semantics.md, "Success").

A run trains with the spec's trainer (:mod:`specguard.spec.trainers`: an SB3 algorithm, or the user's own loop)
for ``spec.budget.timesteps`` steps on the constructed env (or, for a baseline spec, on the initial env's own reward),
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

import functools
import inspect
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import gymnasium as gym

from specguard.construction.env import SPEC_KEY, action_masks_problem
from specguard.error import InvalidSpec, SpecError, TrainingError
from specguard.evaluation.episodes import EVAL_SEED_BASE, EVAL_SEED_STRIDE, evaluate
from specguard.evaluation.policy import policy as policy_of
from specguard.parallel.protocol import Report
from specguard.spec.algorithms import ALGORITHMS, algorithm_class, algorithm_name, takes_action_masks
from specguard.spec.spec import Spec
from specguard.spec.trainers import SB3, TrainingLoop
from specguard.stats.anytime import checkpoint_steps, final_evaluation, interim_look
from specguard.training.auto_weights import WeightAdapter
from specguard.training.curve import GoalCurve, root_success
from specguard.training.progress import ProgressEvent, decode_update, encode_update
from specguard.training.result import RunResult
from specguard.utils.text import MAX_SHOWN, elide, function_text, shown

if TYPE_CHECKING:
    from specguard.training.callback import UserCallback

__all__ = ["train_run"]

CURVE_POINTS = 10


Emit = Callable[[str, int | None, str | None], None]


@dataclass
class _Run:
    """One run being trained: its spec and seed, the model on its training envs, and its evaluation env."""

    spec: Spec
    seed: int
    model: Any
    normalizer: Any  # the training envs' VecNormalize, or None
    eval_env: gym.Env
    episode: int = 0  # where the last evaluation was, for an error's message
    started: dict[int, bool] = field(default_factory=dict)  # evaluation episode -> it started in the root goal
    terminated: dict[int, bool] = field(default_factory=dict)  # evaluation episode -> it ended by termination
    capped: dict[int, bool] = field(default_factory=dict)  # evaluation episode -> specguard's step cap cut it
    met_early: bool = False  # a checkpoint's look met every threshold and stopped training
    hit_wall_clock: bool = False  # the wall-clock cap stopped training
    stop_reason: str | None = None  # a user's callback stopped training: which, where (RunResult.stop_reason)
    log: Any = None  # the run's LogGoals callback, made when it trains: its evaluations go to the model's logger
    steps: int | None = None  # a trainer's last checkpoint's steps (Spec(trainer=...)); None: the SB3 model's
    seen: list[tuple[list[float], dict[str, int]]] = field(default_factory=list)  # the evaluation under way
    looks: list[dict[str, Any]] = field(default_factory=list)  # what each finished evaluation saw (RunResult.looks)

    @property
    def timesteps(self) -> int:
        """The steps the run trained: the SB3 model's, or the trainer's last checkpoint's."""
        return int(self.model.num_timesteps) if self.steps is None else self.steps

    @property
    def label(self) -> str:
        return f"Spec {self.spec.label!r}, seed {self.seed}"

    def episodes(self, start: int, count: int) -> dict[str, int]:
        """Evaluation episodes ``start .. start + count - 1`` of the run (its own evaluation seeds)."""
        self.episode = start
        first = EVAL_SEED_BASE + self.seed * EVAL_SEED_STRIDE
        act = policy_of(self.model, self.normalizer, deterministic=self.spec.deterministic)
        started: list[bool] = []
        terminated: list[bool] = []
        capped: list[bool] = []
        outcomes: list[dict[str, int]] = []
        starts: list[list[float]] = []
        seeds = range(first + start, first + start + count)
        counts = evaluate(act, self.eval_env, count, seeds, started, terminated, capped, outcomes, starts)
        if start == 0:  # a new evaluation (a look, or the final one) begins at its first episode
            self.seen = []
        self.seen += zip(starts, outcomes)
        # The evaluation counted is the last one run (a met checkpoint's, or the final one): keep each latest.
        self.started.update(zip(range(start, start + count), started))
        self.terminated.update(zip(range(start, start + count), terminated))
        self.capped.update(zip(range(start, start + count), capped))
        return counts

    def record_look(self, step: int) -> None:
        """Keep what the evaluation that just ended saw, at training step ``step`` (:attr:`RunResult.looks`)."""
        keys = {key for _, outcome in self.seen for key in outcome}
        self.looks.append(
            {
                "timesteps": int(step),
                "features": [[float(f"{x:.6g}") for x in start] for start, _ in self.seen],
                "held": {key: "".join(str(outcome.get(key, 0)) for _, outcome in self.seen) for key in sorted(keys)},
            }
        )
        self.seen = []

    def started_in_goal(self, episodes: int) -> int:
        """Of evaluation episodes ``0 .. episodes - 1``, those that started in the root goal."""
        return sum(self.started.get(i, False) for i in range(episodes))

    def ended_by_termination(self, episodes: int) -> int:
        """Of evaluation episodes ``0 .. episodes - 1``, those that ended by termination, not truncation."""
        return sum(self.terminated.get(i, False) for i in range(episodes))

    def cut_at_cap(self, episodes: int) -> int:
        """Of evaluation episodes ``0 .. episodes - 1``, those that specguard's step cap cut."""
        return sum(self.capped.get(i, False) for i in range(episodes))

    def failure(self, where: str, e: Exception) -> TrainingError:
        """The run's error for ``e``, raised by the env or a user function ``where`` the run was."""
        cause = str(e) if isinstance(e, SpecError) else f"the environment raised {type(e).__name__}: {e}"
        return TrainingError(f"{self.label}, {where}: {cause}")


def _masks_problem(build: Callable[[], gym.Env]) -> str | None:
    """Why the spec's env has no action masks for an algorithm that acts on them, or ``None``."""
    env = build()
    try:
        return action_masks_problem(env)
    finally:
        env.close()


def _build(spec: Spec, sb3: SB3, seed: int) -> _Run:
    """The model on the spec's training envs (normalized if its trainer asks), and the evaluation env, one
    compilation.

    Raises:
        InvalidSpec: the algorithm does not fit the action space, or SB3 rejects the hyperparameters.
        TrainingError: building the env failed.
    """
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import VecNormalize

    from specguard.training.vec_env import spec_vec_env

    label = f"Spec {spec.label!r}"
    build = spec.env_factory()  # the training envs and the evaluation env share one compiled tree
    try:
        # The constructed envs stepped together (the same steps, without a Monitor and an info copy per env); a
        # baseline's envs are the initial env's own, in make_vec_env's.
        vectorise = make_vec_env if spec.baseline else spec_vec_env
        venv = vectorise(build, n_envs=sb3.n_envs, seed=seed)
    except SpecError:
        raise
    except Exception as e:
        raise TrainingError(f"{label}, seed {seed}, building the env: {type(e).__name__}: {e}") from e
    name = algorithm_name(sb3.algorithm)
    space = type(venv.action_space).__name__
    if isinstance(sb3.algorithm, str) and space not in ALGORITHMS[sb3.algorithm]:
        venv.close()
        raise InvalidSpec(
            f"{label}.trainer.algorithm",
            f"{name} cannot act in a {space} action space; it handles {', '.join(ALGORITHMS[sb3.algorithm])}",
        )
    algorithm = algorithm_class(sb3.algorithm, f"{label}.trainer.algorithm")
    problem = _masks_problem(build) if takes_action_masks(algorithm) else None
    if problem is not None:
        venv.close()
        raise InvalidSpec(
            f"{label}.trainer.algorithm",
            f"{name} acts on action masks, and {problem}",
            hint="give the initial env an action_masks() method (sb3_contrib.common.wrappers.ActionMasker wraps one "
            "around an env), or train an algorithm without masks (PPO)",
        )
    if sb3.normalize:  # a Dict observation's "spec" part only: the features and own state, as for a Box
        venv = VecNormalize(venv, norm_obs_keys=[SPEC_KEY] if spec.observation == "features+env" else None)
    hyperparameters = dict(sb3.hyperparameters)
    if sb3.tensorboard_log is not None:  # the trainer's folder (a door's option replaced it: Spec.as_run)
        hyperparameters["tensorboard_log"] = sb3.tensorboard_log
    try:
        model = algorithm(sb3.policy, venv, seed=seed, device="cpu", verbose=0, **hyperparameters)
    except (TypeError, ValueError, AssertionError) as e:
        venv.close()
        raise InvalidSpec(f"{label}.trainer.hyperparameters", f"{name} rejected them: {e}") from e
    if hyperparameters.get("tensorboard_log") is None:
        # SB3's logger for a quiet model without a TensorBoard folder writes nothing, and learn() makes it in a
        # new empty folder /tmp/SB3-<time> each call: one left behind per run. The same logger, without the folder.
        model.set_logger(Logger(folder=None, output_formats=[]))
    normalizer = venv if isinstance(venv, VecNormalize) else None
    return _Run(spec, seed, model, normalizer, build())


Learned = tuple[GoalCurve, WeightAdapter | None, dict[str, Any], float]
"""What training a run gives its evaluation: the curve, the weight adapter, a met look's counts, the seconds."""


def _learn(run: _Run, sb3: SB3, emit: Emit) -> Learned:
    """Train the run's budget, looking at its checkpoints; the curve, the adapter, a met look's counts, the seconds.

    What stopped training early is recorded on ``run`` (``met_early``, ``hit_wall_clock``, ``stop_reason``).

    Raises:
        TrainingError: the env or a user function failed while training (the training step named) or in a
            checkpoint's evaluation (the checkpoint and evaluation episode named).
    """
    from specguard.training.callback import (
        LogGoals,
        StopTrainingOnMetCheckpoint,
        StopTrainingOnWallClock,
        training_callbacks,
    )

    spec, budget = run.spec, run.spec.budget
    looked: dict[str, Any] = {}
    # weights="auto" adapts on the constructed env's reward; a baseline trains on the initial env's own.
    adapter = None if spec.baseline else WeightAdapter.of(spec.tree)
    curve = GoalCurve(adapter)
    log = run.log = LogGoals()
    stop_on_checkpoint = StopTrainingOnMetCheckpoint(_checkpoints(spec), _looker(run, curve, looked))
    stop_on_wall_clock = StopTrainingOnWallClock(budget.wall_clock_s)
    user = _user_callbacks(run, sb3.callbacks)
    callback = training_callbacks(
        curve,
        every=budget.timesteps // CURVE_POINTS,
        total=budget.timesteps,
        report=emit,
        adapter=adapter,
        stop_on_checkpoint=stop_on_checkpoint,
        stop_on_wall_clock=stop_on_wall_clock,
        log=log,
        user=user,
    )
    emit("train", 0, None)
    start = time.perf_counter()
    try:
        run.model.learn(total_timesteps=budget.timesteps, callback=callback, tb_log_name=_log_name(run))
    except TrainingError:
        run.eval_env.close()
        raise
    except Exception as e:
        run.eval_env.close()
        raise run.failure(f"training step {run.model.num_timesteps}", e) from e
    seconds = time.perf_counter() - start
    # A look that met every threshold stopped training, even if the evaluation itself ran past the cap.
    run.met_early = stop_on_checkpoint.met_early
    run.hit_wall_clock = stop_on_wall_clock.hit_wall_clock and not run.met_early
    run.stop_reason = _stop_reason(user, budget.timesteps)
    return curve, adapter, looked, seconds


def _stop_reason(user: Sequence[UserCallback], budget: int) -> str | None:
    """What the first of the user's callbacks to stop training says of it (:attr:`RunResult.stop_reason`), or
    ``None`` when none did; a ``None`` returned (SB3 takes it as False) is named as such."""
    stopped = [c for c in user if c.stopped_at is not None]
    if not stopped:
        return None
    first = min(stopped, key=lambda c: c.stopped_at or 0)  # the order of the spec among those at one step
    reason = f"stopped by {first.name} at {first.stopped_at} of {budget} steps"
    return reason + (": its _on_step returned None, which SB3 takes as False" if first.returned_none else "")


def _checkpoints(spec: Spec) -> list[int]:
    """The steps of a run's planned looks (none without thresholds: nothing to meet early)."""
    return checkpoint_steps(spec.budget.timesteps, spec.budget.checkpoints) if spec.thresholds else []


def _looker(run: _Run, curve: GoalCurve, looked: dict[str, Any]) -> Callable[[int], bool]:
    """A look at the run's policy at a step (:func:`~specguard.stats.anytime.interim_look` on its evaluation
    episodes), recorded in ``curve`` (and the run's logger); a met look's counts go to ``looked``."""
    spec = run.spec
    confidence = spec.verdict_confidence  # corrected for every look (specguard.stats.anytime)

    def look(step: int) -> bool:
        try:
            counts, episodes, ok = interim_look(run.episodes, spec.budget.eval_episodes, spec.thresholds, confidence)
        except Exception as e:
            raise run.failure(f"checkpoint evaluation at step {step}, evaluation episode {run.episode}", e) from e
        curve.evaluated(step, counts, episodes)
        run.record_look(step)
        if run.log is not None:
            run.log.evaluated(step, counts, episodes)
        if ok:
            looked.update(counts=counts, episodes=episodes)
        return ok

    return look


def _learn_with_loop(run: _Run, loop: TrainingLoop, emit: Emit) -> Learned:
    """Run the spec's training loop through its checkpoints (:func:`specguard.training.user_loop.drive`), looking at the
    planned ones as :func:`_learn` does; the run's model is then the last agent, its steps the last checkpoint's.

    Raises:
        InvalidSpec: the trainer returned no generator.
        TrainingError: the trainer failed or yielded a bad checkpoint, or an evaluation failed (named).
    """
    from specguard.training.user_loop import drive

    spec, budget = run.spec, run.spec.budget
    looked: dict[str, Any] = {}
    curve = GoalCurve()  # the trainer's own episodes are not seen: the curve has the looks' evaluations
    look = _looker(run, curve, looked)

    def at(steps: int, agent: Any) -> bool:
        run.model, run.steps = agent, steps
        return look(steps)

    emit("train", 0, None)
    start = time.perf_counter()
    tenth = max(1, budget.timesteps // CURVE_POINTS)
    next_line = [tenth]

    def report(steps: int) -> None:
        """A checkpoint's step; a progress line at the first checkpoint past each tenth of the budget (with its
        look's root-goal success, when it was looked at: the trainer's own episodes are not seen)."""
        if steps < next_line[0]:
            emit("train", steps, None)
            return
        next_line[0] = (steps // tenth + 1) * tenth
        point = curve.points[-1] if curve.points and curve.points[-1]["timesteps"] == steps else {}
        evaluation = point.get("evaluation", {})
        line = encode_update(
            steps,
            budget.timesteps,
            time.perf_counter() - start,
            root_success(evaluation),
            point.get("evaluation_episodes", 0),
        )
        emit("train", steps, line)

    try:
        done = drive(
            loop.function,
            spec.env_factory(),
            budget.timesteps,
            run.seed,
            checkpoints=_checkpoints(spec),
            look=at,
            label=run.label,
            wall_clock_s=budget.wall_clock_s,
            report=report,
        )
    except Exception:
        run.eval_env.close()
        raise
    seconds = time.perf_counter() - start
    run.model, run.steps = done.agent, done.steps
    run.met_early = done.met_early
    run.hit_wall_clock = done.hit_wall_clock and not done.met_early
    return curve, None, looked, seconds


def _user_callbacks(run: _Run, factories: Sequence[Callable[..., Any]]) -> list[UserCallback]:
    """The trainer's callbacks of the user's, each made by its factory for this run and guarded (its errors named).

    Raises:
        TrainingError: a factory raised, or returned something that is no SB3 ``BaseCallback``.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from specguard.training.callback import UserCallback

    made = []
    for factory in factories:
        name = function_text(factory)
        try:
            callback = factory(**_run_arguments(factory, run))
        except Exception as e:
            raise TrainingError(
                f"{run.label}, making callback {name}: it raised {type(e).__name__}: {elide(str(e), MAX_SHOWN)}"
            ) from e
        if not isinstance(callback, BaseCallback):
            raise TrainingError(
                f"{run.label}, callback {name} made {shown(callback)}, not a stable_baselines3 BaseCallback"
            )
        made.append(UserCallback(callback, run.label))
    return made


RUN_ARGUMENTS = ("seed", "spec")
"""The keywords a callback factory is given when its signature names them: the run's seed and its spec."""


def _run_arguments(factory: Callable[..., Any], run: _Run) -> dict[str, Any]:
    """``seed=`` and ``spec=`` for a factory whose signature takes them by those names (not by ``**kwargs``, nor
    bound by a ``functools.partial``), so each run can write its own files (``f"checkpoints/seed_{seed}"``)."""
    try:
        parameters = inspect.signature(factory).parameters
    except (TypeError, ValueError):  # a builtin or C callable without a signature: called bare, as before
        return {}
    bound = factory.keywords if isinstance(factory, functools.partial) else {}
    given = {"seed": run.seed, "spec": run.spec}
    return {
        name: given[name]
        for name in RUN_ARGUMENTS
        if name in parameters
        and name not in bound
        and parameters[name].kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    }


def _log_name(run: _Run) -> str:
    """The run's TensorBoard subfolder (SB3's ``tb_log_name``; SB3 appends ``_<n>``): ``<spec label>/seed_<seed>``."""
    label = "".join(c if c.isalnum() or c in "-_." else "_" for c in run.spec.label) or "spec"
    return f"{label}/seed_{run.seed}"


def _evaluate(run: _Run, curve: GoalCurve, looked: Mapping[str, Any], emit: Emit) -> tuple[dict[str, int], int]:
    """The run's successes and episodes: a met checkpoint's, else the final evaluation's (recorded in the curve).

    Raises:
        TrainingError: the env or a user function failed in an evaluation episode (named).
    """
    spec = run.spec
    if run.normalizer is not None:
        run.normalizer.training = False
    emit("evaluate", 0, None)
    try:
        if run.met_early:
            counts, episodes = looked["counts"], looked["episodes"]
        else:
            stages, thresholds = spec.budget.evaluation_stages, spec.thresholds
            counts, episodes = final_evaluation(run.episodes, stages, thresholds, spec.verdict_confidence)
            curve.evaluated(run.timesteps, counts, episodes)
            run.record_look(run.timesteps)
            if run.log is not None:
                run.log.evaluated(run.timesteps, counts, episodes, write=True)
        emit("evaluate", episodes, None)
    except Exception as e:
        raise run.failure(f"evaluation episode {run.episode}", e) from e
    finally:
        run.eval_env.close()
    return counts, episodes


@functools.singledispatch
def _train(trainer: Any, spec: Spec, seed: int, emit: Emit) -> tuple[_Run, Learned]:
    """Train run ``seed`` of ``spec`` with ``trainer``: the run and what it learned (one implementation per trainer
    class of :mod:`specguard.spec.trainers`, registered below)."""
    raise InvalidSpec(
        f"Spec {spec.label!r}.trainer",
        f"specguard cannot train with {shown(trainer)}; it trains with sg.SB3(...) or a training loop of yours",
    )


@_train.register
def _train_sb3(trainer: SB3, spec: Spec, seed: int, emit: Emit) -> tuple[_Run, Learned]:
    run = _build(spec, trainer, seed)
    return run, _learn(run, trainer, emit)


@_train.register
def _train_loop(trainer: TrainingLoop, spec: Spec, seed: int, emit: Emit) -> tuple[_Run, Learned]:
    # The loop's agent trains on envs it makes; it is evaluated on one of the spec's, as an SB3 model is.
    run = _Run(spec, seed, None, None, spec.make_env())
    return run, _learn_with_loop(run, trainer, emit)


def train_run(
    spec: Spec,
    seed: int,
    progress: Callable[[ProgressEvent], None] | None = None,
    *,
    report: Report | None = None,
) -> tuple[RunResult, Any]:
    """Train and evaluate one run of ``spec`` with ``seed``: build, learn, evaluate.

    ``progress``, if given, receives a :class:`~specguard.training.progress.ProgressEvent`
    at each of the learning curve's points (every tenth of the budget), as
    ``run_spec``'s ``progress`` does (``print_event`` prints it). ``report``, if given,
    receives ``(phase, step, line)`` as the run moves through building the
    env, training and evaluation (worker processes pass it to the parent).

    A spec whose trainer is the user's own loop trains with it (:mod:`specguard.training.user_loop`): its checkpoints
    are looked at as SB3's are, and its last agent is evaluated as an SB3 model is.

    Returns:
        The result and the trained model (an SB3 ``BaseAlgorithm``; with a training loop, its last agent).

    Raises:
        InvalidSpec: the algorithm does not fit the action space, or SB3
            rejects the hyperparameters (its message, attributed to the spec); a training loop returned no generator;
            the spec's trainer is one specguard cannot run.
        TrainingError: the env or a user function failed; the message has the
            seed and the training step, or the checkpoint and evaluation episode.
    """
    import torch

    torch.set_num_threads(1)

    def emit(phase: str, step: int | None, line: str | None) -> None:
        if report is not None:
            report(phase, step, line)
        if progress is not None and line is not None:
            progress(decode_update(spec.label, seed, line))

    emit("build", None, None)
    run, (curve, adapter, looked, train_seconds) = _train(spec.trainer, spec, seed, emit)
    counts, episodes = _evaluate(run, curve, looked, emit)
    result = RunResult(
        spec=spec.label,
        seed=seed,
        timesteps=run.timesteps,
        episodes=episodes,
        successes=counts,
        train_seconds=train_seconds,
        hit_wall_clock=run.hit_wall_clock,
        curve=curve.points,
        met_early=run.met_early,
        weights={} if adapter is None else adapter.in_force_lists(),
        started_in_goal=run.started_in_goal(episodes),
        terminated=run.ended_by_termination(episodes),
        capped=run.cut_at_cap(episodes),
        stop_reason=run.stop_reason,
        looks=run.looks,
    )
    return result, run.model
