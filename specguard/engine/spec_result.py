"""A spec's runs judged: per-goal verdicts (:class:`GoalVerdict`), and :class:`SpecResult` with its table and models."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from specguard.construction import cap
from specguard.error import SpecError
from specguard.extend import until_end
from specguard.spec.spec import Spec
from specguard.stats.intervals import GoalOutcome, QuorumVerdict, RunVerdict, success_interval
from specguard.training.result import RunResult
from specguard.tree.keys import GOAL, kind, label
from specguard.tree.nodes import keeps_to_horizon
from specguard.utils.text import interval_text, render_table, weights_text

if TYPE_CHECKING:
    from collections.abc import Callable

    from specguard.falsify.search import Falsification
    from specguard.starts.space import StartSpace

__all__ = ["VERDICT_WORDS", "GoalVerdict", "SpecResult", "verdict_word"]

# The words every door shows for a goal, worst first: pytest's outcomes, and undecided.
VERDICT_WORDS = ("failed", "undecided", "xfailed", "xpassed", "passed")


def verdict_word(counted: str, outcome: GoalOutcome | str, *, expected_miss: bool = False) -> str:
    """The word every door shows for a goal: pytest's (passed, failed, xfailed, xpassed), or undecided.

    The one rule ``specguard run``'s table and the pytest plugin's summary both follow.

    Args:
        counted: what the goal counts as: ``"passed"``, ``"failed"`` or ``"xfailed"``
            (:meth:`SpecResult.counted`; in pytest, the item's outcome).
        outcome: the goal's :class:`~specguard.stats.intervals.GoalOutcome` (passed, failed, undecided).
        expected_miss: the spec declares the goal in ``xfail``: passing it is ``xpassed``, as a
            non-strict ``pytest.mark.xfail`` that passes.

    An undecided goal that counts as passed or failed says ``undecided``
    (what it counts as decides the exit status); one that counts as xfailed is
    ``xfailed``, as pytest reports it.

    Example:
        >>> verdict_word("passed", "passed", expected_miss=True), verdict_word("xfailed", "failed")
        ('xpassed', 'xfailed')
        >>> verdict_word("failed", "undecided"), verdict_word("passed", "undecided")
        ('undecided', 'undecided')
    """
    if counted == "passed" and expected_miss:
        return "xpassed"
    if GoalOutcome(outcome) is GoalOutcome.UNDECIDED and counted in ("passed", "failed"):
        return "undecided"
    return counted


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


@dataclass
class SpecResult:
    """Everything ``run_spec`` measured; ``to_dict()`` is JSON-serialisable."""

    spec: str
    runs: list[RunResult]
    goals: dict[str, GoalVerdict]
    errors: dict[int, str] = field(default_factory=dict)
    tracebacks: dict[int, str] = field(default_factory=dict)  # the worker's, per failed seed (shown under -v)
    cached: dict[int, bool] = field(default_factory=dict)
    seconds: float = 0.0
    confidence: float = 0.95
    spec_key: str | None = None
    trained: Spec | None = field(default=None, repr=False, compare=False)  # the spec as run, for model()/rollout()
    cache_dir: Path | None = field(default=None, repr=False, compare=False)

    def outcome(self, path: str) -> GoalOutcome:
        """Thresholded goal ``path`` at the end: passed, failed, or undecided.

        Undecided when it failed only through runs that stayed undecided: none
        missed, no seed failed (more evaluation episodes could have decided it).
        """
        goal = self.goals[path]
        if goal.verdict is QuorumVerdict.PASSED:
            return GoalOutcome.PASSED
        if not self.errors and goal.runs and RunVerdict.MISSED not in goal.runs:
            return GoalOutcome.UNDECIDED
        return GoalOutcome.FAILED

    def counted(self, path: str) -> str:
        """What goal ``path`` counts as at every door: ``"passed"``, ``"xfailed"`` or ``"failed"``.

        The one place the spec's ``undecided`` and ``xfail`` apply: an undecided
        goal counts as the spec's ``undecided`` says; a goal the spec expects
        to miss (``xfail``) that did not pass counts as xfailed, unless runs
        crashed: a crash is not a miss, so the goal counts as failed.
        """
        outcome = self.outcome(path)
        if self.errors and outcome is not GoalOutcome.PASSED:
            return "failed"
        undecided_as = self.trained.undecided if self.trained is not None else "fail"
        if outcome is GoalOutcome.PASSED or (outcome is GoalOutcome.UNDECIDED and undecided_as == "pass"):
            return "passed"
        xfail = self.trained.xfail if self.trained is not None else {}
        if path in xfail or (outcome is GoalOutcome.UNDECIDED and undecided_as == "xfail"):
            return "xfailed"
        return "failed"

    def word(self, path: str) -> str:
        """The word shown for goal ``path`` (:func:`verdict_word`): pytest's for the same run, or undecided."""
        xfail = self.trained.xfail if self.trained is not None else {}
        return verdict_word(self.counted(path), self.outcome(path), expected_miss=path in xfail)

    def status(self) -> str:
        """The spec's word at the end: ``FAILED`` when a seed failed, else its goals' worst (:data:`VERDICT_WORDS`).

        ``undecided`` says what it counts as (``Spec.undecided``), which decides the exit status.
        """
        if self.errors:
            return "FAILED"
        words = [self.word(p) for p in self.goals] or ["passed"]
        worst = min(words, key=VERDICT_WORDS.index)
        if worst == "failed":
            return "FAILED"
        if worst == "undecided":
            undecided = [p for p, w in zip(self.goals, words) if w == "undecided"]
            return f"undecided, counted as {self.counted(undecided[0])}"
        return worst

    @property
    def passed(self) -> bool:
        """No seed failed and every thresholded goal counts as passed (:meth:`counted`)."""
        return not self.errors and all(self.counted(p) == "passed" for p in self.goals)

    @property
    def as_expected(self) -> bool:
        """No seed failed and no thresholded goal counts as failed: each passed, or was expected to miss."""
        return not self.errors and all(self.counted(p) != "failed" for p in self.goals)

    def model(self, seed: int) -> Any:
        """The trained SB3 model of run ``seed`` (loaded from the cache, after its checksums are verified).

        Raises:
            SpecError: the run was not cached (``cache_dir=None``) or is gone.
        """
        return self._load(seed)[0]

    def normalizer(self, seed: int) -> Any:
        """Run ``seed``'s ``VecNormalize`` statistics (``None`` where the run did not normalise observations).

        A policy outside specguard must normalise observations with these before asking the model.

        Raises:
            SpecError: the run was not cached (``cache_dir=None``) or is gone.
        """
        return self._load(seed)[1]

    def rollout(self, seed: int, episodes: int = 1, *, deterministic: bool = True) -> list[list[dict[str, Any]]]:
        """Episodes of run ``seed``'s policy on its env, seeded as evaluation episodes are.

        Returns:
            One list of steps per episode: ``{"obs", "action", "reward",
            "terminated", "truncated", "info"}`` with ``info["goals"]``.

        Example:
            >>> result = goal_spec_result(spec)  # doctest: +SKIP
            >>> last = result.rollout(0, episodes=1)[0][-1]  # doctest: +SKIP
            >>> assert last["info"]["goals"]["pendulum/stabilization"]  # doctest: +SKIP
        """
        from specguard.training.rollout import rollout

        model, normalizer = self._load(seed)
        assert self.trained is not None
        return rollout(model, self.trained, episodes=episodes, deterministic=deterministic, normalizer=normalizer)

    def falsify(
        self,
        starts: StartSpace | None = None,
        *,
        seeds: list[int] | None = None,
        examples: int = 200,
        uniform: int = 100,
        search_seed: int = 0,
        database: str | Path | None = None,
        progress: Callable[[str], None] | None = None,
    ) -> dict[int, Falsification]:
        """Search ``starts`` for starts from which each run's cached policy misses the spec (no retraining).

        Args:
            starts: the start space (:class:`~specguard.starts.space.StartSpace`); ``None``: the spec's own
                (``Spec.starts``), else the env's.
            seeds: the runs to falsify; ``None``: every run.
            examples: guided episodes per run at most; ``uniform``: uniform draws for the failure rate.
            database: the Hypothesis example database directory counterexamples are stored in and
                replayed from; default ``<cache_dir>/falsify``.

        Returns:
            Per seed, what was found (:class:`~specguard.falsify.search.Falsification`).

        Raises:
            SpecError: a run was not cached.
        """
        from specguard.engine.falsify_run import falsify_run

        found = {}
        for seed in seeds if seeds is not None else [r.seed for r in self.runs]:
            model, normalizer = self._load(seed)
            assert self.trained is not None
            found[seed] = falsify_run(
                self.trained,
                model,
                normalizer,
                seed=seed,
                spec_key=self.spec_key,
                starts=starts,
                examples=examples,
                uniform=uniform,
                search_seed=search_seed,
                database=database if database is not None else (Path(self.cache_dir or ".") / "falsify"),
                progress=progress,
            )
        return found

    def _load(self, seed: int) -> tuple[Any, Any]:
        from specguard.cache.models import load_model

        if self.trained is None or self.cache_dir is None:
            raise SpecError(
                f"Spec {self.spec!r}: no model kept for seed {seed}: the runs were not cached",
                hint="run with a cache (the default) to reach trained models",
            )
        try:
            return load_model(self.trained, seed, self.cache_dir)
        except FileNotFoundError as e:
            raise SpecError(f"Spec {self.spec!r}: {e}", hint="train it again: its cache entry is gone") from None

    def success(self, path: str) -> tuple[int, int]:
        """Pooled ``(successes, episodes)`` of a goal (or safe episodes of a safety key) over all runs."""
        return sum(r.successes[path] for r in self.runs), sum(r.episodes for r in self.runs)

    def to_dict(self) -> dict[str, Any]:
        return {
            "spec": self.spec,
            "passed": self.passed,
            "seconds": self.seconds,
            "runs": [r.to_dict() for r in self.runs],
            "goals": {p: {**asdict(g), "kind": kind(p)} for p, g in self.goals.items()},
            "errors": {str(k): v for k, v in self.errors.items()},
            "cached": {str(k): v for k, v in self.cached.items()},
            "confidence": self.confidence,
            "spec_key": self.spec_key,
        }

    def notes(self) -> list[str]:
        """The facts about the evaluation episodes that every door shows beside the verdicts, one line each.

        Where the root goal holds until the end: the episodes that started outside it (failed before the
        policy acted) and those the env ended by termination before their horizon (docs/semantics.md,
        "Goals that hold until the end"); for a reach goal, the episodes that started inside it (met
        before the policy acted).
        """
        episodes = sum(r.episodes for r in self.runs)
        started = sum(r.started_in_goal for r in self.runs)
        tree = self.trained.tree if self.trained is not None else None
        root = tree.name if tree is not None else next((p for r in self.runs[:1] for p in r.successes), "?")
        lines = []
        capped = sum(r.capped for r in self.runs)
        if capped:
            lines.append(
                f"{capped} of {episodes} evaluation episodes were cut at {cap.EPISODE_CAP} steps, specguard's cap "
                "for an env that declares no episode limit: give it the horizon you mean (max_episode_steps=N for "
                "an env id, a TimeLimit in a factory)"
            )
        if tree is None or not until_end(tree):
            if started:
                lines.append(
                    f"{started} of {episodes} evaluation episodes started inside the root goal {root!r}: "
                    "met before the policy acted"
                )
            return lines
        if episodes - started:  # a goal that must hold from the first state on
            lines.append(
                f"{episodes - started} of {episodes} evaluation episodes started outside the root goal "
                f"{root!r}, which must hold until the end: failed before the policy acted"
            )
        terminated = sum(r.terminated for r in self.runs)
        if terminated:
            horizon = keeps_to_horizon(tree)
            why = (
                "an Always goal does not keep such an episode unless until='termination'"
                if horizon
                else "until='termination' takes that as a good end: they were judged on their last state"
            )
            lines.append(
                f"{terminated} of {episodes} evaluation episodes were ended by termination before their horizon "
                f"(the env's: a fall, a crash): the root goal {root!r} holds until the end, and {why}"
            )
        return lines

    def table(self) -> str:
        """A per-goal table: pooled success with interval, threshold, runs, verdict (:meth:`word`).

        Goals first, then the safety rates, labelled ``path:name (safe)``; then the :meth:`notes` (the
        episodes that started inside the root goal, or ended before their horizon, how many).
        """
        paths = [p for r in self.runs[:1] for p in r.successes] or list(self.goals)
        paths.sort(key=lambda p: kind(p) != GOAL)  # stable: each kind keeps its order
        header = ("goal", "success", f"{self.confidence:.0%} interval", "threshold", "runs met", "verdict")
        rows = []
        for p in paths:
            k, n = self.success(p)
            rate = f"{k / n:.0%} ({k}/{n})" if n else "-"
            iv = "-" if not n else interval_text(success_interval(k, n, self.confidence))
            g = self.goals.get(p)
            met = "-" if g is None else f"{g.runs.count(RunVerdict.MET)}/{len(g.runs)} (need {g.required})"
            threshold = "-" if g is None else f">= {g.threshold:g}"
            rows.append((label(p), rate, iv, threshold, met, "-" if g is None else self.word(p)))
        lines = render_table(header, rows) + self.notes()
        for run in self.runs:
            if run.weights:
                lines.append(f"seed {run.seed} adapted weights: {weights_text(run.weights)}")
        for seed, message in self.errors.items():
            lines.append(f"seed {seed} failed: {message}")
        return "\n".join(lines)
