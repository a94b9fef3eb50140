"""A spec's runs judged, as plain data: per-goal verdicts (:class:`GoalVerdict`) and :class:`SpecResult`.

A result says what was measured and how each goal is judged, in the words of
:mod:`specguard.stats.verdicts`; ``to_dict()`` is JSON and
:meth:`SpecResult.from_dict` reads it back. What acts on a result lives
elsewhere: its models, rollouts and falsification in :mod:`specguard.engine.result_models`
and :mod:`specguard.engine.falsify_run`, its table in :mod:`specguard.report.table`.

Example:
    >>> from specguard.stats.verdicts import QuorumVerdict, RunVerdict
    >>> from specguard.training.result import RunResult
    >>> run = RunResult(spec="p", seed=0, timesteps=64, episodes=10, successes={"p": 9}, train_seconds=1.0)
    >>> goal = GoalVerdict("p", 0.5, 1, [RunVerdict.MET], QuorumVerdict.PASSED, 9, 10, (0.555, 0.997))
    >>> result = SpecResult(spec="p", runs=[run], goals={"p": goal})
    >>> result.passed, result.word("p"), result.status()
    (True, <Word.PASSED: 'passed'>, 'passed')
    >>> SpecResult.from_dict(result.to_dict()) == result
    True
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from specguard.spec.spec import Spec
from specguard.stats.verdicts import (
    DEFAULT_UNDECIDED,
    UNDECIDED_AS,
    GoalOutcome,
    QuorumVerdict,
    RunVerdict,
    Word,
    counted,
    goal_outcome,
    spec_word,
    verdict_word,
)
from specguard.training.result import RunResult
from specguard.tree.keys import kind
from specguard.utils.text import value_text
from specguard.validation import is_choice, is_count, is_finite, is_natural, is_open_fraction

__all__ = ["GoalVerdict", "SpecResult"]

_GOAL_FIELDS = ("path", "threshold", "required", "runs", "verdict", "successes", "episodes", "interval")


@dataclass
class GoalVerdict:
    """One goal (or safety rate) of a spec against its threshold, over all runs.

    Attributes:
        path: the node path, or for a safety rate its key ``path:name``.
        threshold: the minimum success asked for.
        required: runs that must meet it.
        runs: each run's verdict, by seed order.
        verdict: passed, failed, or open (more runs could still decide it).
        successes, episodes: pooled over runs (for a safety rate: episodes without a violation).
        interval: the pooled success rate's confidence interval.
    """

    path: str
    threshold: float
    required: int
    runs: list[RunVerdict]
    verdict: QuorumVerdict
    successes: int
    episodes: int
    interval: tuple[float, float]

    @property
    def success(self) -> float:
        return self.successes / self.episodes if self.episodes else 0.0

    def to_dict(self) -> dict[str, Any]:
        """The goal as JSON-ready data, its verdicts as their words; :meth:`from_dict` reads it back."""
        return {**asdict(self), "runs": [str(v) for v in self.runs], "verdict": str(self.verdict)}

    @classmethod
    def from_dict(cls, data: Any) -> GoalVerdict:
        """The goal :meth:`to_dict` wrote (extra keys, such as a result's ``kind`` and ``word``, ignored).

        Raises:
            ValueError: ``data`` is no object, a field is missing, or one is not what :meth:`to_dict` writes (a
                verdict not one of its words, a count not an integer), in one line naming the goal and the field.
        """
        if not isinstance(data, dict):
            raise ValueError(f"goal verdict: expected an object, as to_dict() writes, got {value_text(data)}")
        missing = sorted(set(_GOAL_FIELDS) - set(data))
        if missing:
            raise ValueError(f"goal verdict {value_text(data.get('path', '?'))} lacks {', '.join(missing)}")
        where = f"goal verdict {value_text(data['path'])}"
        for name, ok, expected in _GOAL_CHECKS:
            if not ok(data[name]):
                raise ValueError(f"{where}: {name} {value_text(data[name])} is not {expected}")
        if data["successes"] > data["episodes"]:
            raise ValueError(f"{where}: successes {data['successes']!r} exceed episodes {data['episodes']!r}")
        lo, hi = data["interval"]
        return cls(
            path=data["path"],
            threshold=data["threshold"],
            required=data["required"],
            runs=[RunVerdict(v) for v in data["runs"]],
            verdict=QuorumVerdict(data["verdict"]),
            successes=data["successes"],
            episodes=data["episodes"],
            interval=(lo, hi),
        )


def _words(enum: Any) -> tuple[str, ...]:
    return tuple(str(v) for v in enum)


_GOAL_CHECKS: tuple[tuple[str, Callable[[Any], bool], str], ...] = (
    ("path", lambda v: isinstance(v, str), "a string"),
    ("threshold", lambda v: is_finite(v) and 0.0 <= float(v) <= 1.0, "a number in [0, 1]"),
    ("required", is_count, "an integer >= 1"),
    (
        "runs",
        lambda v: isinstance(v, list) and all(is_choice(x, _words(RunVerdict)) for x in v),
        f"a list of run verdicts ({', '.join(_words(RunVerdict))})",
    ),
    ("verdict", lambda v: is_choice(v, _words(QuorumVerdict)), f"one of {', '.join(_words(QuorumVerdict))}"),
    ("successes", is_natural, "an integer >= 0"),
    ("episodes", is_natural, "an integer >= 0"),
    (
        "interval",
        lambda v: isinstance(v, (list, tuple)) and len(v) == 2 and all(is_finite(x) for x in v),
        "two finite numbers",
    ),
)
"""Each field of a stored goal verdict: its rule and the words for what it should be."""


@dataclass
class SpecResult:
    """Everything a spec's runs measured and how each goal is judged: plain data.

    ``to_dict()`` is JSON, and :meth:`from_dict` reads it back equal. The words it
    reports (:meth:`outcome`, :meth:`counted`, :meth:`word`, :meth:`status`,
    :attr:`passed`) are :mod:`specguard.stats.verdicts`'s, as at every door.

    Attributes:
        spec: the spec's label.
        runs: what each finished run measured, by seed.
        goals: per thresholded goal (and safety rate), its verdict and pooled figures: all a door
            reports of a goal (a result of evaluation episodes alone, without training, fills
            ``goals`` the same way, with its episodes as one run).
        errors, tracebacks: per seed whose run crashed, what happened (the worker's traceback is shown under -v).
        cached: per seed, whether its run came from the cache.
        seconds: wall-clock time of the call.
        confidence: the level of the pooled intervals.
        spec_key: the spec's identity in the cache (``None`` without a cache).
        undecided: what a goal whose runs stayed undecided counts as (``Spec.undecided``).
        xfail: the goals the spec expects to miss, with the reasons (``Spec.xfail``).
        notes: the facts about the evaluation episodes that every door shows beside the
            verdicts, one line each (:func:`specguard.engine.judging.episode_notes`).
        agent: the name of the agent judged, for a result of :func:`~specguard.engine.check_agent.check_agent` (one
            run that trained nothing); ``None`` for a trained spec.
        hints: per goal (or safety rate) that did not pass, what to try (:func:`specguard.engine.judging.goal_hint`),
            the hint every door prints under its verdict; a result stored before hints were kept has none.
        trained: the spec as run, which with ``cache_dir`` reaches the runs' models
            (:func:`specguard.engine.result_models.load_model`); neither is reported nor serialised.
    """

    spec: str
    runs: list[RunResult]
    goals: dict[str, GoalVerdict]
    errors: dict[int, str] = field(default_factory=dict)
    tracebacks: dict[int, str] = field(default_factory=dict)
    cached: dict[int, bool] = field(default_factory=dict)
    seconds: float = 0.0
    confidence: float = 0.95
    spec_key: str | None = None
    undecided: str = DEFAULT_UNDECIDED
    xfail: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    agent: str | None = None
    hints: dict[str, str] = field(default_factory=dict)
    trained: Spec | None = field(default=None, repr=False, compare=False)
    cache_dir: Path | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.undecided not in UNDECIDED_AS:
            raise ValueError(f"expected undecided to be one of {tuple(UNDECIDED_AS)}, got {self.undecided!r}")

    def outcome(self, path: str) -> GoalOutcome:
        """Thresholded goal ``path`` at the end: passed, failed, or undecided.

        Undecided when it failed only through runs that stayed undecided
        (:func:`~specguard.stats.verdicts.goal_outcome`).
        """
        goal = self.goals[path]
        return goal_outcome(goal.verdict, goal.runs, crashed=bool(self.errors))

    def counted(self, path: str) -> Word:
        """What goal ``path`` counts as at every door: passed, xfailed or failed.

        The spec's ``undecided`` and ``xfail`` apply here (:func:`~specguard.stats.verdicts.counted`).
        """
        return counted(
            self.outcome(path), crashed=bool(self.errors), undecided_as=self.undecided, expected_miss=path in self.xfail
        )

    def word(self, path: str) -> Word:
        """The word shown for goal ``path`` (:func:`~specguard.stats.verdicts.verdict_word`): pytest's, or undecided."""
        return verdict_word(self.counted(path), self.outcome(path), expected_miss=path in self.xfail)

    def status(self) -> str:
        """The spec's word at the end (:func:`~specguard.stats.verdicts.spec_word`): ``FAILED``, or its goals' worst.

        ``undecided`` says what it counts as (:attr:`undecided`), which decides the exit status.
        """
        words = [self.word(p) for p in self.goals]
        undecided = [p for p, w in zip(self.goals, words) if w is Word.UNDECIDED]
        return spec_word(
            words, crashed=bool(self.errors), undecided_counts_as=self.counted(undecided[0]) if undecided else None
        )

    @property
    def passed(self) -> bool:
        """No seed failed and every thresholded goal counts as passed (:meth:`counted`)."""
        return not self.errors and all(self.counted(p) is Word.PASSED for p in self.goals)

    @property
    def as_expected(self) -> bool:
        """No seed failed and no thresholded goal counts as failed: each passed, or was expected to miss."""
        return not self.errors and all(self.counted(p) is not Word.FAILED for p in self.goals)

    def success(self, path: str) -> tuple[int, int]:
        """Pooled ``(successes, episodes)`` of a goal (or safe episodes of a safety key) over all runs."""
        return sum(r.successes[path] for r in self.runs), sum(r.episodes for r in self.runs)

    def to_dict(self) -> dict[str, Any]:
        """The result as JSON-ready data, with the words it reports (``passed``, ``status``, each goal's ``word``)."""
        return {
            "spec": self.spec,
            "passed": self.passed,
            "status": self.status(),
            "seconds": self.seconds,
            "runs": [r.to_dict() for r in self.runs],
            "goals": {
                p: {**g.to_dict(), "kind": kind(p), "outcome": str(self.outcome(p)), "word": str(self.word(p))}
                for p, g in self.goals.items()
            },
            "errors": {str(k): v for k, v in self.errors.items()},
            "tracebacks": {str(k): v for k, v in self.tracebacks.items()},
            "cached": {str(k): v for k, v in self.cached.items()},
            "confidence": self.confidence,
            "spec_key": self.spec_key,
            "undecided": self.undecided,
            "xfail": dict(self.xfail),
            "notes": list(self.notes),
            "agent": self.agent,
            "hints": dict(self.hints),
        }

    @classmethod
    def from_dict(
        cls, data: dict[str, Any], *, trained: Spec | None = None, cache_dir: str | Path | None = None
    ) -> SpecResult:
        """The result :meth:`to_dict` wrote, equal to it in everything it reports.

        Each run is read by :meth:`RunResult.from_dict <specguard.training.result.RunResult.from_dict>`, which
        checks every field. The words ``to_dict`` adds (``passed``, ``status``, ``kind``, ``outcome``,
        ``word``) are derived again, not read.

        Args:
            trained, cache_dir: the spec as run and its cache, to reach the runs' models again.

        Raises:
            ValueError: ``data`` is no object, or a field is missing or not what ``to_dict`` writes: one line naming
                the result, the field (and the goal or run) and the value found.
        """
        if not isinstance(data, dict):
            raise ValueError(f"a spec result is an object, as to_dict() writes, got {value_text(data)}")
        missing = sorted({"spec", "runs", "goals"} - set(data))
        if missing:
            raise ValueError(f"a spec result needs {', '.join(missing)}, got the fields {sorted(map(str, data))}")
        spec = data["spec"]
        if not isinstance(spec, str):
            raise ValueError(f"spec result {value_text(spec)}: spec {value_text(spec)} is not a string")
        fields = {name: _field(spec, data, name, default, ok, expected) for name, default, ok, expected in _FIELDS}
        goals: dict[str, GoalVerdict] = {}
        for path, goal in fields["goals"].items():
            if not isinstance(goal, dict):
                raise ValueError(
                    f"spec result {spec!r}: goal verdict {path!r}: expected an object, got {value_text(goal)}"
                )
            try:
                goals[path] = GoalVerdict.from_dict(goal)
            except ValueError as e:
                raise ValueError(f"spec result {spec!r}: {e}") from None
        return cls(
            spec=spec,
            runs=[_run_of(run, spec) for run in fields["runs"]],
            goals=goals,
            errors=_by_seed(fields["errors"]),
            tracebacks=_by_seed(fields["tracebacks"]),
            cached=_by_seed(fields["cached"]),
            seconds=fields["seconds"],
            confidence=fields["confidence"],
            spec_key=fields["spec_key"],
            undecided=fields["undecided"],
            xfail=dict(fields["xfail"]),
            notes=list(fields["notes"]),
            agent=fields["agent"],
            hints=dict(fields["hints"]),
            trained=trained,
            cache_dir=None if cache_dir is None else Path(cache_dir),
        )


def _is_seed_key(key: Any) -> bool:
    """A seed as ``to_dict`` writes it in a key (``"3"``), or as an ``int``."""
    return is_natural(key) or (isinstance(key, str) and key.isascii() and key.isdecimal())


def _by_seed(values: dict[Any, Any]) -> dict[int, Any]:
    return {int(k): v for k, v in values.items()}


def _seeds_to(ok: Callable[[Any], bool]) -> Callable[[Any], bool]:
    """The rule for a per-seed field: an object whose keys are seeds and whose values pass ``ok``."""
    return lambda v: isinstance(v, dict) and all(_is_seed_key(k) and ok(x) for k, x in v.items())


def _is_text(value: Any) -> bool:
    return isinstance(value, str)


_FIELDS: tuple[tuple[str, Any, Callable[[Any], bool], str], ...] = (
    ("runs", None, lambda v: isinstance(v, list), "a list of runs"),
    ("goals", None, lambda v: isinstance(v, dict), "an object of goal verdicts by path"),
    ("errors", {}, _seeds_to(_is_text), "an object of texts by seed"),
    ("tracebacks", {}, _seeds_to(_is_text), "an object of texts by seed"),
    ("cached", {}, _seeds_to(lambda x: isinstance(x, bool)), "an object of true or false by seed"),
    ("seconds", 0.0, lambda v: is_finite(v) and float(v) >= 0, "a finite number >= 0"),
    ("confidence", 0.95, is_open_fraction, "a number in (0, 1)"),
    ("spec_key", None, lambda v: v is None or isinstance(v, str), "a string or null"),
    ("undecided", DEFAULT_UNDECIDED, lambda v: is_choice(v, tuple(UNDECIDED_AS)), f"one of {', '.join(UNDECIDED_AS)}"),
    (
        "xfail",
        {},
        lambda v: isinstance(v, dict) and all(isinstance(k, str) and isinstance(x, str) for k, x in v.items()),
        "an object of reasons (texts) by goal path",
    ),
    ("notes", [], lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "a list of texts"),
    ("agent", None, lambda v: v is None or isinstance(v, str), "a string or null"),
    (
        "hints",
        {},
        lambda v: isinstance(v, dict) and all(isinstance(k, str) and isinstance(x, str) for k, x in v.items()),
        "an object of hints (texts) by goal path",
    ),
)
"""Each field of a stored result but its label: its default where it may be absent, its rule and the words for
what it should be."""


def _field(spec: str, data: dict[str, Any], name: str, default: Any, ok: Callable[[Any], bool], expected: str) -> Any:
    """Field ``name`` of a stored result (``default`` where absent), if ``ok`` says it is what ``to_dict`` writes.

    Raises:
        ValueError: naming the result, the field and the value found.
    """
    value = data.get(name, default)
    if not ok(value):
        raise ValueError(f"spec result {spec!r}: {name} {value_text(value)} is not {expected}")
    return value


def _run_of(data: Any, spec: str) -> RunResult:
    """One run of a result's ``to_dict()``, checked as a worker's or the cache's is (its own seed and keys)."""
    run = data if isinstance(data, dict) else {}
    seed, successes = run.get("seed", -1), run.get("successes")
    try:
        return RunResult.from_dict(data, seed=seed, paths=successes if isinstance(successes, dict) else ())
    except ValueError as e:
        raise ValueError(f"spec result {spec!r}: run seed {seed!r}: {e}") from None
