"""An agent judged under pytest, against the agent a baseline saved for its test (docs/semantics.md, "A saved agent's
comparison").

``--goal-specs-save`` stores an :class:`~specguard.gate.baseline.AgentEntry` per agent test (:func:`saved_entry`): the
agent's identity, its spec's key, the evaluation settings, and per episode (as many as the check may draw, its
``max_episodes``) the env seed and each asserted goal's and safety rate's outcome. ``--goal-specs-compare`` plays the
new agent on **the baseline's own episodes** (the same env seeds: the pairs are paired) and tests each key with the
exact one-sided McNemar test of a drop, as :func:`~specguard.gate.agent_gate.compare_agents` does (its
:func:`~specguard.gate.agent_gate.paired_figures` and :func:`~specguard.gate.agent_gate.key_comparison`). There is one
look, on the saved episodes, so its p-value needs no looks correction; each key is judged at Holm's first step over
the baseline's comparisons, and the session's Holm procedure takes its p-value beside the trained specs'
(:func:`specguard.pytest_plugin.recorder.apply_family`).

Not compared, each with its reason (:func:`compare_saved`): a test the baseline stored as a trained spec, or holds
nothing for; an agent judged against another spec (its key differs) or with other settings; and the very agent the
baseline saved, whose outcomes are the baseline's (as a spec a pull request leaves alone is not compared).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from specguard.agents.agent import Agent
from specguard.engine.check_agent import AgentCheck, agent_stages, evaluation_identity, seed_base, spec_agent
from specguard.error import AgentError, FingerprintError
from specguard.gate.agent_gate import KeyComparison, compared_keys, key_comparison, paired_figures, played
from specguard.gate.baseline import SETTINGS, AgentEntry, Baseline, spec_of_key
from specguard.stats.paired import drop_p_value
from specguard.stats.sequential import DEFAULT_MARGIN, describe_change

__all__ = ["SavedAgentGate", "compare_saved", "saved_entry"]


@dataclass(frozen=True)
class SavedAgentGate:
    """An agent item's comparison with the agent its baseline saved.

    Attributes:
        keys: per compared goal path and safety key, its comparison on the pairs (none when not compared).
        reason: why nothing was compared (the comparison column's line), or None.
        level: each key's level (Holm's first step over the baseline's comparisons); margin: a drop called fine
            once clearly below it.
    """

    keys: dict[str, KeyComparison] = field(default_factory=dict)
    reason: str | None = None
    level: float = 0.05
    margin: float = DEFAULT_MARGIN

    def describe(self, key: str) -> str:
        """A compared key's line, in the words of a trained spec's comparison (dropped, improved, unchanged within
        chance, undecided), with the pairs it was measured on."""
        k = self.keys[key]
        return describe_change(
            k.state,
            k.old / k.episodes,
            k.new / k.episodes,
            p_drop=k.p_value,
            p_rise=drop_p_value(k.gained, k.lost),
            alpha=self.level,
            upper=k.bound,
            margin=self.margin,
            sample=f"paired on {k.episodes} saved episodes, {k.lost} lost, {k.gained} gained",
            most="all the baseline saved",
        )

    def figures(self, key: str) -> dict[str, Any]:
        """A compared key's figures, for the session's family-wise procedure and the reports."""
        k = self.keys[key]
        return {
            "p_drop": k.p_value,
            "p_rise": drop_p_value(k.gained, k.lost),
            "state": k.state.value,
            "level": self.level,
            "before": k.old / k.episodes,
            "after": k.new / k.episodes,
            "episodes": k.episodes,
            "lost": k.lost,
            "gained": k.gained,
        }


def _identity(check: AgentCheck, agent: Agent) -> tuple[dict[str, Any], dict[str, Any], bool]:
    """The entry's identity (``agent``, ``spec``: the spec's key), its settings (:data:`SETTINGS`), and whether the
    env repeats a fixed-seed rollout.

    Raises:
        FingerprintError, AgentError: as :func:`~specguard.engine.check_agent.evaluation_identity`.
    """
    parts, reproducible = evaluation_identity(check.spec, agent, check.wrap)
    settings = {"observation": check.observation, "wrap": parts["wrap"], "seed_base": seed_base(check.seed)}
    return parts, settings, reproducible


def _options(check: AgentCheck) -> dict[str, Any]:
    return {"observation": check.observation, "wrap": check.wrap, "seed": check.seed}


def saved_entry(check: AgentCheck, outcomes: list[dict[str, int]]) -> AgentEntry:
    """What ``--goal-specs-save`` stores for ``check``: its agent on as many episodes as the check may draw (its
    ``max_episodes``), ``outcomes`` (those its verdicts played, each episode's own) extended in place.

    Raises:
        FingerprintError, AgentError: the spec, the agent or ``wrap`` has no exact identity (nothing to save).
        EvaluationError, AgentError: an episode failed, as :func:`~specguard.engine.check_agent.check_agent`'s.
    """
    most = agent_stages("AgentCheck", check.spec, check.episodes, check.max_episodes)[-1]
    agent = spec_agent(check.spec, check.agent, algorithm=check.algorithm)
    parts, settings, _ = _identity(check, agent)
    first = played(check.spec, agent, outcomes, most, **_options(check))
    base = settings["seed_base"]
    return AgentEntry(
        agent=parts["agent"],
        name=agent.name,
        spec=parts["spec"],
        settings=settings,
        seeds=list(range(base, base + most)),
        outcomes={key: [o[key] for o in first] for key in compared_keys(check.spec)},
    )


def _differs(saved: dict[str, Any], ours: dict[str, Any]) -> str:
    """``seed_base 1100000, not 1000000 as saved``: each setting that differs, ours then the baseline's."""
    return ", ".join(f"{k} {ours[k]!r}, not {saved[k]!r} as saved" for k in SETTINGS if saved[k] != ours[k])


def compare_saved(
    check: AgentCheck,
    outcomes: list[dict[str, int]],
    baseline: Baseline,
    group: str,
    name: str,
    *,
    level: float,
    margin: float = DEFAULT_MARGIN,
) -> SavedAgentGate:
    """Compare ``check``'s agent with the agent ``baseline`` (named ``name``) saved for test ``group``, on the
    baseline's own episodes (``outcomes``, those the check played, extended in place to them).

    Raises:
        EvaluationError, AgentError: an episode failed, as :func:`~specguard.engine.check_agent.check_agent`'s.
    """
    saved = baseline.agents.get(group)
    if saved is None:
        trained = any(spec_of_key(key) == group for key in baseline.runs)
        what = "a trained spec's figures for this test, not an agent's" if trained else "no agent saved for this test"
        return SavedAgentGate(reason=f"not compared: baseline {name!r} holds {what}")
    agent = spec_agent(check.spec, check.agent, algorithm=check.algorithm)
    try:
        parts, settings, reproducible = _identity(check, agent)
    except (FingerprintError, AgentError) as e:
        return SavedAgentGate(reason=f"not compared: {e}")
    if parts["spec"] != saved.spec:
        return SavedAgentGate(
            reason=f"not compared: the spec changed since baseline {name!r} (a saved agent is compared on its spec)"
        )
    if settings != saved.settings:
        differs = _differs(saved.settings, settings)
        return SavedAgentGate(reason=f"not compared: other evaluation settings than baseline {name!r}'s ({differs})")
    if parts["agent"] == saved.agent:
        return SavedAgentGate(
            reason=f"unchanged: the same agent as baseline {name!r} ({saved.name!r}; its outcomes are the "
            "baseline's); not compared"
        )
    base, n = settings["seed_base"], len(saved.seeds)
    if not reproducible or saved.seeds != list(range(base, base + n)):
        why = "the env does not repeat a fixed-seed rollout" if not reproducible else "its seeds are not its settings'"
        return SavedAgentGate(reason=f"not compared: baseline {name!r}'s episodes cannot be replayed ({why})")
    new = played(check.spec, agent, outcomes, n, **_options(check))
    old = [{key: values[i] for key, values in saved.outcomes.items()} for i in range(n)]
    keys = {}
    for key in compared_keys(check.spec):
        if key in saved.outcomes:
            figures = paired_figures(old, new, key)
            p_value = drop_p_value(figures[2], figures[3])
            keys[key] = key_comparison(figures, n, p_value, dropped=p_value <= level, margin=margin)
    return SavedAgentGate(keys, level=level, margin=margin)
