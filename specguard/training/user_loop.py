"""A trainer of the user's (``Spec(trainer=...)``) driven through its checkpoints: :func:`drive`.

The protocol: a trainer is a generator function ``trainer(make_env, timesteps, seed)``. ``make_env()`` returns a
fresh constructed env (the spec's :meth:`~specguard.spec.spec.Spec.env_factory`, as SB3 trains on), ``timesteps`` is
the spec's budget, ``seed`` the run's seed. It trains as it likes and **yields** ``(steps, agent)`` checkpoints:
``steps`` the steps trained so far (ints, increasing), ``agent`` what acts on the constructed env's observation (a
callable ``obs -> action``, an object with SB3's ``predict``, an SB3 model).

:func:`drive` asks for checkpoints and looks at them as SB3's training is looked at
(:mod:`specguard.stats.anytime`): the first checkpoint at or past each planned step
(``checkpoint_steps(budget.timesteps, budget.checkpoints)``) is judged, so the number of looks and their correction
do not change. Once a look meets every threshold the generator is closed (``gen.close()``: its ``finally`` runs, it
is asked for nothing more); otherwise it runs to its end, to a checkpoint at or past the budget, or to the
wall-clock cap, and the last agent is the run's (:mod:`specguard.training.train` evaluates it as an SB3 model).

Example:
    >>> def trainer(make_env, timesteps, seed):
    ...     for steps in range(100, timesteps + 1, 100):
    ...         yield steps, (lambda obs: 0)
    >>> done = drive(trainer, lambda: None, 300, 0, checkpoints=[150], look=lambda steps, agent: True, label="run")
    >>> done.steps, done.met_early
    (200, True)
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

from specguard.error import InvalidSpec, SpecError, TrainingError
from specguard.utils.text import MAX_SHOWN, elide, function_text, shown

__all__ = ["Trained", "drive"]

TrainerLook = Callable[[int, Any], bool]
"""A planned look at a checkpoint: ``look(steps, agent)``; True when every threshold is met."""


@dataclass(frozen=True)
class Trained:
    """Where a trainer stopped: its last checkpoint (``steps``, ``agent``) and why it stopped there."""

    steps: int
    agent: Any
    met_early: bool  # a look met every threshold, and the generator was closed
    hit_wall_clock: bool  # the wall-clock cap stopped it


def _raised(e: Exception) -> str:
    return f"it raised {type(e).__name__}: {elide(str(e), MAX_SHOWN)}"


def _checkpoint(item: object, previous: int | None, where: str) -> tuple[int, Any]:
    """A yielded ``(steps, agent)`` pair, checked: ``steps`` an int past ``previous``, ``agent`` one that can act."""
    if not isinstance(item, tuple) or len(item) != 2:
        raise TrainingError(f"{where}: expected a (steps, agent) pair, got {shown(item)}")
    steps, agent = item
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise TrainingError(f"{where}: expected steps to be a natural int, got {shown(steps)}")
    if previous is not None and steps <= previous:
        raise TrainingError(f"{where}: expected steps to increase past {previous}, got {steps}")
    if not (callable(agent) or callable(getattr(agent, "predict", None))):
        raise TrainingError(
            f"{where}: expected the agent to be a callable obs -> action, an object with predict or an SB3 model, "
            f"got {shown(agent)}"
        )
    return steps, agent


def drive(
    trainer: Callable[..., Any],
    make_env: Callable[..., Any],
    timesteps: int,
    seed: int,
    *,
    checkpoints: Sequence[int],
    look: TrainerLook,
    label: str,
    wall_clock_s: float | None = None,
    report: Callable[[int], None] | None = None,
) -> Trained:
    """Run ``trainer(make_env, timesteps, seed)`` through its checkpoints, looking at the planned ones (the module).

    Args:
        checkpoints: the planned looks' steps (:func:`~specguard.stats.anytime.checkpoint_steps`).
        look: judges a checkpoint; True closes the generator.
        label: the run, as messages name it (``Spec 'x', seed 0``).
        wall_clock_s: the budget's wall-clock cap, or ``None``.
        report: receives each checkpoint's steps, after the checkpoint's look if it had one.

    Raises:
        InvalidSpec: the trainer returned no iterator (every seed would).
        TrainingError: the trainer raised (its name, the seed and its last steps), yielded something that is not a
            ``(steps, agent)`` pair of increasing steps, or yielded nothing.
    """
    name = function_text(trainer)
    try:
        gen = trainer(make_env, timesteps, seed)
    except SpecError:
        raise
    except Exception as e:
        raise TrainingError(f"{label}, trainer {name}, called: {_raised(e)}") from e
    if not isinstance(gen, Iterator):
        raise InvalidSpec(
            f"{label}.trainer",
            f"expected trainer {name} to return a generator of (steps, agent), got {shown(gen)}",
            hint="write the trainer as a generator function: `yield steps, agent` at each checkpoint",
        )
    pending = list(checkpoints)
    deadline = None if wall_clock_s is None else time.perf_counter() + wall_clock_s
    steps: int | None = None
    agent: Any = None
    met_early = hit_wall_clock = False
    try:
        for count in itertools.count(1):
            item = _next(gen, name, label, steps)
            if item is _END:
                break
            steps, agent = _checkpoint(item, steps, f"{label}, trainer {name}, checkpoint {count}")
            if pending and steps >= pending[0]:
                while pending and pending[0] <= steps:
                    pending.pop(0)
                met_early = look(steps, agent)
            if report is not None:
                report(steps)  # after its look, which the report may tell
            if met_early:
                break
            if steps >= timesteps:
                break
            if deadline is not None and time.perf_counter() > deadline:
                hit_wall_clock = True
                break
    finally:
        _close(gen, name, label, steps)
    if steps is None:
        raise TrainingError(f"{label}, trainer {name}: it yielded no (steps, agent) checkpoint")
    return Trained(steps, agent, met_early, hit_wall_clock)


_END = object()  # the trainer's generator ended


def _next(gen: Iterator[Any], name: str, label: str, steps: int | None) -> Any:
    """``gen``'s next item, or :data:`_END`; an exception it raises is a :class:`TrainingError` naming the trainer
    and its last steps."""
    try:
        return next(gen)
    except StopIteration:
        return _END
    except SpecError:
        raise
    except Exception as e:
        raise TrainingError(f"{label}, trainer {name}, after step {_steps(steps)}: {_raised(e)}") from e


def _close(gen: Iterator[Any], name: str, label: str, steps: int | None) -> None:
    """Close the generator (its ``finally`` runs); an exception its closing raises is the trainer's."""
    close = getattr(gen, "close", None)
    if close is None:
        return
    try:
        close()
    except SpecError:
        raise
    except Exception as e:
        raise TrainingError(f"{label}, trainer {name}, closed after step {_steps(steps)}: {_raised(e)}") from e


def _steps(steps: int | None) -> str:
    return "0 (no checkpoint yet)" if steps is None else str(steps)
