"""One judge: the hints a result carries are the pytest item's, and every table prints them."""

from __future__ import annotations

import pytest

import specguard as sg
from example_specs import pendulum
from specguard.engine.judging import judged
from specguard.engine.spec_result import SpecResult
from specguard.pytest_plugin.judge import judge_goal
from specguard.report.table import table
from specguard.training.result import RunResult


def runs_of(spec: sg.Spec, per_seed: list[dict[str, int]], episodes: int = 30) -> list[RunResult]:
    """One run per seed, each goal (and safety key) met in the given number of its episodes (all, where unsaid)."""
    keys = [p for p, _ in spec.tree.walk()] + list(spec.thresholds)
    return [
        RunResult(
            spec=spec.label,
            seed=seed,
            timesteps=10,
            episodes=episodes,
            successes={k: met.get(k, episodes) for k in dict.fromkeys(keys)},
            train_seconds=1.0,
        )
        for seed, met in enumerate(per_seed)
    ]


def spec(tree: str = "b", **expect: float) -> sg.Spec:
    return sg.Spec(
        pendulum.initial_env,
        pendulum.trees[tree],
        budget=sg.Budget(timesteps=10, min_seeds=2),
        expect=expect or {"pendulum": 0.8},
    )


CASES = {
    "a sparse goal never reached": (spec(), [{"pendulum": 0}, {}]),
    "subgoals that compete": (
        spec(**{"pendulum": 0.8}),
        [{"pendulum": 3, "pendulum/position": 3, "pendulum/stabilization": 30}] * 2,
    ),
    "runs left undecided": (spec(pendulum=0.5), [{"pendulum": 15}, {"pendulum": 15}]),
}


@pytest.mark.parametrize("case", CASES)
def test_a_results_hints_are_the_pytest_items_hints(case):
    s, per_seed = CASES[case]
    result = judged(s, runs_of(s, per_seed))
    failed = [p for p in result.goals if str(result.outcome(p)) != "passed"]
    assert failed and set(result.hints) == set(failed)
    for path in failed:
        assert result.hints[path] == judge_goal(result, s, path, "g").hint


def test_an_agents_result_carries_the_agents_hint_not_trainings():
    s = spec()
    result = judged(s, runs_of(s, [{"pendulum": 0}])[:1], agent="zoo")
    assert result.hints == {"pendulum": "agent 'zoo' never ended an evaluation episode in 'pendulum' (30 episodes)"}
    assert result.hints["pendulum"] == judge_goal(result, s, "pendulum", "g").hint


def test_a_passed_goal_has_no_hint_and_its_table_none():
    s = spec()
    result = judged(s, runs_of(s, [{}, {}]))
    assert result.hints == {}
    assert "hint" not in table(result)


def test_the_table_ends_with_each_hint_as_the_pytest_item_says_it():
    s, per_seed = CASES["a sparse goal never reached"]
    result = judged(s, runs_of(s, per_seed))
    lines = table(result).splitlines()
    assert lines[-1] == f"hint for 'pendulum': {result.hints['pendulum']}"
    assert f"  hint: {result.hints['pendulum']}" in judge_goal(result, s, "pendulum", "g").message().splitlines()


def test_hints_survive_json_and_a_result_stored_before_them_loads_without():
    s, per_seed = CASES["subgoals that compete"]
    result = judged(s, runs_of(s, per_seed))
    data = result.to_dict()
    assert SpecResult.from_dict(data).hints == result.hints != {}
    older = {k: v for k, v in data.items() if k != "hints"}
    assert SpecResult.from_dict(older).hints == {}
    with pytest.raises(ValueError, match="hints"):
        SpecResult.from_dict({**data, "hints": {"pendulum": 3}})
