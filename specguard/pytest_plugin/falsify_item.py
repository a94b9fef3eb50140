"""The ``[falsify]`` item of a goal spec: the falsifier on the session's trained runs (or on the agent of an
:class:`~specguard.engine.check_agent.AgentCheck`, :func:`specguard.engine.falsify_run.falsify_agent`), and its
pytest outcome.

The spec is trained (or read back) once per session, as for its goal items; the
falsifier then searches each run's start space on the cached model
(:func:`specguard.engine.falsify_run.falsify_runs`) and each run is judged by
:func:`specguard.falsify.assertion.falsify_verdict`. A run falsified fails the item
with its report: the shrunk start, the goals it missed, a summary of its episode,
and the failure rate over the start space with its interval. A run left
undecided by ``max_rate`` counts as the spec's ``Spec.undecided`` says, as an
undecided goal does.
"""

from __future__ import annotations

import dataclasses
import json
import warnings
from pathlib import Path
from typing import Any

import pytest

from specguard.pytest_plugin.items import GoalMissed, group_of, one_line_errors
from specguard.pytest_plugin.session import GoalSpecSession, terminal_lines

__all__ = ["COUNTEREXAMPLES", "run_falsify_item"]

COUNTEREXAMPLES = "specguard.counterexamples"
"""The user property carrying a falsify item's runs (JSON) to the reports, on the xdist controller too."""


def run_falsify_item(item: pytest.Function, state: GoalSpecSession, check: Any, expect: Any) -> None:
    """Train (or read back) the item's spec, falsify every run, and pass, fail or xfail the item."""
    from specguard.engine.check_agent import spec_agent
    from specguard.engine.falsify_run import falsify_agent, falsify_runs, start_space
    from specguard.falsify.assertion import falsify_verdict, verdict_lines
    from specguard.stats.verdicts import UNDECIDED_AS, RunVerdict, Word

    with one_line_errors(item):
        spec, _, agent = state.item_spec(item, expect)
        if agent is not None:  # an agent trained elsewhere: its one policy, in the env check_agent judges it in
            trained = spec.as_run(undecided=state.options.undecided)
            space = start_space(trained, check.starts)
            cache = state.options.cache_dir
            # loaded once: falsified, then its counterexample's episode replayed for the report's GIF
            loaded = spec_agent(trained, agent.agent, algorithm=agent.algorithm, trust=agent.trust)
            agent = dataclasses.replace(agent, spec=trained, agent=loaded)
            found = {
                agent.seed: falsify_agent(
                    trained,
                    loaded,
                    space,
                    **check.kwargs(),
                    database=None if cache is None else Path(cache) / "falsify",
                    progress=terminal_lines(item.config),
                    observation=agent.observation,
                    wrap=agent.wrap,
                    algorithm=agent.algorithm,
                    trust=agent.trust,
                )
            }
            result = None
        else:
            trained = state.scaled(spec)
            space = start_space(trained, check.starts)
            space.resolve(trained.initial_env.make())  # names and bounds checked before anything trains
            result = state.run(trained, item)
            found = falsify_runs(result, space, **check.kwargs(), progress=terminal_lines(item.config))
    verdicts = {seed: falsify_verdict(f, check.max_rate, trained.confidence) for seed, f in found.items()}
    for seed, falsification in sorted(found.items()):
        item.config.hook.pytest_goal_spec_falsification(
            item=item, spec=trained, seed=seed, falsification=falsification, verdict=verdicts[seed]
        )
    lines = verdict_lines(found, verdicts, check.max_rate)
    gifs: dict[int, Any] = {}
    if state.options.report_dir is not None:  # the counterexamples' episodes, as GIFs (an agent's own, acting)
        from specguard.report.gifs import counterexample_gifs

        gifs = counterexample_gifs(state.options.report_dir, group_of(item), result, found, space, agent=agent)
        lines += [
            f"seed {seed}: counterexample episode: {gif.path} ({gif.text})" if gif.path else f"seed {seed}: {gif.text}"
            for seed, gif in gifs.items()
        ]
    text = "\n".join(lines)
    item.user_properties.append(("specguard.falsify", text))
    runs = [
        {
            "group": group_of(item),
            "seed": seed,
            "verdict": verdicts[seed].value,
            "max_rate": check.max_rate,
            **f.to_dict(),
            "gif": gifs[seed].path.name if seed in gifs and gifs[seed].path is not None else None,
            "gif_text": gifs[seed].text if seed in gifs else "",
        }
        for seed, f in sorted(found.items())
    ]
    item.user_properties.append((COUNTEREXAMPLES, json.dumps(runs)))
    states = set(verdicts.values())
    undecided_as = UNDECIDED_AS[trained.undecided]
    if RunVerdict.MISSED in states or (RunVerdict.UNDECIDED in states and undecided_as is Word.FAILED):
        raise GoalMissed(f"falsified:\n{text}")
    if RunVerdict.UNDECIDED in states and undecided_as is Word.XFAILED:
        pytest.xfail(f"undecided:\n{text}")
    if RunVerdict.UNDECIDED in states:
        warnings.warn(f"undecided falsification passed by undecided='pass':\n{text}", stacklevel=1)
