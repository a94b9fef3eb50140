"""The falsifier: a guided search for starts from which a trained policy misses its spec.

:class:`EpisodeRunner` runs a policy (any callable from a batch of
observations to a batch of actions: a trained model, or a planted policy in a
test; one that carries something per env, an :class:`~specguard.construction.episode_policy.EpisodePolicy`, is told
when episodes start and which rows still run) on the spec's env from chosen starts, several starts in lockstep so
the policy is asked once per step for all of them, and judges each
episode by the spec's property: the verdict at its end, as the env reports it, and
a robustness score that steers the search (:mod:`specguard.falsify.robustness`):
by default each key's margin in the last state (``score="last"``); with
``score="episode"``, signal temporal logic's over the whole episode, the keys
that hold throughout it by their lowest margin over its states, kept per row as
the batch steps (dearer per episode, and not better on the held-out agents of
docs/guide/falsify.md).

:func:`falsify` searches a start space:

1. **replay**: the counterexample stored under ``key`` in the Hypothesis
   example database (if any) is run first; if it still fails, that is the answer;
2. **guided search**: ``EXPLORE`` uniform draws with the middle of the
   space among them (the fourth start), then rounds of a portfolio of
   samplers (uniform draws, a cross-entropy trend, local steps;
   :mod:`specguard.falsify.portfolio`) that shifts each round's starts to
   the samplers whose episodes came closest to failing, keeping half of them
   uniform; it stops at the first failing start, which is then moved
   towards the middle of the space, each variable in turn
   (set to its middle if the start still fails there, else bisected), so the
   counterexample has as few variables off the middle as it can, each on the
   boundary of the failure region;
3. **uniform draws**, counted apart: ``uniform`` starts drawn uniformly
   give the failure rate over the space, with its interval; where the guided
   search found nothing but a uniform draw failed, that draw, shrunk the
   same way, is the counterexample (the rate still counts only the draws).

The shrunk start is saved under ``key`` so the next run replays it first.

Why not Hypothesis's own generation with :func:`hypothesis.target`: measured
by an earlier ``benchmarks/bench_falsify.py`` (docs/guide/falsify.md), it
needed more episodes than uniform sampling to a first failure (a median of 179.5 against 152.5 on the CartPole
case study, 143.5 against 73 on Acrobot). Its generation is built for
programs, whose bugs sit at the middle, the edges and the special values of a
range; a trained policy's failures are thin regions inside it, near the
starts where the policy already struggles. Hypothesis keeps its example
database: the counterexample replayed first.
"""

from __future__ import annotations

import contextlib
import json
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from specguard.construction.env import BaselineEnv, SpecEnv, features_space, stack_observations
from specguard.construction.episode_policy import EpisodePolicy
from specguard.error import InvalidSpec
from specguard.extend import until_end
from specguard.falsify.portfolio import Portfolio
from specguard.falsify.predictor import FailureData, FailurePredictor
from specguard.falsify.related import EPSILONS, perturbed
from specguard.falsify.robustness import (
    SCORES,
    EpisodeMinimum,
    Judgement,
    feature_scales,
    judge_end,
    own_states,
    reached_early,
)
from specguard.starts.setter import env_label
from specguard.starts.space import START_OPTION, Starts, StartSpace, starts_of
from specguard.stats.importance import RateEstimate, importance_rate, proposal, weights_of
from specguard.stats.intervals import failure_upper_bound, success_interval
from specguard.validation import check_choice, check_count, check_flag, check_natural, check_open_fraction

__all__ = ["EpisodeRunner", "Falsification", "Outcome", "falsify", "judged_env", "start_text"]

BISECTIONS = 16
"""Bisection steps per variable when a counterexample is moved to the failure region's boundary."""

EXPLORE = 16
"""Uniform draws (the middle of the space among them) before the portfolio's rounds."""

POOL = 20
"""The importance-sampling pool holds this many uniform starts per episode drawn from it (its own spread is a floor
under the interval's width; a start is scored without an episode, by a reset)."""

DEFENSIVE = 0.5
"""The uniform share of the importance-sampling proposal: every weight is at most ``1 / DEFENSIVE``."""

MIN_FAILURES = 3
"""The failure predictor is fitted only on data with at least this many failures (and a success)."""

PROBES = 64
"""Uniform starts whose features tell how much of the start space the predictor's data spans."""

COVERAGE = 0.5
"""The failure predictor is used only where at least this share of the start space's starts (``PROBES`` uniform
draws) have features within the range its data's starts span, feature by feature (5% of each range beyond its ends
admitted). A run's looks start where the env's own reset does; a search over a wider space than that (as the
benchmark's InvertedPendulum, within 0.2 rad of upright where training started within 0.01) would follow a surface
fitted elsewhere: on those held-out agents the looks' predictor cost 16% and 36% more episodes than none."""

MIDDLE_AFTER = 3
"""The exploration runs the middle of the space after this many uniform draws.

Not first: where failures are common (a third to a half of all starts, as on InvertedPendulum's wide starts),
one of three uniform draws fails with probability 0.7 to 0.9, so the middle rarely runs before the first failure
(run first, it cost random's 2 or 3 episodes one more). Not last: where the middle itself fails (a trained agent's
start at rest, as some CartPole and Acrobot agents), it is found by the fourth episode, not the seventeenth.
"""


@dataclass(frozen=True)
class Outcome:
    """One episode from one start.

    Attributes:
        start: the start, by variable.
        judgement: the property: the keys missed at the episode's end, the margins (as the runner's ``score``).
        steps: the episode's length.
        ended: ``"terminated"`` or ``"truncated"``.
        last: the last state's features, by name.
        first: the first state's features, in the spec's order (the failure predictor's input).
    """

    start: dict[str, float]
    judgement: Judgement
    steps: int
    ended: str
    last: dict[str, float]
    first: tuple[float, ...] = ()

    @property
    def failed(self) -> bool:
        return bool(self.judgement.missed)

    def summary(self) -> str:
        """A short line: the episode's length, how it ended, its last state and what it missed."""
        last = ", ".join(f"{k}={v:.3g}" for k, v in self.last.items())
        missed = ", ".join(self.judgement.missed) or "nothing"
        return f"{self.steps} steps, {self.ended} at ({last}); missed {missed}; score {self.judgement.score:.3g}"


class EpisodeRunner:
    """Runs a policy from chosen starts on fresh copies of one env, several starts in lockstep.

    Args:
        make_env: ``make_env(starts=space)`` builds the spec's env in the start space's wrapper (a ``SpecEnv``:
            it reports goals, safety and its evaluator), as :meth:`Spec.make_env
            <specguard.spec.spec.Spec.make_env>` and :func:`~specguard.construction.env.make_env` do; or a
            ``BaselineEnv`` (:func:`~specguard.construction.env.make_baseline_env`), its episodes the initial env's
            own; either may be wrapped (an agent's observation wrappers), the goals read beneath.
        act: ``act(observations) -> actions``, a batch (rows) to a batch; an
            :class:`~specguard.construction.episode_policy.EpisodePolicy` is told when the batch's episodes start and
            which rows still run.
        space: the start space.
        keys: the asserted goal paths and safety keys (the property).
        batch: starts run in lockstep.
        score: the robustness score that steers the search (:data:`~specguard.falsify.robustness.SCORES`):
            ``"last"``, each key's margin in the episode's last state (the default); ``"episode"``, over the whole
            episode (:class:`~specguard.falsify.robustness.EpisodeMinimum`: margins at every step).

    Raises:
        InvalidSpec: ``score`` is not one of ``SCORES``, naming it and the choices.
    """

    def __init__(
        self,
        make_env: Callable[..., Any],
        act: Callable[[np.ndarray], Any],
        space: StartSpace,
        keys: Sequence[str],
        *,
        batch: int = 8,
        score: str = "last",
    ) -> None:
        self.score = check_choice("EpisodeRunner", "score", score, SCORES)
        self._make_env = make_env
        self.space = space
        self.act = act
        self.keys = tuple(keys)
        self.batch = max(1, int(batch))
        first = make_env(starts=space)
        self.starts: Starts = starts_of(first)
        self._envs: list[Any] = [first]
        judged = judged_env(first)
        self.observation_space, self.action_space = first.observation_space, first.action_space
        """What the policy reads and gives (the env's, outermost wrapper's)."""
        self.tree = judged.tree
        self.scales = feature_scales(judged.features, *_feature_bounds(judged))
        self.discrete = isinstance(first.action_space, gym.spaces.Discrete)
        self.max_steps = _time_limit(first)
        # Reaching the root goal ends a constructed env's episode; a baseline's end where the initial env ends them.
        self.reach = isinstance(judged, SpecEnv) and not until_end(self.tree)
        """The episode's step limit (``None``: the env has no ``TimeLimit``)."""
        self.episodes = 0
        """Episodes run so far."""
        self.lowest = EpisodeMinimum(self.tree, self.keys, self.scales) if self.score == "episode" else None
        """The running minimum of the margins of the keys judged over the whole episode, per row of a batch
        (``None``: ``score="last"``, no margins before an episode's end)."""

    def _ready(self, k: int) -> list[Any]:
        while len(self._envs) < k:
            self._envs.append(self._make_env(starts=self.space))
        return self._envs[:k]

    @contextlib.contextmanager
    def acting(self, act: Callable[[np.ndarray], Any]) -> Iterator[None]:
        """Episodes run within are ``act``'s instead of the runner's policy, which is put back after."""
        own, self.act = self.act, act
        try:
            yield
        finally:
            self.act = own

    def features(self, points: np.ndarray) -> np.ndarray:
        """The first state's features from each start (rows of ``points``): each start set by a reset, no step
        run, no episode counted (what the failure predictor reads of a start it is asked about)."""
        env, judged = self._envs[0], judged_env(self._envs[0])
        rows = []
        for p in points:
            env.reset(seed=0, options={START_OPTION: self.starts.values(p)})
            rows.append(judged.start_features)
        return np.array(rows, dtype=np.float64).reshape(len(points), -1)

    def run(self, points: np.ndarray) -> list[Outcome]:
        """One episode from each start (rows of ``points``), in lockstep batches."""
        out: list[Outcome] = []
        for lo in range(0, len(points), self.batch):
            out.extend(self._run_batch(points[lo : lo + self.batch]))
        return out

    def _run_batch(self, points: np.ndarray) -> list[Outcome]:
        envs = self._ready(len(points))
        starts = [self.starts.values(p) for p in points]
        obs = [env.reset(seed=0, options={START_OPTION: v})[0] for env, v in zip(envs, starts, strict=True)]
        first = [judged_env(env).start_features for env in envs]
        steps = [0] * len(envs)
        results: list[Outcome | None] = [None] * len(envs)
        active = list(range(len(envs)))
        act = self.act
        if isinstance(act, EpisodePolicy):
            act.start(envs)
        lowest = self.lowest
        if lowest is not None:
            lowest.start(len(envs))
        watch = lowest if lowest is not None and lowest.keys else None  # margins at every step: score="episode"
        while active:
            rows = stack_observations([obs[i] for i in active])
            actions = act(rows, active) if isinstance(act, EpisodePolicy) else act(rows)
            for j, i in enumerate(active):
                action = int(actions[j]) if self.discrete else actions[j]
                obs[i], _, terminated, truncated, info = envs[i].step(action)
                steps[i] += 1
                if watch is not None:
                    ev = judged_env(envs[i]).evaluator
                    watch.update(i, ev.state, own_states(ev.slots, ev.own_state), info["goals"])
                if terminated or truncated:
                    low = lowest.rows[i] if lowest is not None else None
                    results[i] = self._outcome(envs[i], starts[i], info, steps[i], bool(terminated), low, first[i])
            active = [i for i in active if results[i] is None]
        self.episodes += len(envs)
        return [r for r in results if r is not None]

    def _outcome(
        self,
        env: Any,
        start: dict[str, float],
        info: dict[str, Any],
        steps: int,
        terminated: bool,
        lowest: dict[str, float] | None,
        first: tuple[float, ...],
    ) -> Outcome:
        ev = judged_env(env).evaluator
        s = ev.state
        own = own_states(ev.slots, ev.own_state)
        judgement = judge_end(self.tree, self.keys, s, own, info["goals"], info["safe"], self.scales, lowest)
        if terminated and self.max_steps and self.reach:  # a reach goal: how early it was reached
            judgement = reached_early(judgement, self.tree.name, steps, self.max_steps)
        last = {f: float(v) for f, v in zip(s._fields, s, strict=True)}
        return Outcome(start, judgement, steps, "terminated" if terminated else "truncated", last, first)


@dataclass
class Falsification:
    """What :func:`falsify` found.

    Attributes:
        starts: the start space searched.
        counterexample: the shrunk failing start's episode, or ``None``: none found.
        first: the first failing episode found (before shrinking).
        episodes_to_first: guided episodes run up to and including the first failure.
        guided: guided episodes run (replay, search and shrinking).
        replayed: the counterexample came from the database.
        from_uniform: the guided search found none; the counterexample is the first failing uniform draw, shrunk.
        uniform_failures, uniform_episodes: the uniform draws, counted apart from the guided ones.
        interval: the failure rate's interval over the uniform draws.
        confidence: the interval's confidence, and the bound's where no uniform draw failed.
        key: the database key the counterexample is stored under.
        drawn_by: the guided search's episodes (up to and including its first failure, else all of them) by the
            sampler that drew each start: ``"uniform"`` (the exploration's draws among them), ``"middle"`` (the
            middle of the space), ``"trend"``, ``"local"``, ``"learned"`` (:data:`~specguard.falsify.portfolio.ARMS`),
            and ``"related"`` (episodes of the agent made weaker, the predictor's data); they sum to
            ``episodes_to_first`` where the search found the failure.
        found_by: the sampler whose start failed first (``None``: the search found none, or it was replayed).
        predictor: the failure predictor the search fitted (``None``: none: no data, or its data saw too
            few failures); not serialised.
        related: what it was fitted on (the run's looks and the weaker agent's episodes).
        coverage: the share of the start space's starts whose features lie within the range ``related`` spans
            (``None``: not measured: no data, or too few failures); under ``COVERAGE``, no predictor.
        importance: the failure rate by importance sampling from the predictor's proposal, with its interval
            (``None``: not asked for, ``importance=0``, or no predictor).
    """

    starts: Starts
    counterexample: Outcome | None = None
    first: Outcome | None = None
    episodes_to_first: int | None = None
    guided: int = 0
    replayed: bool = False
    from_uniform: bool = False
    uniform_failures: int = 0
    uniform_episodes: int = 0
    interval: tuple[float, float] = (0.0, 1.0)
    confidence: float = 0.95
    key: str = ""
    notes: list[str] = field(default_factory=list)
    drawn_by: dict[str, int] = field(default_factory=dict)
    found_by: str | None = None
    predictor: FailurePredictor | None = field(default=None, repr=False, compare=False)
    related: FailureData | None = field(default=None, repr=False, compare=False)
    coverage: float | None = None
    importance: RateEstimate | None = None

    @property
    def found(self) -> bool:
        return self.counterexample is not None

    @property
    def failure_rate(self) -> float:
        return self.uniform_failures / self.uniform_episodes if self.uniform_episodes else 0.0

    @property
    def origin(self) -> str:
        """How the counterexample was found, in words (``""``: none was)."""
        if self.counterexample is None:
            return ""
        if self.replayed:
            return "replayed from the database"
        if self.from_uniform:
            return f"found by the uniform draws, none in {self.guided} guided episodes"
        return f"found after {self.episodes_to_first} episodes"

    @property
    def rate_text(self) -> str:
        """The failure rate over the start space with its draws and interval (``""``: no uniform draws); where none
        failed, the most it can be: the one-sided exact binomial bound, never a bare 0%.

        Example:
            >>> import gymnasium as gym
            >>> from specguard.starts.space import StartSpace
            >>> starts = StartSpace({"x": (-0.05, 0.05)}).resolve(gym.make("CartPole-v1"))
            >>> Falsification(starts, uniform_episodes=100).rate_text
            'at most 3.0% at 95% (none in 100 uniform draws; one-sided exact binomial bound)'
        """
        if not self.uniform_episodes:
            return ""
        if not self.uniform_failures:
            bound = failure_upper_bound(self.uniform_episodes, self.confidence)
            return (
                f"at most {bound:.1%} at {self.confidence:.0%} (none in {self.uniform_episodes} uniform draws; "
                "one-sided exact binomial bound)"
            )
        lo, hi = self.interval
        return (
            f"{self.failure_rate:.1%} ({self.uniform_failures}/{self.uniform_episodes} uniform draws), "
            f"interval [{lo:.1%}, {hi:.1%}]"
        )

    def report(self) -> str:
        """A few lines: the counterexample (or none), what it missed, its episode, and the failure rate."""
        lines = [self.starts.note]
        if self.counterexample is None:
            lines.append(f"no counterexample in {self.guided} guided episodes")
        else:
            c = self.counterexample
            lines.append(f"counterexample ({self.origin}): {start_text(c.start)}")
            lines.append(f"  missed: {', '.join(c.judgement.missed)}")
            lines.append(f"  episode: {c.summary()}")
        if self.uniform_episodes:
            lines.append(f"failure rate over the start space: {self.rate_text}")
        if self.related is not None:
            lines.append(f"failure predictor: {self.predictor_text}")
        if self.importance is not None:
            lines.append(f"failure rate from the predictor's starts, weighed back: {self.importance.summary()}")
        return "\n".join([*lines, *self.notes])

    @property
    def predictor_text(self) -> str:
        """What the failure predictor was fitted on, or why it was not (``""``: no related agents' episodes).

        Example:
            >>> import gymnasium as gym
            >>> from specguard.falsify.predictor import FailureData
            >>> from specguard.starts.space import StartSpace
            >>> starts = StartSpace({"x": (-0.05, 0.05)}).resolve(gym.make("CartPole-v1"))
            >>> related = FailureData(np.zeros((48, 4)), np.full(48, 0.3), np.arange(48) < 2, np.ones(48))
            >>> Falsification(starts, related=related).predictor_text
            'not fitted: 2 failures in 48 episodes of related agents (it needs 3, and a success)'
        """
        if self.related is None:
            return ""
        seen = f"{self.related.failures} failures in {len(self.related)} episodes of related agents"
        if self.predictor is None and self.coverage is not None:
            return (
                f"not used: {seen}, whose starts span {self.coverage:.0%} of the start space's (it needs "
                f"{COVERAGE:.0%}; fitted elsewhere it would extrapolate)"
            )
        if self.predictor is None:
            return f"not fitted: {seen} (it needs {MIN_FAILURES}, and a success)"
        return f"fitted on {seen}; the learned arm drew {self.drawn_by.get('learned', 0)} of the guided starts"

    def to_dict(self) -> dict[str, Any]:
        """The findings as plain JSON-ready values (the counterexample's start exact, as stored)."""
        c = self.counterexample
        return {
            "starts": self.starts.note,
            "start": dict(c.start) if c is not None else None,
            "missed": list(c.judgement.missed) if c is not None else [],
            "origin": self.origin,
            "episode": c.summary() if c is not None else "",
            "guided": self.guided,
            "uniform_failures": self.uniform_failures,
            "uniform_episodes": self.uniform_episodes,
            "interval": list(self.interval),
            "rate": self.rate_text,
            "drawn_by": dict(self.drawn_by),
            "found_by": self.found_by,
            "predictor": self.predictor_text,
            "importance": self.importance.summary() if self.importance is not None else None,
        }


def start_text(start: Mapping[str, float]) -> str:
    """A start as reports print it, exact: each value the shortest text that reads back as the same float, so a
    start copied from a report replays the very episode (rounded, a start a millionth away may end elsewhere).

    Example:
        >>> start_text({"x": 0.5020751953125001, "v": 0.0, "theta": -1e-07})
        'x=0.5020751953125001, v=0.0, theta=-1e-07'
    """
    return ", ".join(f"{k}={float(v)!r}" for k, v in start.items())


def judged_env(env: Any) -> SpecEnv | BaselineEnv:
    """The env beneath ``env``'s wrappers that judges the goals (a ``SpecEnv`` or a ``BaselineEnv``), or ``env``.

    Raises:
        InvalidSpec: none of ``env`` and its wrappers reports goals.
    """
    inner = env
    while not isinstance(inner, (SpecEnv, BaselineEnv)):
        if not isinstance(inner, gym.Wrapper):
            raise InvalidSpec(
                env_label(env),
                f"no SpecEnv or BaselineEnv among the env's wrappers ({type(env).__name__} over "
                f"{type(env.unwrapped).__name__}): nothing judges its goals",
                hint="make it with make_env or make_baseline_env",
            )
        inner = inner.env
    return inner


def _feature_bounds(env: SpecEnv | BaselineEnv) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of ``env``'s features: a ``SpecEnv`` shows them in its observation (either kind), a baseline
    keeps them aside."""
    if isinstance(env, BaselineEnv):
        return env.feature_low, env.feature_high
    n = len(env.features)
    box = features_space(env.observation_space)
    return box.low[:n], box.high[:n]


def _time_limit(env: Any) -> int | None:
    """The episode's step limit: the outermost ``TimeLimit``'s among ``env``'s wrappers, else ``None``."""
    while env is not None:
        limit = getattr(env, "_max_episode_steps", None)
        if isinstance(limit, int) and not isinstance(limit, bool) and limit > 0:
            return limit
        env = getattr(env, "env", None)
    return None


@dataclass
class _Search:
    """What the guided search ran: by sampler, its episodes (to the first failure), and the first failure; the
    failure predictor and what it was fitted on."""

    drawn_by: Counter[str] = field(default_factory=Counter)
    hit: tuple[Outcome, np.ndarray, int] | None = None
    found_by: str | None = None
    predictor: FailurePredictor | None = None
    related: FailureData | None = None
    coverage: float | None = None


def _chances(runner: EpisodeRunner, predictor: FailurePredictor) -> Callable[[np.ndarray], np.ndarray]:
    """The predictor's chance of failing from unit-box points of the runner's start space."""
    starts = runner.starts
    half = (starts.high - starts.low) / 2.0

    def chances(unit: np.ndarray) -> np.ndarray:
        points = np.clip(starts.center + unit * half, starts.low, starts.high)
        return predictor.predict(runner.features(points))

    return chances


def _learn(
    runner: EpisodeRunner,
    related: FailureData | None,
    weaker: int,
    rng: np.random.Generator,
    search: _Search,
    room: int,
) -> FailurePredictor | None:
    """The failure predictor, fitted on ``related`` (a run's looks) and on episodes of the agent made weaker
    (``weaker`` uniform starts at each of :data:`~specguard.falsify.related.EPSILONS`, no more than ``room`` in
    all; counted as ``"related"`` episodes of the search). ``None`` where those saw fewer than ``MIN_FAILURES``
    failures, or no success: nothing to learn from; or where the data's starts span less than ``COVERAGE`` of the
    start space (``search.coverage``): fitted elsewhere, it would extrapolate."""
    data = related
    per = min(weaker, room // len(EPSILONS))
    for epsilon in EPSILONS if per else ():
        episodes = perturbed(runner, runner.starts.uniform(rng, per), epsilon, rng)
        search.drawn_by["related"] += len(episodes)
        data = episodes if data is None else data + episodes
    search.related = data
    if data is None or data.failures < MIN_FAILURES or data.failures == len(data):
        return None
    probe = runner.features(runner.starts.uniform(rng, PROBES))
    low, high = data.features.min(axis=0), data.features.max(axis=0)
    margin = 0.05 * (high - low) + 1e-12
    search.coverage = float(np.mean(np.all((probe >= low - margin) & (probe <= high + margin), axis=1)))
    return FailurePredictor().fit(data) if search.coverage >= COVERAGE else None


def _guided(
    runner: EpisodeRunner, examples: int, rng: np.random.Generator, related: FailureData | None, weaker: int
) -> _Search:
    """The guided search: its first failing start with its point and the episodes run up to it (``hit``; ``None``:
    none), and which sampler drew each episode.

    ``EXPLORE`` uniform draws with the middle of the space after the first ``MIDDLE_AFTER`` of them; then, given
    ``related`` data or ``weaker`` episodes, the failure predictor is fitted (:func:`_learn`; the weaker agent's
    episodes count among the search's); then rounds of the portfolio's proposals, its ``learned`` arm among
    them where the predictor was fitted (:mod:`specguard.falsify.portfolio`). A space of reset seeds has no
    neighbourhoods (seed 41 and seed 42 start anywhere): all its starts are uniform draws.
    """
    starts = runner.starts
    seeds = starts.how == "reset seeds"
    half = (starts.high - starts.low) / 2.0
    search = _Search()
    portfolio = Portfolio(len(starts.names), rng)
    done, learned = 0, False
    while done < examples:
        if done and (related is not None or weaker) and not seeds and not learned:
            learned = True
            predictor = search.predictor = _learn(runner, related, weaker, rng, search, examples - done)
            done += search.drawn_by["related"]
            if predictor is not None:
                portfolio.predict = _chances(runner, predictor)
            continue
        if done == 0:
            n = min(examples, EXPLORE + (0 if seeds else 1))
            drawn = starts.uniform(rng, n - (0 if seeds else 1))
            middle = [] if seeds else [starts.center[None, :]]
            points = np.concatenate([drawn[:MIDDLE_AFTER], *middle, drawn[MIDDLE_AFTER:]])
            arms = ["uniform"] * len(points)
            if middle:
                arms[min(MIDDLE_AFTER, len(drawn))] = "middle"
        elif seeds:
            points = starts.uniform(rng, min(runner.batch, examples - done))
            arms = ["uniform"] * len(points)
        else:
            unit, arms = portfolio.propose(min(runner.batch, examples - done))
            points = np.clip(starts.center + unit * half, starts.low, starts.high)
        outcomes = runner.run(points)
        for i, (outcome, point, arm) in enumerate(zip(outcomes, points, arms, strict=True)):
            search.drawn_by[arm] += 1
            if outcome.failed:
                search.hit, search.found_by = (outcome, point, done + i + 1), arm
                return search
        if not seeds:
            unit = np.divide(points - starts.center, half, out=np.zeros_like(points), where=half > 0)
            observed = ["uniform" if a == "middle" else a for a in arms]
            portfolio.observe(unit, np.array([o.judgement.score for o in outcomes]), observed)
        done += len(points)
    return search


def _importance_rate(
    runner: EpisodeRunner, predictor: FailurePredictor, episodes: int, seed: int, confidence: float
) -> RateEstimate:
    """The failure rate from ``episodes`` starts drawn from the predictor's proposal (uniform share
    ``DEFENSIVE``) over a pool of ``POOL * episodes`` uniform starts, each weighed back (unbiased)."""
    rng = np.random.default_rng([seed, 2])
    pool = runner.starts.uniform(rng, POOL * episodes)
    q = proposal(predictor.predict(runner.features(pool)), alpha=DEFENSIVE)
    drawn = rng.choice(len(q), size=episodes, p=q)
    outcomes = runner.run(pool[drawn])
    return importance_rate(
        [o.failed for o in outcomes],
        weights_of(q, drawn),
        pool=len(q),
        alpha=DEFENSIVE,
        min_weight=1.0 / (len(q) * float(q.max())),
        confidence=confidence,
    )


def _load(database: Any, key: str) -> list[dict[str, float]]:
    if database is None:
        return []
    found = []
    for raw in database.fetch(key.encode()):
        try:
            found.append({str(k): float(v) for k, v in json.loads(raw.decode()).items()})
        except (ValueError, AttributeError):
            database.delete(key.encode(), raw)  # not ours: an entry that cannot be read is dropped
    return found


def _point_of(starts: Starts, values: dict[str, float]) -> np.ndarray | None:
    if set(values) != set(starts.names):
        return None
    point = np.array([values[n] for n in starts.names], dtype=np.float64)
    return point if np.all(point >= starts.low) and np.all(point <= starts.high) else None


def _to_boundary(runner: EpisodeRunner, failing: Outcome, point: np.ndarray) -> tuple[Outcome, np.ndarray]:
    """Move each variable of a failing start towards the middle of its range while it still fails (bisection)."""
    starts = runner.starts
    if starts.how == "reset seeds":
        return failing, point
    best, best_point = failing, point.copy()
    for d in range(len(point)):
        inner, outer = starts.center[d], best_point[d]  # inner passes or is unknown; outer fails
        probe = best_point.copy()
        probe[d] = inner
        tried = runner.run(probe[None, :])[0]
        if tried.failed:
            best, best_point = tried, probe
            continue
        for _ in range(BISECTIONS):
            probe = best_point.copy()
            probe[d] = (inner + outer) / 2.0
            tried = runner.run(probe[None, :])[0]
            if tried.failed:
                outer, best, best_point = probe[d], tried, probe
            else:
                inner = probe[d]
    return best, best_point


def _kept(
    runner: EpisodeRunner,
    outcome: Outcome,
    point: np.ndarray,
    *,
    shrink: str | None,
    database: Any,
    key: str,
    say: Callable[[str], None],
) -> Outcome:
    """A failing start as the counterexample: shrunk (saying ``shrink``; ``None``: not shrunk), then stored."""
    if shrink is not None:
        say(shrink)
        outcome, _ = _to_boundary(runner, outcome, point)
    if database is not None and key:
        database.save(key.encode(), json.dumps(outcome.start).encode())
    return outcome


def falsify(
    runner: EpisodeRunner,
    *,
    examples: int = 200,
    uniform: int = 100,
    seed: int = 0,
    database: Any = None,
    key: str = "",
    shrink: bool = True,
    confidence: float = 0.95,
    progress: Callable[[str], None] | None = None,
    related: FailureData | None = None,
    weaker: int = 0,
    importance: int = 0,
) -> Falsification:
    """Search ``runner``'s start space for a start from which its policy misses the spec.

    Args:
        runner: the policy, env and property.
        examples: guided episodes at most (shrinking runs more).
        uniform: uniform draws for the failure rate, counted apart (0: none).
        seed: the search's and the draws' seed.
        database: a Hypothesis ``ExampleDatabase`` (``None``: nothing replayed or stored).
        key: the spec's identity, under which the counterexample is stored.
        shrink: shrink the first failing start (else stop at it: the benchmark's episodes to a first failure).
        progress: called with a line at each phase.
        related: episodes of related, less robust agents (a run's looks:
            :func:`~specguard.falsify.predictor.from_looks`). After the exploration, a failure predictor is fitted
            on them, and the portfolio's ``learned`` arm proposes the starts it ranks likeliest to fail.
        weaker: episodes per level of :data:`~specguard.falsify.related.EPSILONS` of the agent made weaker
            (``epsilon``-random actions, :mod:`specguard.falsify.related`), run after the exploration as more data
            for the predictor; they count among the guided episodes. 0 (the default): none, as measured in
            docs/guide/falsify.md they cost more episodes than they save.
        importance: episodes for the failure rate by importance sampling (0: none), drawn from the failure
            predictor's proposal over a pool of ``POOL`` times as many uniform starts
            (:mod:`specguard.stats.importance`), counted apart like the uniform draws; only given ``related`` data or
            ``weaker`` episodes (a search that ended before it fitted its predictor has it fitted then), and where
            they saw enough failures (``Falsification.importance``).

    Raises:
        InvalidSpec: an argument of the wrong type or out of range, naming it and its value.
    """
    where = "falsify"
    examples = check_count(where, "examples", examples, "guided episodes at most")
    uniform = check_natural(where, "uniform", uniform, "uniform draws")
    seed = check_natural(where, "seed", seed, "the search's seed")
    confidence = check_open_fraction(where, "confidence", confidence)
    shrink = check_flag(where, "shrink", shrink)
    weaker = check_natural(where, "weaker", weaker, "episodes per level of the agent made weaker")
    importance = check_natural(where, "importance", importance, "episodes drawn from the predictor's proposal")
    say = progress or (lambda line: None)
    starts = runner.starts
    result = Falsification(starts=starts, key=key, confidence=confidence)
    say(starts.note)
    start_count = runner.episodes

    for values in _load(database, key):
        point = _point_of(starts, values)
        if point is None:
            continue
        replay = runner.run(point[None, :])[0]
        if replay.failed:
            say("counterexample replayed from the database: it still fails")
            result.counterexample = result.first = replay
            result.replayed, result.episodes_to_first = True, runner.episodes - start_count
            break
        database.delete(key.encode(), json.dumps(values).encode())

    if result.counterexample is None:
        say(f"guided search: up to {examples} episodes")
        search = _guided(runner, examples, np.random.default_rng([seed, 1]), related, weaker)
        result.drawn_by, result.found_by = dict(search.drawn_by), search.found_by
        result.predictor, result.related, result.coverage = search.predictor, search.related, search.coverage
        if search.hit is not None:
            outcome, point, result.episodes_to_first = search.hit
            result.first = outcome
            moving = "shrinking: moving each variable towards the middle of its range while it still fails"
            result.counterexample = _kept(
                runner, outcome, point, shrink=moving if shrink else None, database=database, key=key, say=say
            )
    result.guided = runner.episodes - start_count
    if importance and result.related is None and (related is not None or weaker):
        fitting = _Search()  # the search ended before it fitted its predictor (an early failure): fitted now
        rng = np.random.default_rng([seed, 3])
        result.predictor = _learn(runner, related, weaker, rng, fitting, weaker * len(EPSILONS))
        result.related, result.coverage = fitting.related, fitting.coverage
        result.drawn_by["related"] = fitting.drawn_by["related"]
    if importance and result.predictor is not None:
        say(f"importance sampling: {importance} episodes from the predictor's proposal for the failure rate")
        result.importance = _importance_rate(runner, result.predictor, importance, seed, confidence)

    if uniform:
        say(f"uniform draws: {uniform} episodes for the failure rate")
        rng = np.random.default_rng(seed)
        points = starts.uniform(rng, uniform)
        drawn = runner.run(points)
        failures = sum(o.failed for o in drawn)
        result.uniform_failures, result.uniform_episodes = failures, len(drawn)
        ok_lo, ok_hi = success_interval(len(drawn) - failures, len(drawn), confidence)
        result.interval = (1.0 - ok_hi, 1.0 - ok_lo)
        if result.counterexample is None and failures:  # a failure is a failure, whoever drew it
            i = next(i for i, o in enumerate(drawn) if o.failed)
            moving = "shrinking the first failing uniform draw towards the middle of the space"
            result.counterexample = _kept(
                runner, drawn[i], points[i], shrink=moving if shrink else None, database=database, key=key, say=say
            )
            result.from_uniform = True
    return result
