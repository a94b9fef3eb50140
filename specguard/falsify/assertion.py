"""A falsification asserted as a test: what to search, and when the search fails the spec.

``@sg.goal_spec(..., falsify=sg.Falsify(...))`` adds one item per spec to a
pytest session, ``[falsify]``, that searches each trained run's start space
(:func:`specguard.falsify.search.falsify`, on the cached model) and fails by
:func:`falsify_verdict`:

* without ``max_rate``: when any run has a counterexample, a start from which
  its policy misses the spec;
* with ``max_rate``: when a run's failure rate over the start space (its
  uniform draws, counted apart from the guided search) is above ``max_rate``
  by the same interval rule that judges success thresholds
  (:func:`specguard.stats.intervals.run_verdict` on the starts that did not
  fail, against ``1 - max_rate``): *met* once the interval lies at or under
  it, *missed* once it lies above, *undecided* in between, which counts as
  the spec's ``Spec.undecided`` says.

:func:`verdict_lines` writes each run's verdict and report for the item's
failure message.

Example:
    >>> check = Falsify({"x": (-1.0, 1.0)}, max_rate=0.05)
    >>> check.starts.ranges, check.max_rate
    ((('x', -1.0, 1.0),), 0.05)
    >>> from specguard.error import InvalidSpec
    >>> try:
    ...     Falsify(examples=0)
    ... except InvalidSpec as e:
    ...     print(str(e).splitlines()[0])
    Falsify: expected examples to be an integer >= 1 (guided episodes per run at most), got 0
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from specguard.error import InvalidSpec
from specguard.falsify.robustness import SCORES
from specguard.falsify.search import Falsification
from specguard.starts.space import StartSpace, as_start_space
from specguard.stats.intervals import run_verdict
from specguard.stats.verdicts import RunVerdict
from specguard.validation import check_choice, check_count, check_natural, check_open_fraction

__all__ = ["Falsify", "as_falsify", "falsify_verdict", "rule_text", "verdict_lines"]


@dataclass(frozen=True, init=False)
class Falsify:
    """What a spec's ``[falsify]`` item searches, and the failure rate it tolerates.

    Args:
        starts: the start space: a :class:`~specguard.starts.space.StartSpace`, or its ranges
            ``{variable: (lo, hi)}``; ``None``: the spec's own (``Spec.starts``), else the env's reset ranges.
        examples: guided episodes per run at most.
        uniform: uniform draws per run for the failure rate (at least 1 with ``max_rate``).
        max_rate: the failure rate over the start space a run may have, in ``(0, 1)``: uniform
            draws can bound a rate away from a positive number, never from 0; ``None``: no failing
            start at all (any counterexample fails).
        seed: the search's seed, an integer >= 0.
        score: the robustness score that steers the search: ``"last"`` (the default) or ``"episode"``
            (:data:`~specguard.falsify.robustness.SCORES`, as for :func:`~specguard.engine.falsify_run.falsify_runs`).
    """

    starts: StartSpace | None
    examples: int
    uniform: int
    max_rate: float | None
    seed: int
    score: str

    def __init__(
        self,
        starts: StartSpace | Mapping[str, tuple[float, float]] | None = None,
        *,
        examples: int = 200,
        uniform: int = 100,
        max_rate: float | None = None,
        seed: int = 0,
        score: str = "last",
    ) -> None:
        where = "Falsify"
        starts = as_start_space(where, starts)
        examples = check_count(where, "examples", examples, "guided episodes per run at most")
        uniform = check_natural(where, "uniform", uniform, "uniform draws per run")
        if max_rate is not None:
            meaning = "the failure rate a run may have; None for no failing start"
            max_rate = check_open_fraction(where, "max_rate", max_rate, meaning)
            if uniform < 1:
                raise InvalidSpec(where, f"max_rate={max_rate!r} needs uniform draws: expected uniform >= 1, got 0")
        seed = check_natural(where, "seed", seed, "the search's seed")
        score = check_choice(where, "score", score, SCORES)
        object.__setattr__(self, "starts", starts)
        object.__setattr__(self, "examples", examples)
        object.__setattr__(self, "uniform", uniform)
        object.__setattr__(self, "max_rate", max_rate)
        object.__setattr__(self, "seed", seed)
        object.__setattr__(self, "score", score)

    def kwargs(self) -> dict[str, Any]:
        """The keyword arguments of :func:`specguard.engine.falsify_run.falsify_runs` this check runs with."""
        return {"examples": self.examples, "uniform": self.uniform, "search_seed": self.seed, "score": self.score}


def falsify_verdict(found: Falsification, max_rate: float | None, confidence: float = 0.95) -> RunVerdict:
    """A run's verdict under a falsify check: MISSED when it is falsified, MET when it is not, else UNDECIDED.

    Without ``max_rate`` a counterexample is MISSED and none is MET. With it, the
    failure rate of the uniform draws is judged against ``max_rate`` by the
    interval rule of success thresholds (never by the guided episodes, which seek
    failures and so overcount them).

    Example:
        >>> from specguard.starts.space import StartSpace
        >>> from specguard.falsify.search import Falsification
        >>> found = Falsification(StartSpace(), uniform_failures=0, uniform_episodes=100)
        >>> falsify_verdict(found, None).value, falsify_verdict(found, 0.05).value
        ('met', 'met')
        >>> falsify_verdict(Falsification(StartSpace(), uniform_failures=20, uniform_episodes=100), 0.05).value
        'missed'
    """
    if max_rate is None:
        return RunVerdict.MISSED if found.found else RunVerdict.MET
    held = found.uniform_episodes - found.uniform_failures
    return run_verdict(held, found.uniform_episodes, 1.0 - max_rate, confidence)


def rule_text(max_rate: float | None, found: bool | None = None) -> str:
    """What a falsify check asserts, in words (reports and failure messages say it alike); without ``max_rate``, a
    run's header says what its search found (``found``), so a falsified run's never reads "no counterexample".

    Example:
        >>> rule_text(None), rule_text(0.05)
        ('no counterexample', 'a failure rate at most 0.05 over the start space')
        >>> rule_text(None, found=True), rule_text(None, found=False), rule_text(0.05, found=True)
        ('a counterexample found', 'no counterexample found', 'a failure rate at most 0.05 over the start space')
    """
    if max_rate is not None:
        return f"a failure rate at most {max_rate:g} over the start space"
    if found is None:
        return "no counterexample"
    return "a counterexample found" if found else "no counterexample found"


def verdict_lines(
    found: Mapping[int, Falsification], verdicts: Mapping[int, RunVerdict], max_rate: float | None
) -> list[str]:
    """Per run (by seed), its verdict under the rule, then the search's report, indented.

    Example:
        >>> import gymnasium as gym
        >>> from specguard.starts.space import StartSpace
        >>> from specguard.falsify.search import Falsification
        >>> starts = StartSpace({"x": (-0.05, 0.05)}).resolve(gym.make("CartPole-v1"))
        >>> found = {0: Falsification(starts, guided=200)}
        >>> print("\\n".join(verdict_lines(found, {0: falsify_verdict(found[0], None)}, None)))
        seed 0: met (no counterexample found)
          StartSpace for CartPole-v1: starts set by state over x, v, theta, omega
          no counterexample in 200 guided episodes
    """
    lines = []
    for seed, falsification in sorted(found.items()):
        lines.append(f"seed {seed}: {verdicts[seed].value} ({rule_text(max_rate, falsification.found)})")
        lines += [f"  {line}" for line in falsification.report().splitlines()]
    return lines


def as_falsify(where: str, value: object) -> Falsify | None:
    """``falsify=`` as declared: ``None``/``False`` (none), ``True`` (the spec's start space), a start space or its
    ranges, or a :class:`Falsify`.

    Raises:
        InvalidSpec: naming ``where`` and the value given.
    """
    if value is None or value is False:
        return None
    if value is True:
        return Falsify()
    if isinstance(value, Falsify):
        return value
    if isinstance(value, (StartSpace, Mapping)):
        return Falsify(value)
    expected = "a Falsify, a StartSpace, {name: (lo, hi)} or a bool"
    raise InvalidSpec(where, f"expected falsify to be {expected}, got {value!r}")
