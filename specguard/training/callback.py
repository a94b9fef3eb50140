"""The SB3 callbacks of a training run, one job each, and their composition (:func:`training_callbacks`).

At every step, in this order:

* :class:`RecordGoalCurve` counts each finished episode's goals into the
  learning curve (:mod:`specguard.training.curve`) and makes a point at every
  tenth of the budget and at every interim checkpoint;
* :class:`AdaptWeights` feeds each finished episode to the weight adapter
  (``weights="auto"``) and switches the envs' weights after each rollout;
* :class:`ReportProgress` reports the step at every hundredth of the budget,
  and a progress line at each point and at a hundredth when none was sent
  for :data:`HEARTBEAT_S`;
* :class:`StopTrainingOnMetCheckpoint` evaluates the policy at each interim
  checkpoint, after that step's point, and stops training once every
  threshold is met;
* :class:`StopTrainingOnWallClock` stops training at the budget's wall-clock cap;
* :class:`LogGoals` records each goal's success and each constraint's safety through SB3's logger (the logs
  users already read: stdout, CSV, TensorBoard), over the training episodes of each rollout and at each evaluation;
* the user's own callbacks (``Spec(callbacks=...)``), each behind :class:`UserCallback`, which names it when it
  raises.

They are composed as SB3 composes its own (``CallbackList``,
``StopTrainingOnMaxEpisodes``), and each may be tested alone with a model that
has ``num_timesteps`` and a ``locals`` with ``dones`` and ``infos``.
Stable-baselines3 is imported with this module; :mod:`specguard.training.train`
imports it only when a run trains.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from specguard.error import SpecError, SpecWarning, TrainingError
from specguard.evaluation.episodes import count_episode
from specguard.training.curve import root_success
from specguard.training.progress import encode_update
from specguard.utils.text import MAX_SHOWN, elide, function_text

if TYPE_CHECKING:
    from specguard.parallel.protocol import Report
    from specguard.training.auto_weights import WeightAdapter
    from specguard.training.curve import GoalCurve

__all__ = [
    "HEARTBEAT_S",
    "TICKS",
    "AdaptWeights",
    "LogGoals",
    "Look",
    "RecordGoalCurve",
    "ReportProgress",
    "StopTrainingOnMetCheckpoint",
    "StopTrainingOnWallClock",
    "UserCallback",
    "log_key",
    "training_callbacks",
]

TICKS = 100  # step reports per run (cheap; they tell where a run was when it died)
HEARTBEAT_S = 30.0  # at a tick, a progress line once this long passed since the last (a long tenth is not silent)

Look = Callable[[int], bool]
"""An interim checkpoint: evaluates the policy at a training step; True when every threshold is met."""


def _finished(locals_: Mapping[str, Any]) -> Iterator[Mapping[str, Any]]:
    """The last ``info`` of each episode that ended at this step (a spec's env reports its ``"goals"`` there)."""
    for done, info in zip(locals_["dones"], locals_["infos"]):
        if done and "goals" in info:
            yield info


class RecordGoalCurve(BaseCallback):  # type: ignore[misc]
    """Counts every finished training episode into ``curve``; a point every ``every`` steps and at each checkpoint.

    Args:
        curve: the run's learning curve.
        every: steps between points (a tenth of the budget).
        checkpoints: the interim checkpoints' steps: a point at each, for its evaluation to be stored in.
    """

    def __init__(self, curve: GoalCurve, every: int, checkpoints: Sequence[int] = ()) -> None:
        super().__init__()
        self.curve = curve
        self.every = max(1, every)
        self._next = self.every
        self._checkpoints = list(checkpoints)

    def _on_step(self) -> bool:
        for info in _finished(self.locals):
            self.curve.count(info)
        step = self.num_timesteps
        at_checkpoint = bool(self._checkpoints) and step >= self._checkpoints[0]
        if step >= self._next or at_checkpoint:
            while self._next <= step:
                self._next += self.every
            while self._checkpoints and self._checkpoints[0] <= step:
                self._checkpoints.pop(0)
            self.curve.point(step)
        return True


class AdaptWeights(BaseCallback):  # type: ignore[misc]
    """Feeds every finished training episode to ``adapter``, and switches the envs' weights after each rollout.

    Between rollouts, so every env switches at its next reset (:mod:`specguard.training.auto_weights`).

    Args:
        adapter: the run's weight adapter (``weights="auto"``).
    """

    def __init__(self, adapter: WeightAdapter) -> None:
        super().__init__()
        self.adapter = adapter

    def _on_step(self) -> bool:
        for info in _finished(self.locals):
            self.adapter.observe(info["goals"], info.get("safe"))
        return True

    def _on_rollout_end(self) -> None:
        if self.adapter.update() is not None:
            self.training_env.env_method("set_weights", self.adapter.in_force)


class ReportProgress(BaseCallback):  # type: ignore[misc]
    """Reports a run's progress to ``report``: its step :data:`TICKS` times a run, and a progress line at each point.

    A line (``report("train", step, line)``, :func:`~specguard.training.progress.encode_update`) gives the root
    goal's success over the episodes since the last point; at a tick, a line is sent instead of the bare step
    (``report("train", step, None)``) once :data:`HEARTBEAT_S` passed since the last one. Its clock starts when
    the callback is made. Place it after :class:`RecordGoalCurve`, which makes the points it reports.

    Args:
        curve: the run's learning curve.
        report: receives ``(phase, step, line)``.
        total: the run's budget of steps.
    """

    def __init__(self, curve: GoalCurve, report: Report, total: int) -> None:
        super().__init__()
        self.curve = curve
        self.report = report
        self.total = total
        self.tick = max(1, total // TICKS)
        self._next_tick = self.tick
        self._points = len(curve.points)
        self.start = self._said = time.perf_counter()  # when training began, when the last line was sent

    def _on_step(self) -> bool:
        step = self.num_timesteps
        made = len(self.curve.points) > self._points  # a point made at this step closed the period up to it
        self._points = len(self.curve.points)
        point = self.curve.points[-1] if made else None
        if step >= self._next_tick:
            self._next_tick = step + self.tick
            if time.perf_counter() - self._said >= HEARTBEAT_S:
                self._say(step, point)
            else:
                self.report("train", step, None)
        if point is not None:
            self._say(step, point)
        return True

    def _say(self, step: int, point: Mapping[str, Any] | None) -> None:
        """A progress line of the episodes up to ``step``: ``point``'s, else the open period's so far."""
        if point is None:
            episodes, success = self.curve.episodes, self.curve.success()
        else:
            episodes, success = point["episodes"], point["success"]
        self._said = now = time.perf_counter()
        line = encode_update(step, self.total, now - self.start, root_success(success), episodes)
        self.report("train", step, line)


class StopTrainingOnMetCheckpoint(BaseCallback):  # type: ignore[misc]
    """Looks at each interim checkpoint (``look``) and stops training once a look says every threshold is met.

    Place it after :class:`RecordGoalCurve`, so that the look's evaluation is stored in its checkpoint's point.

    Args:
        checkpoints: the interim checkpoints' steps (:func:`specguard.stats.anytime.checkpoint_steps`).
        look: evaluates the policy at a step; True when every threshold is met.
    """

    def __init__(self, checkpoints: Sequence[int], look: Look) -> None:
        super().__init__()
        self.checkpoints = tuple(checkpoints)
        self.look = look
        self._pending = list(self.checkpoints)
        self.met_early = False

    def _on_step(self) -> bool:
        step = self.num_timesteps
        if not self._pending or step < self._pending[0]:
            return True
        while self._pending and self._pending[0] <= step:
            self._pending.pop(0)
        self.met_early = self.look(step)
        return not self.met_early


class StopTrainingOnWallClock(BaseCallback):  # type: ignore[misc]
    """Stops training once ``max_seconds`` passed since the callback was made (``None``: never).

    Args:
        max_seconds: the budget's wall-clock cap, or ``None``.
    """

    def __init__(self, max_seconds: float | None) -> None:
        super().__init__()
        self.max_seconds = max_seconds
        self.deadline = None if max_seconds is None else time.perf_counter() + max_seconds
        self.hit_wall_clock = False

    def _on_step(self) -> bool:
        if self.deadline is not None and time.perf_counter() > self.deadline:
            self.hit_wall_clock = True
        return not self.hit_wall_clock


def log_key(key: str, *, evaluation: bool = False) -> str:
    """The logger's name of a goal (by path) or a safety rate (``path:name``): ``specguard/goal/<path>``,
    ``specguard/safe/<path>/<name>``; under ``specguard/eval/`` for an evaluation's.

    Example:
        >>> log_key("balance/upright"), log_key("balance:edges", evaluation=True)
        ('specguard/goal/balance/upright', 'specguard/eval/safe/balance/edges')
    """
    path, safety, name = key.partition(":")
    head = "specguard/eval" if evaluation else "specguard"
    return f"{head}/safe/{path}/{name}" if safety else f"{head}/goal/{path}"


class LogGoals(BaseCallback):  # type: ignore[misc]
    """Records every goal's success and every safety rate through the model's SB3 logger.

    At each rollout's end, the rates over the training episodes finished during it (:func:`log_key`); at each
    evaluation (:meth:`evaluated`: a checkpoint's look, the final evaluation), the evaluation's rates under
    ``specguard/eval/``. SB3 writes them with its own records, in the formats its
    logger has (``tensorboard_log``: TensorBoard; ``stable_baselines3.common.logger.configure``: CSV, JSON, ...).
    When training ends, what SB3 left unwritten is written at the last step: the episodes of a rollout that a
    callback cut short, and a met checkpoint's look that stopped training (the run's result).
    """

    def __init__(self) -> None:
        super().__init__()
        self.counts: dict[str, int] = {}
        self.episodes = 0

    def _on_step(self) -> bool:
        for info in _finished(self.locals):
            self.episodes += 1
            count_episode(self.counts, info)
        return True

    def _on_rollout_end(self) -> None:
        if self.episodes:
            for key, count in self.counts.items():
                self.logger.record(log_key(key), count / self.episodes)
        self.counts, self.episodes = {}, 0

    def _on_training_end(self) -> None:
        # A callback that stopped training (a met look, the wall-clock cap, the user's) stopped it inside a rollout,
        # after SB3's last write: what is pending (a met look, the run's result; SB3's own last records) and the
        # episodes of the rollout cut short would never be written. Written here, at the step training ended.
        self._on_rollout_end()
        self.logger.dump(self.num_timesteps)

    def evaluated(self, step: int, counts: Mapping[str, int], episodes: int, *, write: bool = False) -> None:
        """Record an evaluation of ``episodes`` episodes at training step ``step``.

        SB3 writes it with its next records (a checkpoint's, while training: writing it at once would move SB3's
        own pending records to this step), or, if training ends first, :class:`LogGoals` writes it when training
        ends (a met look that stopped training); ``write=True`` writes it now, at ``step`` (the final evaluation,
        after training, when SB3 writes nothing more).
        """
        for key, count in counts.items():
            self.logger.record(log_key(key, evaluation=True), count / episodes)
        self.logger.record("specguard/eval/episodes", episodes)
        if write:
            self.logger.dump(step)


class UserCallback(BaseCallback):  # type: ignore[misc]
    """A user's callback (``Spec(callbacks=...)``) among specguard's: it acts as it would alone, and an exception
    it raises fails the run in one line naming it (a :class:`~specguard.error.TrainingError`), not as the env's.

    When its ``on_step`` stops training (returns False), :attr:`stopped_at` is the step, for the run's result to
    say so (:attr:`RunResult.stop_reason <specguard.training.result.RunResult>`); returning ``None`` (a forgotten
    ``return True``), which SB3 takes as False, also warns (a :class:`~specguard.error.SpecWarning` naming it).

    Args:
        callback: the user's ``BaseCallback``.
        label: the run, as messages name it (``Spec 'x', seed 0``).
    """

    def __init__(self, callback: BaseCallback, label: str) -> None:
        super().__init__()
        self.callback = callback
        self.label = label
        self.stopped_at: int | None = None  # the step its on_step first returned False (or None): it stopped training
        self.returned_none = False  # what it returned then was None (a forgotten `return True`)

    @property
    def name(self) -> str:
        """The user's callback as messages name it: its class's qualified name."""
        return function_text(type(self.callback))

    def _guard(self, hook: str, call: Callable[[], Any]) -> Any:
        try:
            return call()
        except SpecError:
            raise
        except Exception as e:
            raise TrainingError(
                f"{self.label}, callback {self.name}, in {hook} at step {self.num_timesteps}: it raised "
                f"{type(e).__name__}: {elide(str(e), MAX_SHOWN)}"
            ) from e

    def _init_callback(self) -> None:
        self._guard("init_callback", lambda: self.callback.init_callback(self.model))

    def _on_training_start(self) -> None:
        self._guard("on_training_start", lambda: self.callback.on_training_start(self.locals, self.globals))

    def _on_rollout_start(self) -> None:
        self._guard("on_rollout_start", self.callback.on_rollout_start)

    def _on_step(self) -> bool:
        go_on = self._guard("on_step", self.callback.on_step)
        if go_on is None and self.stopped_at is None:  # a forgotten `return True`: SB3 stops, in silence
            self.returned_none = True
            warnings.warn(
                f"{self.label}, callback {self.name}: its _on_step returned None at step {self.num_timesteps}, "
                "which SB3 takes as False: training stopped there (return True to go on training)",
                SpecWarning,
                stacklevel=2,
            )
        if not go_on and self.stopped_at is None:
            self.stopped_at = self.num_timesteps
        return bool(go_on)

    def _on_rollout_end(self) -> None:
        self._guard("on_rollout_end", self.callback.on_rollout_end)

    def _on_training_end(self) -> None:
        self._guard("on_training_end", self.callback.on_training_end)

    def update_child_locals(self, locals_: dict[str, Any]) -> None:
        self.callback.update_locals(locals_)


def training_callbacks(
    curve: GoalCurve,
    *,
    every: int,
    total: int,
    report: Report | None = None,
    adapter: WeightAdapter | None = None,
    stop_on_checkpoint: StopTrainingOnMetCheckpoint | None = None,
    stop_on_wall_clock: StopTrainingOnWallClock | None = None,
    log: LogGoals | None = None,
    user: Sequence[UserCallback] = (),
) -> CallbackList:
    """The callbacks of a training run, in the order they act at each step (the module's list).

    The caller makes the stopping callbacks and reads their flags after training
    (``stop_on_checkpoint.met_early``, ``stop_on_wall_clock.hit_wall_clock``); the curve has a point at each
    of ``stop_on_checkpoint``'s steps. SB3 calls every callback of the list at each step, and stops training
    when any of them returns False.

    Args:
        curve: the run's learning curve (:class:`RecordGoalCurve`).
        every: steps between curve points.
        total: the run's budget of steps (:class:`ReportProgress`).
        report: receives the run's progress, or ``None`` (no :class:`ReportProgress`).
        adapter: the run's weight adapter (``weights="auto"``), or ``None`` (no :class:`AdaptWeights`).
        stop_on_checkpoint: the interim checkpoints' looks, or ``None``.
        stop_on_wall_clock: the wall-clock cap, or ``None``.
        log: the logger's per-goal records, or ``None``.
        user: the user's callbacks, last, in the spec's order.
    """
    checkpoints = () if stop_on_checkpoint is None else stop_on_checkpoint.checkpoints
    callbacks: list[BaseCallback] = [RecordGoalCurve(curve, every, checkpoints)]
    if adapter is not None:
        callbacks.append(AdaptWeights(adapter))
    if report is not None:
        callbacks.append(ReportProgress(curve, report, total))
    callbacks.extend(stop for stop in (stop_on_checkpoint, stop_on_wall_clock) if stop is not None)
    if log is not None:
        callbacks.append(log)
    callbacks.extend(user)
    return CallbackList(callbacks)
