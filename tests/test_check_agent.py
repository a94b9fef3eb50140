"""Judging an agent trained elsewhere (specguard/engine/check_agent.py): each verdict checked by replaying the agent on
the raw env with the same seeds, and computing the goal by hand."""

from __future__ import annotations

import json
import warnings

import gymnasium as gym
import numpy as np
import pytest

import specguard as sg
from specguard.engine import check_agent as check_agent_module
from specguard.engine.check_agent import check_agent
from specguard.error import AgentError, AgentMismatch
from specguard.evaluation.episodes import EVAL_SEED_BASE, EVAL_SEED_STRIDE
from specguard.stats.intervals import success_interval
from specguard.stats.verdicts import Word

sb3 = pytest.importorskip("stable_baselines3")

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
EDGE = 2.0  # the cart's edges, inside the env's own 2.4


def off_the_edges(s, a):  # type: ignore[no-untyped-def]
    return abs(s.x) > EDGE


# "Keep the pole up until the end", and the cart off the edges (a safety rate), as the CartPole case study's Avoids.
BALANCE = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance").annotate(
    sg.Constraint(off_the_edges, name="edges")
)
KEEP = sg.Spec(CARTPOLE, BALANCE, budget=sg.Budget(timesteps=1), expect={"balance": 0.5, "edges": 0.8})
# Where the pole falls: a reach goal whose last state decides, met by about half the starts of "push toward the lean".
RIGHT = sg.Spec(CARTPOLE, sg.Goal("right", theta=(0.1, None)), budget=sg.Budget(timesteps=1), expect=0.5)


def lean(obs):  # type: ignore[no-untyped-def]
    """Push toward the lean: the pole falls within a few dozen steps, to one side or the other."""
    return int(obs[2] > 0)


def replay(act, episodes: int, seed: int = 0) -> dict[str, int]:
    """The spec's counts, computed by hand: ``act`` on the raw ``gym.make("CartPole-v1")``, on the evaluation seeds."""
    env = gym.make("CartPole-v1")
    counts = {"balance": 0, "balance/upright": 0, "balance:edges": 0, "right": 0}
    for i in range(episodes):
        obs, _ = env.reset(seed=EVAL_SEED_BASE + seed * EVAL_SEED_STRIDE + i)
        states, terminated, truncated = [obs], False, False
        while not (terminated or truncated):
            obs, _, terminated, truncated, _ = env.step(act(obs))
            states.append(obs)
        upright = [-0.2 <= float(s[2]) <= 0.2 for s in states]
        counts["balance"] += all(upright) and not terminated  # held at every state, up to the horizon
        counts["balance/upright"] += upright[-1]
        counts["balance:edges"] += all(abs(float(s[0])) <= EDGE for s in states)
        counts["right"] += float(states[-1][2]) >= 0.1
    return counts


def assert_replayed(result: sg.SpecResult, expected: dict[str, int]) -> None:
    (run,) = result.runs
    assert {k: expected[k] for k in run.successes} == run.successes
    for path, goal in result.goals.items():
        assert (goal.successes, goal.episodes) == (expected[path], run.episodes)
        assert goal.interval == success_interval(expected[path], run.episodes, 0.95)


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path, monkeypatch):
    """The default cache (``.specguard/cache``, relative) in the test's own folder, not the checkout."""
    monkeypatch.chdir(tmp_path)


@pytest.fixture(scope="module")
def ppo_zip(tmp_path_factory):
    """A PPO agent trained by plain stable-baselines3, outside specguard, saved as a zip."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a small network: more threads only wait for each other on a busy machine
    try:
        model = sb3.PPO("MlpPolicy", "CartPole-v1", n_steps=256, batch_size=64, n_epochs=4, seed=0, device="cpu")
        model.learn(2048)
    finally:
        torch.set_num_threads(threads)
    path = tmp_path_factory.mktemp("agent") / "ppo-CartPole-v1.zip"
    model.save(path)
    return path


# -- verdicts, replayed ------------------------------------------------------------------------------------------


def test_push_toward_the_lean_is_judged_as_its_replay_on_the_raw_env():
    result = check_agent(RIGHT, lean)
    (run,) = result.runs
    assert run.episodes == 120, "about half the starts: undecided at 30 and 60 episodes, so doubled up to 120"
    expected = replay(lean, 120)
    assert 0.3 < expected["right"] / 120 < 0.7
    assert_replayed(result, expected)
    assert result.outcome("right") == "undecided" and result.word("right") is Word.UNDECIDED
    assert not result.passed  # an undecided goal counts as the spec's undecided says: fail


def test_an_agent_that_drops_the_pole_fails_keep_it_up_while_the_safety_rate_passes():
    result = check_agent(KEEP, lean)
    assert_replayed(result, replay(lean, 30))
    assert result.word("balance") is Word.FAILED and result.word("balance:edges") is Word.PASSED
    assert not result.passed and result.status() == "FAILED"


def test_a_random_policy_fails_keep_the_pole_up_until_the_end():
    rng = np.random.default_rng(0)
    result = check_agent(KEEP, lambda obs: int(rng.integers(2)))
    goal = result.goals["balance"]
    assert goal.successes == 0 and goal.episodes == 30 and result.word("balance") is Word.FAILED
    assert not result.passed


@pytest.mark.slow
def test_an_sb3_zip_trained_outside_specguard_is_judged_as_its_replay(ppo_zip):
    model = sb3.PPO.load(ppo_zip, device="cpu")
    result = check_agent(KEEP, ppo_zip, episodes=20, max_episodes=20)
    (run,) = result.runs
    assert_replayed(result, replay(lambda obs: int(model.predict(obs, deterministic=True)[0]), run.episodes))
    assert result.passed is all(result.counted(p) is Word.PASSED for p in result.goals)
    assert "agent 'PPO (ppo-CartPole-v1.zip)'" in result.notes[0]


def test_the_seed_picks_the_evaluation_episodes_as_a_runs_seed_does():
    result = check_agent(RIGHT, lean, episodes=20, max_episodes=20, seed=3)
    assert_replayed(result, replay(lean, 20, seed=3))
    assert replay(lean, 20, seed=3) != replay(lean, 20), "the seeds would not show"
    assert "env seeds 1300000..1300019" in result.notes[0]


# -- what the agent sees ------------------------------------------------------------------------------------------


def test_wrap_changes_what_the_agent_sees_and_not_what_the_goals_read():
    def negate(env):  # type: ignore[no-untyped-def]
        return gym.wrappers.TransformObservation(env, lambda obs: -obs, env.observation_space)

    result = check_agent(RIGHT, lambda obs: int(-obs[2] > 0), wrap=negate)
    assert_replayed(result, replay(lean, result.runs[0].episodes))
    assert "through negate" in result.notes[0]


def test_observation_spec_gives_the_constructed_envs_observation():
    seen = []

    def agent(obs):  # type: ignore[no-untyped-def]
        seen.append(np.shape(obs))
        return lean(obs)

    check_agent(KEEP, agent, episodes=2, max_episodes=2, observation="spec")
    shape = sg.make_env(CARTPOLE, BALANCE).observation_space.shape
    assert set(seen) == {shape} and shape == (6,)  # the features, then the held slot and the edges' counter


# -- refused before any episode ----------------------------------------------------------------------------------


@pytest.fixture
def no_episode(monkeypatch):
    """Fails the test at the first evaluation episode."""

    def evaluate(*args, **kwargs):  # type: ignore[no-untyped-def]
        raise AssertionError("an episode ran")

    monkeypatch.setattr(check_agent_module, "evaluate", evaluate)


def test_an_agent_of_another_env_is_refused_in_one_line_before_any_episode(tmp_path, no_episode):
    path = tmp_path / "pendulum.zip"
    sb3.PPO("MlpPolicy", "Pendulum-v1", seed=0, device="cpu").save(path)
    with pytest.raises(AgentMismatch) as e:
        check_agent(KEEP, path)
    line = e.value.message
    assert "\n" not in line and "(3,)" in line and "(4,)" in line, line


def test_an_action_of_the_wrong_type_is_an_agent_error():
    with pytest.raises(AgentError, match=r"gave the action 0\.5 \(a float64, not an integer\)"):
        check_agent(KEEP, lambda obs: 0.5, episodes=1, max_episodes=1)


def test_a_wrap_that_returns_no_env_is_refused(no_episode):
    with pytest.raises(AgentError, match=r"wrap=<lambda> returned None, not a gymnasium\.Env"):
        check_agent(KEEP, lean, wrap=lambda env: None)


def test_arguments_out_of_range_are_refused(no_episode):
    with pytest.raises(sg.error.InvalidSpec, match="expected max_episodes >= episodes, got 10 < 20"):
        check_agent(KEEP, lean, episodes=20, max_episodes=10)
    with pytest.raises(sg.error.InvalidSpec, match="observation"):
        check_agent(KEEP, lean, observation="pixels")


# -- the result ----------------------------------------------------------------------------------------------------


def test_a_result_round_trips_through_json():
    result = check_agent(KEEP, lean, episodes=10, max_episodes=10)
    data = json.loads(json.dumps(result.to_dict()))
    assert sg.SpecResult.from_dict(data) == result
    assert data["passed"] is False and data["goals"]["balance"]["word"] == "failed"


def test_a_goal_that_never_failed_shows_an_upper_bound_on_its_failure_rate():
    result = check_agent(KEEP, lean)
    assert result.goals["balance:edges"].successes == 30
    bound = 1 - 0.05 ** (1 / 30)  # about 3/30
    note = f"never failed in 30 episodes: balance:edges (safe); a failure rate of at most {bound:.1%} each"
    assert any(line.startswith(note) for line in result.notes), result.notes
    assert note in sg.table(result)
    assert not any("never failed" in line and "balance " in line for line in result.notes)  # the root failed


# -- the command line ------------------------------------------------------------------------------------------------

SPEC_FILE = """
import specguard as sg

cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
balance = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")
budget = sg.Budget(timesteps=1, eval_episodes=10)
specs = {
    "easy": sg.Spec(cartpole, balance, budget=budget, expect={"upright": 0.0}),
    "hard": sg.Spec(cartpole, balance, budget=budget, expect={"balance": 0.99}),
}
"""


@pytest.fixture
def spec_file(tmp_path):
    path = tmp_path / "cartpole_specs.py"
    path.write_text(SPEC_FILE)
    return path


@pytest.mark.slow
def test_check_exits_0_when_the_agent_passes_and_1_when_it_fails(spec_file, ppo_zip, tmp_path, capsys):
    from specguard.cli.main import main

    args = ["--agent", str(ppo_zip), "--episodes", "10", "--max-episodes", "10"]
    assert main(["check", f"{spec_file}::easy", *args]) == 0
    out = capsys.readouterr().out
    assert "== easy: passed" in out and "agent 'PPO (ppo-CartPole-v1.zip)': 10 evaluation episodes" in out
    report = tmp_path / "out.json"
    assert main(["check", f"{spec_file}::hard", *args, "--json", str(report)]) == 1
    assert "== hard: FAILED" in capsys.readouterr().out
    data = json.loads(report.read_text())["hard"]
    model = sb3.PPO.load(ppo_zip, device="cpu")
    kept = replay(lambda obs: int(model.predict(obs, deterministic=True)[0]), 10)["balance"]
    assert data["goals"]["balance"]["successes"] == kept and data["goals"]["balance"]["episodes"] == 10


def test_check_refuses_bad_input_in_one_line_with_exit_2(spec_file, tmp_path, capsys):
    from specguard.cli.main import main

    pendulum = tmp_path / "pendulum.zip"
    sb3.PPO("MlpPolicy", "Pendulum-v1", seed=0, device="cpu").save(pendulum)
    not_a_model = tmp_path / "notes.zip"
    not_a_model.write_bytes(b"not a zip")
    for agent, culprit in [(pendulum, "(3,)"), (not_a_model, "notes.zip"), (tmp_path / "absent.zip", "absent.zip")]:
        assert main(["check", f"{spec_file}::easy", "--agent", str(agent)]) == 2
        err = capsys.readouterr().err
        first = err.splitlines()[0]
        assert first.startswith("specguard: error: ") and culprit in first, err
        assert len(err.splitlines()) <= 2, err  # the line, and its hint
    assert main(["check", f"{spec_file}::easy", "--agent", str(pendulum), "--algorithm", "DQN"]) == 2
    assert "not by DQN" in capsys.readouterr().err


def test_an_agent_check_runs_check_agent_with_its_settings_and_refuses_bad_ones_when_made():
    check = sg.AgentCheck(KEEP, lean, episodes=10, max_episodes=10, seed=3)
    assert_replayed(check.run(), replay(lean, 10, seed=3))
    with pytest.raises(
        sg.error.InvalidSpec, match=r"^AgentCheck\('balance'\): expected max_episodes >= episodes, got 5 < 10"
    ):
        sg.AgentCheck(KEEP, lean, episodes=10, max_episodes=5)
    with pytest.raises(
        sg.error.InvalidSpec, match=r"^AgentCheck\('balance'\): expected wrap to be a function env -> env"
    ):
        sg.AgentCheck(KEEP, lean, wrap=3)
    with pytest.raises(sg.error.InvalidSpec, match=r"^AgentCheck\('balance'\): expected algorithm to be a name"):
        sg.AgentCheck(KEEP, lean, algorithm=3)
    with pytest.raises(sg.error.InvalidSpec, match=r"^AgentCheck: expected a Spec, got 'keep'"):
        sg.AgentCheck("keep", lean)


# -- the cache -------------------------------------------------------------------------------------------------------


@pytest.mark.filterwarnings("error")
def test_an_evaluation_is_cached_by_agent_spec_and_settings(tmp_path, monkeypatch):
    calls = []
    evaluate = check_agent_module._evaluate

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        calls.append(1)
        return evaluate(*args, **kwargs)

    monkeypatch.setattr(check_agent_module, "_evaluate", counted)
    first = check_agent(KEEP, lean, episodes=10, max_episodes=10, cache_dir=tmp_path)
    again = check_agent(KEEP, lean, episodes=10, max_episodes=10, cache_dir=tmp_path)
    assert len(calls) == 1 and first.cached == {0: False} and again.cached == {0: True}
    assert again.runs == first.runs and again.goals == first.goals and again.notes == first.notes
    # Another agent, spec or setting: evaluated once more, then found.
    variants = [
        (KEEP, lambda obs: int(obs[2] < 0), {}),
        (RIGHT, lean, {}),
        (KEEP, lean, {"observation": "spec"}),
        (KEEP, lean, {"episodes": 5}),
        (KEEP, lean, {"wrap": gym.wrappers.RecordEpisodeStatistics}),
    ]
    for spec, agent, settings in variants:
        settings = {"episodes": 10, "max_episodes": 10, **settings}
        assert check_agent(spec, agent, cache_dir=tmp_path, **settings).cached == {0: False}, settings
        assert check_agent(spec, agent, cache_dir=tmp_path, **settings).cached == {0: True}, settings
    assert len(calls) == 1 + len(variants)
    assert check_agent(KEEP, lean, episodes=10, max_episodes=10, cache_dir=None).cached == {0: False}
    assert len(calls) == 2 + len(variants)


def test_a_damaged_evaluation_entry_is_discarded_with_a_warning(tmp_path):
    first = check_agent(KEEP, lean, episodes=10, max_episodes=10, cache_dir=tmp_path)
    (entry,) = tmp_path.glob("*/*/result.json")
    entry.write_text(entry.read_text().replace('"episodes": 10', '"episodes": 11'))
    with pytest.warns(UserWarning, match="discarded entry"):
        again = check_agent(KEEP, lean, episodes=10, max_episodes=10, cache_dir=tmp_path)
    assert again.cached == {0: False} and again.runs == first.runs


def test_an_agent_trained_on_an_env_made_otherwise_is_judged_with_a_loud_note():
    from specguard.agents.agent import Agent

    agent = Agent(lean, name="zoo lean", env_kwargs={"sutton_barto_reward": True, "render_mode": None})
    with pytest.warns(sg.error.SpecWarning, match=r"made with \{'sutton_barto_reward': True\}"):
        result = check_agent(KEEP, agent, episodes=10, max_episodes=10, cache_dir=None)
    assert "sutton_barto_reward" in result.notes[0] and "sutton_barto_reward" in sg.table(result)
    same = sg.Spec(
        sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"), sutton_barto_reward=True),
        BALANCE,
        budget=sg.Budget(timesteps=1),
        expect=0.5,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error", sg.error.SpecWarning)
        result = check_agent(same, agent, episodes=10, max_episodes=10, cache_dir=None)
    assert not any("made with" in note for note in result.notes)


def test_check_takes_a_policy_defined_in_a_python_file(spec_file, tmp_path, capsys):
    from specguard.cli.main import main

    policies = tmp_path / "policies.py"
    policies.write_text("def lean(obs):\n    return int(obs[2] > 0)\n")
    assert main(["check", f"{spec_file}::hard", "--agent", f"{policies}::lean", "--max-episodes", "10"]) == 1
    out = capsys.readouterr().out
    assert "== hard: FAILED" in out and "agent 'lean': 10 evaluation episodes" in out
    assert main(["check", f"{spec_file}::hard", "--agent", f"{policies}::leen"]) == 2
    assert "defines nothing named 'leen'; its callables: lean" in capsys.readouterr().err


def test_the_table_of_an_agent_counts_no_runs():
    result = check_agent(KEEP, lean, episodes=10, max_episodes=10)
    assert result.agent == "lean"
    header = sg.table(result).splitlines()[0].split()
    assert header == ["goal", "success", "95%", "interval", "threshold", "verdict"]


def test_an_agent_trained_on_another_env_id_is_judged_with_a_loud_note():
    from specguard.agents.agent import Agent

    agent = Agent(lean, name="zoo lean", env_id="CartPole-v0")
    with pytest.warns(sg.error.SpecWarning, match=r"trained on env 'CartPole-v0'.*\('CartPole-v1'\)"):
        result = check_agent(KEEP, agent, episodes=10, max_episodes=10, cache_dir=None)
    assert "'CartPole-v0'" in result.notes[0] and "'CartPole-v0'" in sg.table(result)
    with warnings.catch_warnings():
        warnings.simplefilter("error", sg.error.SpecWarning)
        agent = Agent(lean, name="zoo lean", env_id="CartPole-v1")
        same = check_agent(KEEP, agent, episodes=10, max_episodes=10, cache_dir=None)
    assert not any("trained on env" in note for note in same.notes)


def test_an_agents_result_asked_for_its_model_points_to_the_agent():
    result = check_agent(KEEP, lean, episodes=10, max_episodes=10)
    for reach in (sg.load_model, sg.rollout):
        with pytest.raises(sg.SpecError, match="judged agent 'lean', trained elsewhere") as caught:
            reach(result, 0)
        assert "not cached" not in str(caught.value) and "falsify_agent" in str(caught.value)


def test_episodes_that_start_inside_a_reach_goal_are_met_at_the_start_only_where_the_goal_ends_them():
    tilted = sg.Spec(CARTPOLE, sg.Goal("tilted", theta=(0.02, None)), budget=sg.Budget(timesteps=1), expect=0.3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", sg.error.SpecWarning)  # some starts are inside the root goal: that is the point
        own = check_agent(tilted, lean, episodes=20, max_episodes=20, cache_dir=None)
        constructed = check_agent(tilted, lean, episodes=20, max_episodes=20, observation="spec", cache_dir=None)
    started = own.runs[0].started_in_goal
    assert started > 0  # the notes are tested
    (note,) = [n for n in own.notes if "started inside the root goal" in n]
    # the initial env's own episodes go on past the goal: the last state decides, as for every episode
    assert "before the policy acted" not in note and "judged at its last state" in note
    assert f"{started} of 20" in note and "judged at its last state" in sg.table(own)
    (note,) = [n for n in constructed.notes if "started inside the root goal" in n]
    assert note.endswith("met before the policy acted")


def test_check_on_a_pytest_agent_file_names_what_it_found_and_how_to_run_it(tmp_path, capsys):
    from specguard.cli.main import main

    tests = tmp_path / "test_agent_checks.py"
    tests.write_text(
        "import specguard as sg\n\n\n"
        "@sg.goal_spec(expect=0.5)\n"
        "def test_lean():\n"
        "    cartpole = sg.InitialEnv('CartPole-v1', features=('x', 'v', 'theta', 'omega'))\n"
        "    spec = sg.Spec(cartpole, sg.Goal('right', theta=(0.1, None)), budget=sg.Budget(timesteps=1))\n"
        "    return sg.AgentCheck(spec, lambda obs: int(obs[2] > 0))\n"
    )
    assert main(["check", str(tests), "--agent", "agent.zip"]) == 2
    err = capsys.readouterr().err
    assert "pytest goal-spec file" in err and "@goal_spec" in err and f"pytest --goal-specs {tests}" in err
