"""Gating a retrained agent against the one it replaces (specguard/gate/agent_gate.py, specguard/stats/paired.py):
paired episodes, the exact one-sided McNemar test, its level, and ``specguard check --agent NEW --against OLD``."""

from __future__ import annotations

import json

import numpy as np
import pytest

import specguard as sg
from specguard.engine import check_agent as check_agent_module
from specguard.gate.agent_gate import compare_agents
from specguard.stats.family import holm
from specguard.stats.paired import discordant, drop_p_value, drop_upper_bound, repeated_p_value
from specguard.stats.sequential import DEFAULT_ALPHA, GateState

# CartPole cut at 24 steps: "push toward the lean" keeps the pole up that long from nearly every start, a random
# policy from about a quarter of them.
SHORT = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"), max_episode_steps=24)
KEEP = sg.Spec(
    SHORT,
    sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="keep"),
    budget=sg.Budget(timesteps=1, eval_episodes=20, max_eval_episodes=80),
    expect=0.1,
)

SPEC_FILE = """
import specguard as sg
SHORT = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"), max_episode_steps=24)
keep = sg.Spec(SHORT, sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="keep"),
               budget=sg.Budget(timesteps=1, eval_episodes=20, max_eval_episodes=80), expect=0.1)
"""


def lean(obs):  # type: ignore[no-untyped-def]
    return int(obs[2] > 0)


def random_policy(seed: int = 0):  # type: ignore[no-untyped-def]
    rng = np.random.default_rng(seed)
    return lambda obs: int(rng.integers(2))


def test_a_random_agent_against_push_toward_the_lean_dropped():
    comparison = compare_agents(KEEP, random_policy(), lean)
    keep = comparison.keys["keep"]
    assert keep.state is GateState.DROPPED and not comparison.passed
    assert keep.lost > keep.gained and keep.old > keep.new
    assert keep.p_value <= DEFAULT_ALPHA  # flagged at the family's level


def test_the_same_agent_against_itself_is_never_dropped_and_fine_with_enough_episodes():
    few = compare_agents(KEEP, lean, lean, episodes=5, max_episodes=5)
    assert few.passed and few.keys["keep"].state is GateState.OPEN  # 5 episodes bound the drop only to 58%
    enough = compare_agents(KEEP, lean, lean)
    assert enough.passed and all(k.state is GateState.FINE for k in enough.keys.values())
    assert all(k.lost == k.gained == 0 and k.p_value == 1.0 for k in enough.keys.values())
    # the better agent as new: not a drop
    better = compare_agents(KEEP, lean, random_policy())
    assert better.passed


def test_the_false_alarm_rate_with_equal_success_is_at_most_the_level():
    rng = np.random.default_rng(0)
    level, stages, trials = DEFAULT_ALPHA, [20, 40, 80], 2000
    for p in (0.3, 0.5, 0.8):
        alarms = 0
        for _ in range(trials):
            old, new = rng.random(80) < p, rng.random(80) < p  # independent pairs, the same success probability
            looks = []
            for n in stages:
                looks.append(drop_p_value(*discordant(old[:n].tolist(), new[:n].tolist())))
                if repeated_p_value(looks, len(stages)) <= level:
                    alarms += 1
                    break
        assert alarms / trials <= level, (p, alarms / trials)


def test_the_statistic_by_hand():
    assert drop_p_value(5, 0) == pytest.approx(0.5**5)
    assert drop_p_value(3, 1) == pytest.approx(5 / 16)  # P(X >= 3), X ~ Bin(4, 1/2)
    assert repeated_p_value([0.02, 0.01], 3) == pytest.approx(0.03)
    assert drop_upper_bound(0, 0, 20) == pytest.approx(1 - 0.0125 ** (1 / 20))
    assert holm({"a": repeated_p_value([0.02], 3)}, 0.05) == {"a": None}


@pytest.fixture
def agents_by_name(monkeypatch):
    """``--agent lean`` and ``--agent random`` as the two policies, loaded as a zip's path would be."""
    policies = {"lean": lean, "random": random_policy()}
    real = check_agent_module.load_agent
    monkeypatch.setattr(check_agent_module, "load_agent", lambda agent, **kw: real(policies.get(agent, agent), **kw))


def test_check_against_exits_1_on_a_drop_0_without_and_2_on_bad_input(tmp_path, capsys, agents_by_name):
    from specguard.cli.main import main

    spec_file = tmp_path / "short_specs.py"
    spec_file.write_text(SPEC_FILE)
    report = tmp_path / "out.json"
    assert main(["check", f"{spec_file}::keep", "--agent", "random", "--against", "lean", "--json", str(report)]) == 1
    out = capsys.readouterr().out
    assert "-- against lean: DROPPED" in out and "dropped" in out and "Holm's step-down procedure" in out
    data = json.loads(report.read_text())["keep"]
    assert data["passed"] is True  # its thresholds met: the drop alone fails it
    assert data["comparison"]["keys"]["keep"]["state"] == "dropped" and not data["comparison"]["passed"]
    assert main(["check", f"{spec_file}::keep", "--agent", "lean", "--against", "lean"]) == 0
    assert "-- against lean: passed" in capsys.readouterr().out
    assert main(["check", f"{spec_file}::keep", "--agent", "lean", "--against", str(tmp_path / "absent.zip")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("specguard: error: ") and "absent.zip" in err.splitlines()[0]


# Random against random, both seeded alike, so nothing drops: the new agent's success (12 of 40) stays undecided
# against 0.3 after its last stage.
NEAR = sg.Spec(
    SHORT,
    sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="keep"),
    budget=sg.Budget(timesteps=1, eval_episodes=20, max_eval_episodes=40),
    expect=0.3,
)


@pytest.fixture
def twins(monkeypatch):
    """``--agent random`` and ``--agent twin``: two random policies seeded alike (they play alike on paired
    episodes)."""
    policies = {"random": random_policy(), "twin": random_policy()}
    real = check_agent_module.load_agent
    monkeypatch.setattr(check_agent_module, "load_agent", lambda agent, **kw: real(policies.get(agent, agent), **kw))


@pytest.mark.parametrize("undecided", ["fail", "pass"])
def test_one_pass_fail_for_a_comparison_at_the_python_object_and_the_cli(tmp_path, capsys, twins, undecided):
    from specguard.cli.main import main

    spec = NEAR.as_run(undecided=undecided)
    comparison = compare_agents(spec, random_policy(), random_policy())
    assert comparison.result.outcome("keep").value == "undecided"
    assert all(k.state is not GateState.DROPPED for k in comparison.keys.values())
    assert comparison.passed is comparison.result.as_expected is (undecided == "pass")
    assert comparison.to_dict()["passed"] is comparison.passed
    spec_file = tmp_path / "near_specs.py"
    spec_file.write_text(SPEC_FILE.replace("max_eval_episodes=80), expect=0.1", "max_eval_episodes=40), expect=0.3"))
    argv = ["check", f"{spec_file}::keep", "--agent", "random", "--against", "twin", "--undecided", undecided]
    assert main(argv) == (0 if comparison.passed else 1)
    assert "-- against twin: passed" in capsys.readouterr().out  # nothing dropped: the check's verdict decides


def test_only_asserted_goals_are_compared_as_against_a_saved_baseline():
    from specguard.gate.saved_agent import saved_entry

    comparison = compare_agents(KEEP, lean, lean, max_episodes=20)
    assert list(comparison.keys) == list(KEEP.thresholds) == ["keep"]  # not the unasserted leaf keep/upright
    entry = saved_entry(sg.AgentCheck(KEEP, lean, max_episodes=20), [])
    assert list(entry.outcomes) == list(comparison.keys)  # what --goal-specs-save stores, --goal-specs-compare gates
    from specguard.gate.agent_gate import compared_keys

    assert compared_keys(KEEP) == list(comparison.keys)


@pytest.mark.parametrize(
    ("options", "culprit"),
    [
        ({"margin": "x"}, "expected margin to be a number in (0, 1] (rate points), got 'x'"),
        ({"margin": None}, "expected margin to be a number in (0, 1] (rate points), got None"),
        ({"margin": True}, "expected margin to be a number in (0, 1] (rate points), got True"),
        ({"margin": 0.0}, "expected margin to be a number in (0, 1] (rate points), got 0.0"),
        ({"level": "x"}, "expected level to be a number in (0, 1)"),
        ({"seed": "x"}, "expected seed to be an integer >= 0"),
    ],
)
def test_bad_arguments_of_compare_agents_are_one_line_naming_them(options, culprit):
    with pytest.raises(sg.error.InvalidSpec) as info:
        compare_agents(KEEP, lean, lean, **options)
    first = str(info.value).splitlines()[0]
    assert first.startswith("compare_agents('keep'): ") and culprit in first
