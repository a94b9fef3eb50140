"""Gating a retrained agent against the one it replaces: :func:`compare_agents` (docs/semantics.md, "Two agents'
comparison").

Both agents are judged against the spec as :func:`~specguard.engine.check_agent.check_agent` judges one (the new
agent's verdicts are the check's verdict), on the same evaluation seed, so that episode ``i`` of each starts from the
same state: the episodes are paired. Every goal and safety rate is then compared on those pairs by the exact one-sided
McNemar test of a drop (:mod:`specguard.stats.paired`), looked at after each stage of the evaluation
(``episodes``, doubled up to ``max_episodes``) while a comparison is *open* and none has *dropped*, each look at its
Bonferroni share of the level; the comparisons together are held at the family-wise ``level`` by Holm's procedure
(:mod:`specguard.stats.family`). A comparison is *fine* once the upper bound of its drop is below ``margin``.

The keys compared are the spec's asserted ones, those with a threshold (:func:`compared_keys`), as against a saved
baseline (:mod:`specguard.gate.saved_agent`): an unasserted leaf is measured, never gated. The comparison passes
(:attr:`AgentComparison.passed`, and so ``specguard check --against``'s exit status) when the new agent's check is as
expected and nothing dropped.

Example:
    >>> import specguard as sg
    >>> cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    >>> up = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="up")
    >>> spec = sg.Spec(cartpole, up, budget=sg.Budget(timesteps=1, eval_episodes=20), expect=0.5)
    >>> lean = lambda obs: int(obs[2] > 0)
    >>> comparison = compare_agents(spec, lean, lean, max_episodes=20)
    >>> comparison.dropped, comparison.keys["up"].state  # no drop against itself ...
    ([], <GateState.FINE: 'fine'>)
    >>> comparison.result.status(), comparison.passed  # ... but it misses its threshold: the comparison fails
    ('FAILED', False)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from specguard.agents.agent import Agent
from specguard.engine.check_agent import AGENT_OBSERVATIONS, agent_episodes, agent_stages, check_agent, spec_agent
from specguard.engine.spec_result import SpecResult
from specguard.spec.spec import Spec
from specguard.stats.family import holm, procedure_text
from specguard.stats.paired import TEST, discordant, drop_p_value, drop_upper_bound, repeated_p_value
from specguard.stats.sequential import DEFAULT_ALPHA, DEFAULT_MARGIN, GateState
from specguard.validation import check_choice, check_fraction, check_natural, check_open_fraction

__all__ = [
    "AgentComparison",
    "Figures",
    "KeyComparison",
    "compare_agents",
    "compared_keys",
    "key_comparison",
    "paired_figures",
    "played",
]

Figures = tuple[int, int, int, int]
"""One key on paired episodes: the old agent's successes, the new one's, the pairs lost (``b``) and gained (``c``)."""


@dataclass(frozen=True)
class KeyComparison:
    """One goal's or safety rate's comparison on the paired episodes.

    Attributes:
        old: the old agent's successes in the compared episodes; new: the new agent's; episodes: the pairs.
        lost: episodes only the old agent met (``b``); gained: episodes only the new one met (``c``).
        p_value: the repeated p-value of the looks taken (:func:`specguard.stats.paired.repeated_p_value`).
        bound: the upper bound of the drop in success (rate points).
        state: dropped (flagged by Holm's procedure), fine (bound below the margin) or open.
    """

    old: int
    new: int
    episodes: int
    lost: int
    gained: int
    p_value: float
    bound: float
    state: GateState


@dataclass
class AgentComparison:
    """The new agent against the old one on one spec.

    Attributes:
        result: the new agent's result against the spec's thresholds (the check's verdict).
        baseline: the old agent's result against them.
        keys: per goal path and safety key, its comparison.
        looks: the episodes at each look taken; planned: the looks planned.
        level: the family-wise level; margin: the drop called fine once clearly below it.
    """

    result: SpecResult
    baseline: SpecResult
    keys: dict[str, KeyComparison]
    looks: list[int]
    planned: int
    level: float
    margin: float

    @property
    def dropped(self) -> list[str]:
        """The goals and safety rates that dropped, in the order compared."""
        return [key for key, k in self.keys.items() if k.state is GateState.DROPPED]

    @property
    def passed(self) -> bool:
        """The comparison's one verdict, at every door (this object, its ``to_dict()``, and the exit status of
        ``specguard check --against``): the new agent's check is as expected
        (:attr:`SpecResult.as_expected <specguard.engine.spec_result.SpecResult.as_expected>`: no seed failed and
        every asserted goal passed or was expected to miss, an undecided one counted as the spec's ``undecided``
        says) **and** no goal or safety rate dropped against the old agent (:attr:`dropped`)."""
        return self.result.as_expected and not self.dropped

    def summary(self) -> str:
        """The family-wise line: the test, the procedure and its level, the looks."""
        dropped = len(self.dropped)
        return (
            f"{dropped} of {len(self.keys)} dropped: {TEST}, {procedure_text(self.level, max(1, len(self.keys)))}, "
            f"{len(self.looks)} of {self.planned} looks (at {', '.join(map(str, self.looks))} episodes), "
            f"margin {self.margin:.0%}"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "passed": self.passed,
            "looks": self.looks,
            "planned_looks": self.planned,
            "level": self.level,
            "margin": self.margin,
            "keys": {key: {**asdict(k), "state": k.state.value} for key, k in self.keys.items()},
        }


def compared_keys(spec: Spec) -> list[str]:
    """The keys a comparison of two agents compares, at every door (:func:`compare_agents`, and a saved agent's
    comparison under pytest, :mod:`specguard.gate.saved_agent`, which stores and gates these): the spec's asserted
    goals and safety rates, those with a threshold, in the spec's order. An unasserted leaf is measured, not gated,
    as a trained spec's comparison with a baseline gates only its thresholded goals."""
    return list(spec.thresholds)


def played(
    spec: Spec, agent: Agent, outcomes: list[dict[str, int]], total: int, **options: Any
) -> list[dict[str, int]]:
    """The outcomes of the agent's first ``total`` episodes: ``outcomes`` (those its check played, each episode's
    own), extended in place by the episodes beyond them that the pairs need (``options``: ``observation``, ``wrap``
    and ``seed``, as :func:`~specguard.engine.check_agent.agent_episodes` takes them)."""
    have = len(outcomes)
    if have < total:
        outcomes += agent_episodes(spec, agent, have, total - have, **options)
    return outcomes[:total]


def paired_figures(old: Sequence[Mapping[str, int]], new: Sequence[Mapping[str, int]], key: str) -> Figures:
    """``(old, new, lost, gained)`` on ``key`` over paired episodes (each episode's outcomes, as
    :func:`~specguard.engine.check_agent.check_agent` gives them): each side's successes, and the discordant pairs.

    Example:
        >>> paired_figures([{"up": 1}, {"up": 1}, {"up": 0}], [{"up": 0}, {"up": 1}, {"up": 0}], "up")
        (2, 1, 1, 0)
    """
    old_k = [bool(o[key]) for o in old]
    new_k = [bool(o[key]) for o in new]
    b, c = discordant(old_k, new_k)
    return sum(old_k), sum(new_k), b, c


def key_comparison(figures: Figures, episodes: int, p_value: float, *, dropped: bool, margin: float) -> KeyComparison:
    """One key's comparison from its :func:`paired_figures` on ``episodes`` pairs and its p-value of a drop: dropped
    where the family's procedure flags it (``dropped``), else fine once the drop's upper bound is under ``margin``,
    else open."""
    old, new, b, c = figures
    bound = drop_upper_bound(b, c, episodes)
    state = GateState.DROPPED if dropped else GateState.FINE if bound < margin else GateState.OPEN
    return KeyComparison(old, new, episodes, b, c, p_value, bound, state)


def compare_agents(
    spec: Spec,
    new: Any,
    old: Any,
    *,
    episodes: int | None = None,
    max_episodes: int | None = None,
    observation: str = "env",
    wrap: Any = None,
    seed: int = 0,
    algorithm: str | type | None = None,
    level: float = DEFAULT_ALPHA,
    margin: float = DEFAULT_MARGIN,
    trust: bool = False,
) -> AgentComparison:
    """Judge ``new`` against ``spec`` and compare it with ``old`` on paired episodes, per goal and safety rate.

    Args:
        spec, episodes, max_episodes, observation, wrap, seed, algorithm, trust: as for
            :func:`~specguard.engine.check_agent.check_agent`, the same for both agents (``wrap`` and ``algorithm``
            too: two agents trained alike).
        new: the agent to gate; old: the agent it replaces (anything ``check_agent`` takes).
        level: the family-wise level of the comparisons (Holm's procedure).
        margin: the drop in success (rate points) a comparison is *fine* once clearly below, in ``(0, 1]``.

    Returns:
        The comparison of each asserted goal and safety rate (:func:`compared_keys`); it passes
        (:attr:`AgentComparison.passed`) when the new agent's check is as expected and none dropped.

    Raises:
        InvalidSpec: an argument is out of range. AgentError, AgentMismatch, EvaluationError: as ``check_agent``.
    """
    where = f"compare_agents({spec.label!r})" if isinstance(spec, Spec) else "compare_agents"
    stages = agent_stages(where, spec, episodes, max_episodes)
    check_choice(where, "observation", observation, AGENT_OBSERVATIONS)
    seed = check_natural(where, "seed", seed, "the evaluation seeds' run")
    level = check_open_fraction(where, "level", level, "the family-wise level")
    margin = check_fraction(where, "margin", margin, "rate points")
    agents = {
        "new": spec_agent(spec, new, algorithm=algorithm, trust=trust),
        "old": spec_agent(spec, old, algorithm=algorithm, trust=trust),
    }
    outcomes: dict[str, list[dict[str, int]]] = {"new": [], "old": []}
    options = {"observation": observation, "wrap": wrap, "seed": seed}
    results = {
        side: check_agent(spec, agent, episodes=stages[0], max_episodes=stages[-1], outcomes=outcomes[side], **options)
        for side, agent in agents.items()
    }
    paths = compared_keys(spec)
    p_values: dict[str, list[float]] = {key: [] for key in paths}
    looks: list[int] = []
    keys: dict[str, KeyComparison] = {}
    for total in stages:
        for side, agent in agents.items():
            played(spec, agent, outcomes[side], total, **options)
        looks.append(total)
        figures = {key: paired_figures(outcomes["old"][:total], outcomes["new"][:total], key) for key in paths}
        for key, (_, _, b, c) in figures.items():
            p_values[key].append(drop_p_value(b, c))
        repeated = {key: repeated_p_value(p_values[key], len(stages)) for key in paths}
        flagged = holm(repeated, level)
        keys = {
            key: key_comparison(figures[key], total, repeated[key], dropped=flagged[key] is not None, margin=margin)
            for key in paths
        }
        states = {k.state for k in keys.values()}
        if GateState.DROPPED in states or GateState.OPEN not in states:
            break
    return AgentComparison(results["new"], results["old"], keys, looks, len(stages), level, margin)
