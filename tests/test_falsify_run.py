"""Falsifying an agent trained elsewhere (specguard/engine/falsify_run.py, ``falsify_agent`` and ``specguard falsify
--agent``): each counterexample replayed on the raw ``gym.make("CartPole-v1")``, its start set as the start setter
sets it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import specguard as sg
from specguard.cli.main import main
from specguard.error import AgentMismatch
from specguard.falsify.search import EpisodeRunner

sb3 = pytest.importorskip("stable_baselines3")

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
BALANCE = sg.Spec(
    CARTPOLE, sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance"), budget=sg.Budget(timesteps=1)
)
NARROW = sg.StartSpace({"theta": (-0.05, 0.05)})


def lean(obs):  # type: ignore[no-untyped-def]
    """Push toward the lean: the pole falls within a few dozen steps."""
    return int(obs[2] > 0)


def steady(obs):  # type: ignore[no-untyped-def]
    """Push toward the lean and its speed: keeps the pole up for 500 steps from near-upright starts."""
    return int(obs[2] + 0.5 * obs[3] > 0)


def raw_episode(act, start: dict[str, float]) -> tuple[list[np.ndarray], bool]:  # type: ignore[no-untyped-def]
    """``act`` on the raw CartPole from ``start`` (the state set after a seeded reset, as the start setter does):
    the episode's states and whether the env terminated it."""
    env = gym.make("CartPole-v1")
    env.reset(seed=0)
    obs = np.array([start[k] for k in ("x", "v", "theta", "omega")], dtype=np.float64)
    env.unwrapped.state = obs.copy()  # type: ignore[attr-defined]
    states, terminated, truncated = [obs], False, False
    while not (terminated or truncated):
        obs, _, terminated, truncated, _ = env.step(act(obs))
        states.append(obs)
    return states, bool(terminated)


def kept_upright(states: list[np.ndarray], terminated: bool) -> bool:
    """The spec's goal by hand: upright at every state, up to the horizon (a terminated episode did not keep it)."""
    return all(-0.2 <= float(s[2]) <= 0.2 for s in states) and not terminated


def test_a_failing_start_of_push_toward_the_lean_is_a_fall_on_the_raw_cartpole():
    found = sg.falsify_agent(BALANCE, lean, sg.StartSpace({"theta": (-0.15, 0.15)}), examples=8, uniform=0)
    assert found.found and found.counterexample is not None
    assert found.counterexample.judgement.missed == ("balance",) and found.counterexample.judgement.score < 0
    states, terminated = raw_episode(lean, found.counterexample.start)
    assert not kept_upright(states, terminated)
    assert len(states) - 1 == found.counterexample.steps  # the same episode, step for step
    assert abs(float(states[-1][2])) > 0.2  # the pole fell


def test_an_episode_the_initial_env_terminates_with_the_pole_up_misses_keep_it_up_until_the_end():
    # Always push right from near the right edge: the cart leaves the track before the pole leaves the goal's box.
    found = sg.falsify_agent(
        BALANCE, lambda obs: 1, sg.StartSpace({"x": (2.36, 2.39), "v": (0.5, 1.0)}), examples=4, uniform=0
    )
    c = found.counterexample
    assert c is not None and c.ended == "terminated" and abs(c.last["theta"]) < 0.2
    assert c.judgement.missed == ("balance",) and c.judgement.score < 0  # the end is the horizon
    states, terminated = raw_episode(lambda obs: 1, c.start)
    assert terminated and all(abs(float(s[2])) <= 0.2 for s in states) and not kept_upright(states, terminated)


def test_a_policy_that_never_fails_on_a_narrow_space_gives_nothing_and_the_failure_rates_bound():
    found = sg.falsify_agent(BALANCE, steady, NARROW, examples=6, uniform=10)
    assert not found.found and found.uniform_failures == 0 and found.uniform_episodes == 10
    assert found.interval[0] == 0.0 and found.interval[1] == pytest.approx(1 - 0.025**0.1)  # exact, two-sided 95%
    bound = 1 - 0.05**0.1  # one-sided at 95%: the most the failure rate can be after 10 draws without one
    assert found.rate_text == f"at most {bound:.1%} at 95% (none in 10 uniform draws; one-sided exact binomial bound)"
    assert f"failure rate over the start space: at most {bound:.1%} at 95%" in found.report()
    for start in (
        {"x": 0.0, "v": 0.0, "theta": 0.05, "omega": 0.0},
        {"x": 0.0, "v": 0.0, "theta": -0.05, "omega": 0.0},
    ):
        assert kept_upright(*raw_episode(steady, start))


def test_the_database_replays_the_agents_counterexample_and_no_other_agents(tmp_path):
    space = sg.StartSpace({"theta": (-0.15, 0.15)})
    first = sg.falsify_agent(BALANCE, lean, space, examples=8, uniform=0, database=tmp_path)
    again = sg.falsify_agent(BALANCE, lean, space, examples=8, uniform=0, database=tmp_path)
    assert first.found and not first.replayed and again.replayed and again.guided == 1
    assert again.counterexample is not None and first.counterexample is not None
    assert again.counterexample.start == first.counterexample.start and again.key == first.key != ""
    other = sg.falsify_agent(BALANCE, lambda obs: int(obs[2] > 0.0), space, examples=8, uniform=0, database=tmp_path)
    seen_as_spec = sg.falsify_agent(BALANCE, lean, space, examples=8, uniform=0, database=tmp_path, observation="spec")
    assert not other.replayed and other.key != first.key  # another agent's code: its own key
    assert not seen_as_spec.replayed and seen_as_spec.key != first.key


def test_an_agent_of_another_env_is_refused_before_any_episode(monkeypatch):
    def no_episode(self, points):  # type: ignore[no-untyped-def]
        raise AssertionError("an episode ran")

    monkeypatch.setattr(EpisodeRunner, "run", no_episode)
    pendulum = sb3.PPO("MlpPolicy", "Pendulum-v1", seed=0, device="cpu")
    with pytest.raises(AgentMismatch, match=r"reads observations of Box.*\(3,\).*the env gives"):
        sg.falsify_agent(BALANCE, pendulum, NARROW, examples=4, uniform=0)


SPEC_FILE = """
import specguard as sg

cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
balance = sg.Spec(cartpole, sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance"),
                  budget=sg.Budget(timesteps=1), expect=0.9)
track = sg.Always(sg.Goal("on_track", x=(-5.0, 5.0)), name="track", until="termination")  # a fall ends it well
on_track = sg.Spec(cartpole, track, budget=sg.Budget(timesteps=1), expect=0.9)
"""


@pytest.mark.slow  # saving an SB3 model asks platform.processor(), a process (uname -p) in a fresh worker
def test_the_command_line_falsifies_an_agent_exit_0_1_and_2(tmp_path, capsys):
    specs = tmp_path / "cartpole_specs.py"
    specs.write_text(SPEC_FILE)
    agent = tmp_path / "ppo-CartPole-v1.zip"
    sb3.PPO("MlpPolicy", "CartPole-v1", seed=0, device="cpu").save(agent)  # untrained: the pole falls
    args = ["--agent", str(agent), "--examples", "4", "--uniform", "4", "--cache-dir", str(tmp_path / "cache")]
    args += ["--starts", "theta=-0.05:0.05", "--quiet"]
    assert main(["falsify", f"{specs}::balance", *args]) == 1
    out = capsys.readouterr().out
    assert "== balance agent" in out and "COUNTEREXAMPLE" in out and "missed: balance" in out
    assert any((tmp_path / "cache" / "falsify").iterdir())  # stored for the next call
    assert main(["falsify", f"{specs}::on_track", *args]) == 0
    assert "none found" in capsys.readouterr().out
    pendulum = tmp_path / "pendulum.zip"
    sb3.PPO("MlpPolicy", "Pendulum-v1", seed=0, device="cpu").save(pendulum)
    for bad, culprit in [(["--agent", str(pendulum)], "(3,)"), (["--algorithm", "PPO"], "--algorithm")]:
        assert main(["falsify", f"{specs}::balance", "--examples", "4", "--uniform", "0", *bad]) == 2
        err = capsys.readouterr().err
        assert err.startswith("specguard: error: ") and culprit in err.splitlines()[0], err
        assert len(err.splitlines()) <= 2, err  # the line, and its hint


# -- what the report says replays: the last state, the printed start, a stateful agent afresh -----------------------

FALLEN_RIGHT = sg.Spec(CARTPOLE, sg.Goal("fallen_right", theta=(0.2, 1.0)), budget=sg.Budget(timesteps=1))
"""A plain goal, no own state: judged in the episode's last state alone."""


def test_a_goal_without_own_state_is_judged_in_the_last_state_a_raw_replay_reaches():
    # Pushed toward its lean, the pole falls to the side it leans to: a start leaning left misses the goal at its
    # last state. The falsifier once judged the baseline env's start instead (its evaluator never moved from it):
    # every start missed, and the reported last state was the start.
    found = sg.falsify_agent(FALLEN_RIGHT, lean, sg.StartSpace({"theta": (-0.15, 0.15)}), examples=8, uniform=0)
    c = found.counterexample
    assert c is not None and c.judgement.missed == ("fallen_right",) and c.start["theta"] < 0
    states, _ = raw_episode(lean, c.start)
    assert c.last == {k: float(v) for k, v in zip(("x", "v", "theta", "omega"), states[-1], strict=True)}
    assert c.steps == len(states) - 1 and c.last["theta"] < -0.2


def printed_start(report: str) -> dict[str, float]:
    """The counterexample's start as the report prints it, read back."""
    line = next(line for line in report.splitlines() if line.startswith("counterexample ("))
    return {k: float(v) for k, v in (part.split("=") for part in line.partition("): ")[2].split(", "))}


def test_the_printed_counterexample_replays_the_very_episode():
    # A spin shrunk to the boundary of the failing spins (omega = 0.4015672...): steady drives the cart off the
    # track after 345 steps. Printed to 6 digits, its replay ended elsewhere (v = 0.577 against 0.187).
    found = sg.falsify_agent(BALANCE, steady, sg.StartSpace({"omega": (-2.0, 2.0)}), examples=16, uniform=0)
    c = found.counterexample
    assert c is not None and c.steps > 100
    start = printed_start(found.report())
    states, _ = raw_episode(steady, start)
    assert {k: float(v) for k, v in zip(("x", "v", "theta", "omega"), states[-1], strict=True)} == c.last
    assert len(states) - 1 == c.steps and start == c.start  # exact: each float's shortest text, not 6 digits


def test_the_header_of_a_falsified_run_says_a_counterexample_was_found():
    from specguard.falsify.assertion import falsify_verdict, verdict_lines
    from specguard.report.session_report import counterexample_lines

    found = sg.falsify_agent(BALANCE, lean, NARROW, examples=4, uniform=0)
    clean = sg.falsify_agent(BALANCE, steady, NARROW, examples=2, uniform=0)
    lines = verdict_lines(
        {0: found, 1: clean}, {0: falsify_verdict(found, None), 1: falsify_verdict(clean, None)}, None
    )
    assert lines[0] == "seed 0: missed (a counterexample found)"
    assert "seed 1: met (no counterexample found)" in lines
    run = {"group": "t.py::test_up", "seed": 0, "verdict": "missed", "max_rate": None, **found.to_dict()}
    assert counterexample_lines([run])[0].startswith(
        "- **`t.py::test_up`**, seed 0: missed (a counterexample found): `"
    )


class Tiring:
    """Steady for its first 600 actions, then pushing toward the lean: it fails only once it has acted enough,
    whatever the start (a policy with state across episodes)."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, obs):  # type: ignore[no-untyped-def]
        self.calls += 1
        return steady(obs) if self.calls <= 600 else lean(obs)


def test_a_counterexample_a_fresh_copy_of_a_stateful_agent_does_not_fail_is_reported_not_reproduced():
    tiring = Tiring()
    with pytest.warns(UserWarning, match="NOT REPRODUCED: a fresh copy of the agent"):
        found = sg.falsify_agent(BALANCE, tiring, NARROW, examples=4, uniform=0)
    assert found.found and tiring.calls > 600  # the tired agent fails
    assert "NOT REPRODUCED" in found.report() and found.notes[-1] in found.report()
    fresh = found.counterexample.start
    assert kept_upright(*raw_episode(Tiring(), fresh))  # and a fresh one does not
    again = sg.falsify_agent(BALANCE, lean, NARROW, examples=4, uniform=0)  # a stateless agent's reproduces: no note
    assert again.found and again.notes == []
