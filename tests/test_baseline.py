"""Stored baselines: saving, loading, old formats, corrupt files, and runs that are the baseline's own."""

from __future__ import annotations

import json
import re

import pytest

from specguard.gate.baseline import AgentEntry, Baseline, BaselineError, load_baseline, save_baseline

SETTINGS = {"observation": "env", "wrap": None, "seed_base": 1_000_000}


def entry(agent: str = "a1", outcomes: dict[str, list[int]] | None = None) -> AgentEntry:
    outcomes = outcomes or {"up": [1, 0, 1], "up:edges": [1, 1, 1]}
    return AgentEntry(agent, "lean", "spec1", SETTINGS, [1_000_000, 1_000_001, 1_000_002], outcomes)


def test_save_and_load_round_trip(tmp_path):
    path = tmp_path / "b" / "main.json"
    save_baseline(path, {"f.py::test::goal": [(3, 4), (4, 4)]}, {"f.py::test::goal": "abc"})
    baseline = load_baseline(path)
    assert baseline.runs == {"f.py::test::goal": [(3, 4), (4, 4)]}
    assert baseline.spec_changed("f.py::test::goal", "abd") and not baseline.spec_changed("f.py::test::goal", "abc")
    assert not baseline.spec_changed("other", "abc")


def test_seeds_round_trip_and_the_baselines_own_runs_are_recognised(tmp_path):
    path = tmp_path / "main.json"
    save_baseline(path, {"k": [(3, 4), (4, 4)]}, {"k": "abc"}, {"k": [0, 1]})
    baseline = load_baseline(path)
    assert baseline.seeds == {"k": [0, 1]}
    assert baseline.same_runs("k", "abc", [(0, 3, 4), (1, 4, 4)])
    assert baseline.same_runs("k", "abc", [(1, 4, 4)])
    assert not baseline.same_runs("k", "abd", [(0, 3, 4)])  # another spec
    assert not baseline.same_runs("k", "abc", [(0, 4, 4)])  # another result
    assert not baseline.same_runs("k", "abc", [(2, 3, 4)])  # a seed the baseline lacks
    assert not baseline.same_runs("k", None, [(0, 3, 4)]) and not baseline.same_runs("k", "abc", [])
    with pytest.raises(ValueError, match="'k': 1 seeds for 2 runs"):
        save_baseline(path, {"k": [(3, 4), (4, 4)]}, seeds={"k": [0]})


def test_a_format_2_baseline_has_no_seeds_and_no_runs_of_its_own(tmp_path):
    path = tmp_path / "old.json"
    path.write_text('{"format": 2, "goals": {"k": {"runs": [[3, 4]], "spec": "abc"}}}')
    baseline = load_baseline(path)
    assert baseline.seeds == {} and not baseline.same_runs("k", "abc", [(0, 3, 4)])


def test_format_1_baselines_still_load(tmp_path):
    path = tmp_path / "old.json"
    path.write_text('{"format": 1, "goals": {"k": [[3, 4]]}}')
    assert load_baseline(path) == Baseline({"k": [(3, 4)]}, {})


@pytest.mark.parametrize(
    "content",
    [
        "{oops",
        '{"format": 5, "goals": {}}',
        '{"format": 4, "goals": {}, "agents": {"t": {"agent": "a", "name": "n", "spec": "s"}}}',
        '{"format": 4, "goals": {}, "agents": []}',
        '{"format": 2, "goals": {"k": {"runs": [[1, 2]], "spec": 5}}}',
        '{"format": 1, "goals": {"k": [[5, 4]]}}',
        '{"format": 1, "goals": {"k": "x"}}',
        '{"format": 3, "goals": {"k": {"runs": [[1, 2]], "spec": null, "seeds": [0, 1]}}}',
        '{"format": 3, "goals": {"k": {"runs": [[1, 2], [1, 2]], "spec": null, "seeds": [0, 0]}}}',
        '{"format": 3, "goals": {"k": {"runs": [[1, 2]], "spec": null, "seeds": ["a"]}}}',
        '{"format": 3, "goals": {"k": {"runs": [[1, 2], [1, 2]], "spec": null, "seeds": [-1, 1]}}}',
        '{"format": 3, "goals": {"k": {"runs": [[1, 2], [1, 2]], "spec": null, "seeds": [true, 2]}}}',
        '{"format": 3, "goals": {"k": {"runs": [[1, 2]], "spec": null, "seeds": [1.5]}}}',
        "[" * 100_000,
    ],
)
def test_corrupt_baselines_name_the_file(tmp_path, content):
    path = tmp_path / "main.json"
    path.write_text(content)
    with pytest.raises(BaselineError, match=r"baseline '.*main.json' is corrupt"):
        load_baseline(path)


def test_negative_seeds_are_corrupt_as_a_seed_is_refused_everywhere(tmp_path):
    path = tmp_path / "main.json"
    path.write_text('{"format": 3, "goals": {"k": {"runs": [[1, 2], [1, 2]], "spec": null, "seeds": [-1, 1]}}}')
    with pytest.raises(BaselineError, match=r"bad seeds for 'k': expected 2 integers >= 0, one per run, got \[-1, 1\]"):
        load_baseline(path)


def test_a_corrupt_baseline_quotes_a_bounded_value(tmp_path):
    path = tmp_path / "main.json"
    path.write_text(
        '{"format": 3, "goals": {"k": {"runs": [[1, 2]], "spec": null, "seeds": [%s]}}}' % ("-1," * 50_000 + "1")
    )
    with pytest.raises(BaselineError, match=r"bad seeds for 'k'") as e:
        load_baseline(path)
    assert len(str(e.value)) < 600


def test_a_directory_in_place_of_the_baseline_is_named_as_one(tmp_path):
    (tmp_path / "main.json").mkdir()
    for act in (lambda: load_baseline(tmp_path / "main.json"), lambda: save_baseline(tmp_path / "main.json", {})):
        with pytest.raises(BaselineError, match=r"baseline '.*main.json' is a directory, not a baseline file"):
            act()


def test_missing_baseline(tmp_path):
    with pytest.raises(BaselineError, match="does not exist; store one first with --goal-specs-save"):
        load_baseline(tmp_path / "none.json")


def test_safety_rates_round_trip_and_old_baselines_without_them_are_noted(tmp_path):
    import specguard as sg
    from example_specs import pendulum
    from specguard.engine.judging import judge as _judge
    from specguard.engine.spec_result import SpecResult
    from specguard.pytest_plugin.judge import check_item
    from specguard.training.result import RunResult

    old = tmp_path / "old.json"  # saved before safety rates were measured: goals only
    old.write_text('{"format": 2, "goals": {"g::pendulum": {"runs": [[30, 30], [29, 30]], "spec": null}}}')
    new = tmp_path / "new.json"
    save_baseline(new, {"g::pendulum": [(30, 30)], "g::pendulum:fast": [(28, 30), (30, 30)]})
    assert load_baseline(new).runs["g::pendulum:fast"] == [(28, 30), (30, 30)]

    fast = sg.Constraint(lambda s, a: abs(s.omega) > 7.5, name="fast")
    tree = sg.All(*pendulum.trees["b"].children, name="pendulum").annotate(fast)
    spec = sg.Spec(pendulum.initial_env, tree, budget=sg.Budget(10), expect={"pendulum": 0.5, "fast": 0.5})
    counts = {"pendulum": 30, "pendulum/position": 30, "pendulum/stabilization": 30, "pendulum:fast": 29}
    runs = [
        RunResult(spec="pendulum", seed=i, timesteps=10, episodes=30, successes=counts, train_seconds=1.0)
        for i in (0, 1)
    ]
    result = SpecResult(spec="pendulum", runs=runs, goals=_judge(spec, runs, 0))
    paths = ["pendulum", "pendulum:fast"]
    goal, safety = check_item(result, spec, paths, "g", baseline=(load_baseline(old), "old"))
    assert goal.comparison.startswith("unchanged within chance: 98% -> 100%")
    assert safety.comparison == "not compared: baseline 'old' has no figures for it" and safety.outcome == "passed"
    _, safety = check_item(result, spec, paths, "g", baseline=(load_baseline(new), "new"))
    assert safety.comparison.startswith("unchanged within chance: 97% -> 97%")


def test_saving_a_subset_keeps_the_other_specs_and_says_what_it_replaced(tmp_path):
    path = tmp_path / "main.json"
    full = {"a.py::t::up": [(3, 4)], "a.py::t::up/x": [(2, 4)], "b.py::t::up": [(4, 4)], "c.py::t[1]::up": [(1, 4)]}
    first = save_baseline(path, full, {key: "v1" for key in full})
    assert first.added == ["a.py::t", "b.py::t", "c.py::t[1]"] and first.replaced == [] and first.kept == []
    # `-k b` later: only spec b ran; a and c stay as they were.
    second = save_baseline(path, {"b.py::t::up": [(1, 4)]}, {"b.py::t::up": "v1"})
    baseline = load_baseline(path)
    assert baseline.runs == {**full, "b.py::t::up": [(1, 4)]}
    assert second.replaced == ["b.py::t"] and second.added == [] and second.kept == ["a.py::t", "c.py::t[1]"]
    assert second.text() == "replaced 1 spec (b.py::t), added none, kept 2 others"


def test_a_goal_the_session_did_not_check_is_kept_if_its_spec_is_unchanged(tmp_path):
    path = tmp_path / "main.json"
    save_baseline(path, {"a::t::up": [(3, 4)], "a::t::up/x": [(2, 4)]}, {"a::t::up": "v1", "a::t::up/x": "v1"})
    save_baseline(path, {"a::t::up": [(4, 4)]}, {"a::t::up": "v1"})  # -k up: the same spec, one goal
    assert load_baseline(path).runs == {"a::t::up": [(4, 4)], "a::t::up/x": [(2, 4)]}
    saved = save_baseline(path, {"a::t::up": [(1, 4)]}, {"a::t::up": "v2"})  # the spec changed: its old goal goes
    assert load_baseline(path).runs == {"a::t::up": [(1, 4)]}
    assert saved.dropped == ["a::t::up/x"]
    assert saved.text() == (
        "replaced 1 spec (a::t), added none, kept none, dropped 1 goal (a::t::up/x) of an earlier version of its spec"
    )


def test_a_corrupt_baseline_is_not_overwritten_by_a_save(tmp_path):
    path = tmp_path / "main.json"
    path.write_text("{oops")
    with pytest.raises(BaselineError, match="is corrupt"):
        save_baseline(path, {"a::t::up": [(1, 4)]})
    assert path.read_text() == "{oops"


SAVER = """
import sys, time
from pathlib import Path
from specguard.gate.baseline import save_baseline

path, spec, ready = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3])
ready.write_text("")
while not (ready.parent / "go").exists():
    time.sleep(0.001)
for i in range(60):
    save_baseline(path, {f"{spec}::t::up": [(i % 5, 4)], f"{spec}::t::up/x": [(1, 4)]}, {f"{spec}::t::up": "v"})
"""


@pytest.mark.slow
def test_concurrent_saves_to_one_baseline_all_survive(tmp_path):
    import os
    import subprocess
    import sys
    import time

    path, sync = tmp_path / "baselines" / "main.json", tmp_path / "sync"
    sync.mkdir()
    specs = ["a.py", "b.py", "c.py"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    procs = [
        subprocess.Popen([sys.executable, "-c", SAVER, str(path), spec, str(sync / spec)], env=env) for spec in specs
    ]
    deadline = time.monotonic() + 60
    while len(list(sync.iterdir())) < len(specs) and time.monotonic() < deadline:  # a barrier: all ready, then go
        time.sleep(0.01)
    (sync / "go").write_text("")
    assert [p.wait(timeout=120) for p in procs] == [0] * len(specs)
    runs = load_baseline(path).runs
    assert sorted(runs) == sorted(f"{s}::t::{goal}" for s in specs for goal in ("up", "up/x"))
    assert all(runs[f"{s}::t::up"] == [(59 % 5, 4)] for s in specs)  # each process's last save


def test_agents_round_trip_beside_goals_and_count_in_the_family(tmp_path):
    path = tmp_path / "main.json"
    save_baseline(path, {"f.py::test_spec::goal": [(3, 4)]}, {"f.py::test_spec::goal": "abc"})
    saved = save_baseline(path, {}, agents={"f.py::test_agent": entry()})
    assert saved.text() == "replaced none, added 1 spec (f.py::test_agent), kept 1 other"
    baseline = load_baseline(path)
    assert baseline.runs == {"f.py::test_spec::goal": [(3, 4)]}  # the trained spec's entry kept beside the agent's
    assert baseline.agents == {"f.py::test_agent": entry()}
    assert baseline.family == 3  # one goal, and the agent's two keys
    episode = json.loads(path.read_text())["agents"]["f.py::test_agent"]["episodes"][1]
    assert episode == {"seed": 1_000_001, "outcomes": {"up": 0, "up:edges": 1}}


def test_a_test_saved_as_an_agent_replaces_its_trained_goals_and_the_other_way_round(tmp_path):
    path = tmp_path / "main.json"
    save_baseline(path, {"f.py::test::goal": [(3, 4)], "f.py::other::goal": [(1, 4)]})
    assert save_baseline(path, {}, agents={"f.py::test": entry()}).replaced == ["f.py::test"]
    baseline = load_baseline(path)
    assert list(baseline.runs) == ["f.py::other::goal"] and list(baseline.agents) == ["f.py::test"]
    save_baseline(path, {"f.py::test::goal": [(2, 4)]})
    baseline = load_baseline(path)
    assert baseline.agents == {} and baseline.runs["f.py::test::goal"] == [(2, 4)]
    save_baseline(path, {}, agents={"f.py::a": entry("a1")})
    save_baseline(path, {}, agents={"f.py::a": entry("a2")})  # the agent saved last replaces the one before
    assert load_baseline(path).agents["f.py::a"].agent == "a2"
    save_baseline(path, {}, agents={"f.py::b": entry("b1")})  # another test's agent is kept beside it
    assert {group: e.agent for group, e in load_baseline(path).agents.items()} == {"f.py::a": "a2", "f.py::b": "b1"}


def test_a_format_3_baseline_has_no_agents(tmp_path):
    path = tmp_path / "old.json"
    path.write_text('{"format": 3, "goals": {"k": {"runs": [[3, 4]], "spec": "abc", "seeds": [0]}}}')
    assert load_baseline(path).agents == {} and load_baseline(path).family == 1


@pytest.mark.parametrize(
    ("episodes", "message"),
    [
        ([], "bad episodes for agent 't'"),
        ([{"seed": 1, "outcomes": {"up": 2}}], "bad outcomes for agent 't'"),
        ([{"seed": 1, "outcomes": {"up": True}}], "bad outcomes for agent 't'"),
        ([{"seed": 1, "outcomes": {"up": 1}}, {"seed": 2, "outcomes": {"down": 1}}], "bad outcomes for agent 't'"),
        ([{"seed": 1, "outcomes": {"up": 1}}, {"seed": 1, "outcomes": {"up": 1}}], "bad seeds for 't'"),
        ([{"seed": -1, "outcomes": {"up": 1}}], "expected 1 integers >= 0, one per episode"),
    ],
)
def test_corrupt_agent_entries_name_the_test(tmp_path, episodes, message):
    path = tmp_path / "main.json"
    agent = {"agent": "a", "name": "n", "spec": "s", "settings": SETTINGS, "episodes": episodes}
    path.write_text(json.dumps({"format": 4, "goals": {}, "agents": {"t": agent}}))
    with pytest.raises(BaselineError, match=re.escape(message)):
        load_baseline(path)
