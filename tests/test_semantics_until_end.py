"""Goals that hold until the end (``sg.Always``): docs/semantics.md, "Goals that hold until the end".

A goal that must hold at every state of the episode ends nothing on entry, is
judged at the last state, pays ``-1`` once when left, and reads "until" beside
a reach goal under ``All``. Both evaluators, the start check and the verdict
table follow the one rule, :func:`specguard.extend.until_end`.
"""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_preflight_met_at_start import TINY, Drift, share_inside

import specguard as sg
from specguard import strategies as sgst
from specguard.construction import cap
from specguard.construction.cap import CAPPED, EPISODE_CAP
from specguard.construction.env import make_baseline_env
from specguard.construction.preflight import START_SAMPLES
from specguard.construction.reference import ReferenceEvaluator
from specguard.engine.judging import judged
from specguard.error import GoalMetAtStart, SpecWarning, UnreachableGoal
from specguard.extend import until_end
from specguard.testing import ReplayEnv
from specguard.training.train import train_run

EVALUATORS = ("flat", "reference")


def _limited(start_low: float):  # Drift ends its episodes at 20 steps itself; a TimeLimit declares it
    return lambda: gym.wrappers.TimeLimit(Drift(start_low), 20)


always_inside, sometimes_inside, never_inside = _limited(0.6), _limited(0.0), _limited(-1.0)
INSIDE = sg.Goal("inside", x=(-1.0, 1.0))
BALANCE = sg.Always(INSIDE, name="balance")


def play(tree: sg.Node, xs: list[float], evaluator: str, *, features: tuple[str, ...] = ("x",)) -> list[tuple]:
    """(reward, terminated, truncated, goals) of every step of a replayed episode, until it ends."""
    env = sg.SpecEnv(ReplayEnv([[x] for x in xs]), tree=tree, features=features, evaluator=evaluator)
    _, info = env.reset(seed=0)
    out = [(None, False, False, info["goals"])]
    while True:
        _, reward, terminated, truncated, info = env.step(0)
        out.append((reward, terminated, truncated, info["goals"]))
        if terminated or truncated:
            return out


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_a_root_goal_that_holds_until_the_end_ends_nothing_and_is_judged_at_the_last_state(evaluator):
    steps = play(BALANCE, [0.0, 0.5, 0.2, -0.9], evaluator)
    assert [s[1] for s in steps] == [False, False, False, False]  # it held all along: the replay's end ends it
    assert steps[-1][2] is True  # truncated by the initial env, as a TimeLimit would
    assert [s[0] for s in steps[1:]] == [0.0, 0.0, 0.0]  # nothing is paid for keeping it
    assert steps[-1][3] == {"balance": True, "balance/inside": True}  # success: it holds at the last state


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_leaving_it_pays_minus_one_once_and_coming_back_is_not_success(evaluator):
    steps = play(BALANCE, [0.0, 2.0, 0.0, 0.5], evaluator)
    assert [s[0] for s in steps[1:]] == [-1.0, 0.0, 0.0]  # re-entering the child's goal pays nothing back
    assert [s[1] for s in steps] == [False] * 4
    assert steps[-1][3] == {"balance": False, "balance/inside": True}  # in the child's goal, but it was left


class Falls(ReplayEnv):
    """A replay the initial env terminates at its last observation (a pendulum's fall)."""

    def step(self, action: int) -> tuple:
        obs, reward, _, truncated, info = super().step(action)
        return obs, reward, truncated, False, info


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_an_episode_the_initial_env_ends_outside_it_fails_it(evaluator):
    env = sg.SpecEnv(Falls([[0.0], [3.0]]), tree=BALANCE, features=("x",), evaluator=evaluator)
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step(0)
    assert (reward, terminated, truncated) == (-1.0, True, False)
    assert info["goals"]["balance"] is False


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_under_all_beside_a_reach_goal_it_reads_until(evaluator):
    tree = sg.All(BALANCE, sg.Goal("far", x=(0.8, None)), name="carry")
    assert not until_end(tree)
    held = play(tree, [0.0, 0.5, 0.9, 0.0], evaluator)
    assert [s[1] for s in held] == [False, False, True]  # reaching far with inside held ends the episode
    assert held[-1][3]["carry"] is True
    left = play(tree, [0.0, 2.0, 0.9, 0.9], evaluator)
    assert [s[1] for s in left] == [False, False, False, False]  # inside was left: far alone reaches nothing
    assert left[-1][3]["carry"] is False


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_an_all_of_goals_that_hold_until_the_end_holds_until_the_end(evaluator):
    tree = sg.All(BALANCE, sg.Always(sg.Goal("right", x=(0.0, None)), name="keep"), name="both")
    assert until_end(tree)
    steps = play(tree, [0.5, 0.5, 0.5], evaluator)
    assert [s[1] for s in steps] == [False, False, False]
    assert steps[-1][3]["both"] is True


def test_a_constraint_below_it_still_ends_the_episode():
    tree = sg.Always(INSIDE.annotate(sg.Constraint(lambda s, a: s.x > 0.4, name="hot")), name="balance")
    steps = play(tree, [0.0, 0.5, 0.0, 0.0], "flat")
    assert [s[1] for s in steps] == [False, False, True]  # (0.5, a) violates: the counter ends it


@given(
    sgst.goals(("a", "b")),
    sgst.trajectories(("a", "b"), min_size=1, max_size=10),
)
def test_it_holds_exactly_when_every_state_so_far_is_in_its_child(leaf, trajectory):
    tree = sg.Always(leaf, name="kept")
    flat = sg.compile_tree(tree, ("a", "b")).evaluator()
    ref = ReferenceEvaluator(tree, ("a", "b"))
    member = sg.compile_tree(leaf, ("a", "b")).members
    inside = [bool(m[0]) for m in member(np.asarray(trajectory, dtype=np.float64))]
    assert flat.reset(trajectory[0])[0] == ref.reset(trajectory[0])[0] == inside[0]
    for t, f in enumerate(trajectory[1:], start=1):
        held = all(inside[: t + 1])
        assert flat.step(0, f)[2][0] == ref.step(0, f)[2][0] == held


@given(
    sgst.goals(("a", "b")),
    sgst.trajectories(("a", "b"), min_size=2, max_size=10),
    st.sampled_from(["horizon", "termination"]),
)
def test_an_episode_the_env_terminates_keeps_it_only_until_termination(leaf, trajectory, until):
    tree = sg.Always(leaf, name="kept", until=until)
    flat = sg.compile_tree(tree, ("a", "b")).evaluator()
    ref = ReferenceEvaluator(tree, ("a", "b"))
    member = sg.compile_tree(leaf, ("a", "b")).members
    inside = [bool(m[0]) for m in member(np.asarray(trajectory, dtype=np.float64))]
    flat.reset(trajectory[0]), ref.reset(trajectory[0])
    for f in trajectory[1:-1]:
        flat.step(0, f), ref.step(0, f)
    fell = [ev.step(0, trajectory[-1], True, True) for ev in (flat, ref)]  # the base env terminated here
    kept = all(inside) and until == "termination"
    assert fell[0][2][0] == fell[1][2][0] == kept
    assert fell[0][0] == fell[1][0] == float(kept) - float(all(inside[:-1]))  # -1 once, on leaving


@given(st.data(), sgst.trajectories(("a", "b", "c"), min_size=1, max_size=10))
def test_refining_its_child_preserves_the_root_goal(data, trajectory):
    features = ("a", "b", "c")
    leaf = data.draw(sgst.goals(features, name="leaf"))
    refined = data.draw(sgst.refinements(leaf))
    ours = sg.Always(leaf, name="kept")
    theirs = sg.Always(refined, name="kept")
    flat = lambda tree: sg.compile_tree(tree, features).evaluator()  # noqa: E731
    reference = lambda tree: ReferenceEvaluator(tree, features)  # noqa: E731
    for make in (flat, reference):
        a, b = make(ours), make(theirs)
        assert a.reset(trajectory[0])[0] == b.reset(trajectory[0])[0]
        for f in trajectory[1:]:
            assert a.step(0, f)[2][0] == b.step(0, f)[2][0]


@given(sgst.trajectories(("a", "b"), min_size=2, max_size=12), sgst.goals(("a", "b")))
def test_its_rewards_telescope_to_membership_at_the_last_state_minus_the_first(trajectory, leaf):
    tree = sg.Always(leaf, name="kept")
    ev = sg.compile_tree(tree, ("a", "b")).evaluator()
    first = ev.reset(trajectory[0])[0]
    total, last = 0.0, first
    for f in trajectory[1:]:
        reward, _, goals, _ = ev.step(0, f)
        total, last = total + reward, goals[0]
    assert total == float(last) - float(first)


# -- before training: the mirror of the reach goal's start check --------------------------------------------


def test_one_held_at_every_start_is_what_it_is_for_and_is_not_refused():
    initial = sg.InitialEnv(always_inside, features=("x",))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sg.make_env(initial, sg.Always(sg.Goal("up", x=(0.5, None)), name="stay")).close()
    with pytest.raises(GoalMetAtStart):  # the same goal as a reach goal is met before the agent acts
        sg.make_env(initial, sg.Goal("up", x=(0.5, None)))


def test_one_held_at_no_start_is_refused_naming_the_goal():
    initial = sg.InitialEnv(never_inside, features=("x",))
    with pytest.raises(UnreachableGoal) as e:
        sg.make_env(initial, sg.Always(sg.Goal("up", x=(1.5, None)), name="stay"))
    assert e.value.where == "stay"
    assert f"holds at none of {START_SAMPLES} sampled starts" in str(e.value)
    assert "Always" in e.value.hint


def test_one_held_at_some_starts_warns_with_the_share_that_fails_before_acting():
    initial = sg.InitialEnv(sometimes_inside, features=("x",))
    outside = START_SAMPLES - share_inside(sometimes_inside, 0.5)
    assert 0 < outside < START_SAMPLES
    with pytest.warns(SpecWarning) as caught:
        sg.make_env(initial, sg.Always(sg.Goal("up", x=(0.5, None)), name="stay")).close()
    (warning,) = [w for w in caught if issubclass(w.category, SpecWarning)]
    assert f"stay must hold until the end and fails at {outside} of {START_SAMPLES} sampled starts" in str(
        warning.message
    )


def test_the_reach_hint_names_always():
    initial = sg.InitialEnv(always_inside, features=("x",))
    with pytest.raises(GoalMetAtStart) as e:
        sg.make_env(initial, sg.Goal("up", x=(0.5, None)))
    assert "sg.Always" in e.value.hint


@pytest.mark.slow
def test_a_spec_trains_on_it_and_its_table_counts_the_episodes_that_started_outside():
    initial = sg.InitialEnv(sometimes_inside, features=("x",))
    tree = sg.Always(sg.Goal("up", x=(0.5, None)), name="stay")
    budget = sg.Budget(timesteps=64, min_seeds=1, max_seeds=1, eval_episodes=6, checkpoints=1)
    spec = sg.Spec(initial, tree, budget=budget, expect=0.1, trainer=sg.SB3(hyperparameters=TINY))
    with pytest.warns(SpecWarning):
        result = sg.run_spec(spec, workers=1, cache_dir=None, progress=None)
    (run,) = result.runs
    outside = run.episodes - run.started_in_goal
    assert outside > 0  # seed 0's evaluation starts include some outside the goal: the line is tested
    assert f"{outside} of {run.episodes} evaluation episodes started outside the root goal 'stay'" in sg.table(result)
    assert "started inside" not in sg.table(result)
    assert run.successes["stay"] <= run.started_in_goal  # an episode that started outside cannot succeed


class Endless(Drift):
    """Drift that never ends its episodes, and declares no limit (an unwrapped env)."""

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, _, _, info = super().step(action)
        return obs, reward, False, False, info


def test_an_env_that_never_ends_its_episodes_runs_under_the_stated_cap():
    tree = sg.Always(sg.Goal("up", x=(-2.0, None)), name="stay")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing to warn about: every episode ends
        env = sg.make_env(sg.InitialEnv(lambda: Endless(0.6), features=("x",)), tree)
    env.reset(seed=0)
    steps, truncated, info = 0, False, {}
    while not truncated:
        _, _, terminated, truncated, info = env.step(0)
        steps += 1
        assert not terminated
    assert steps == EPISODE_CAP and info[CAPPED] == EPISODE_CAP
    assert info["goals"]["stay"] is True  # truncated at the cap: its horizon


def test_an_env_that_ends_its_own_episodes_is_not_warned_about_nor_cut():
    self_ending = sg.InitialEnv(lambda: Drift(0.6), features=("x",))  # ends at 20 steps, declares no limit
    tree = sg.Always(sg.Goal("up", x=(-2.0, None)), name="stay")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = sg.make_env(self_ending, tree)
    env.reset(seed=0)
    for t in range(1, 21):
        _, _, _, truncated, info = env.step(0)
        assert truncated is (t == 20)
    assert CAPPED not in info
    limited = sg.make_env(sg.InitialEnv(always_inside, features=("x",)), tree)  # its own TimeLimit, kept
    assert limited.get_wrapper_attr("_max_episode_steps") == 20


# -- the end is the horizon: an episode the env terminates has not kept it -----------------------------


class Hopper(Drift):
    """Stays tall (``x`` high) and falls over at step 5: the env terminates on a condition the goal omits."""

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        obs, reward, _, truncated, info = super().step(1)  # up, whatever the agent does
        return obs, reward, self.t >= 5, truncated, info


STAY_TALL = sg.Goal("tall", x=(0.5, None))


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_an_episode_the_env_terminates_inside_it_has_not_kept_it(evaluator):
    env = sg.SpecEnv(Falls([[0.0], [0.5], [0.2]]), tree=BALANCE, features=("x",), evaluator=evaluator)
    env.reset(seed=0)
    assert env.step(0)[1:3] == (0.0, False)
    _, reward, terminated, truncated, info = env.step(0)  # inside, but the env ended the episode: a fall
    assert (reward, terminated, truncated) == (-1.0, True, False)
    assert info["goals"] == {"balance": False, "balance/inside": True}
    assert info["reward_terms"]["balance"] == -1.0


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_until_termination_takes_the_envs_termination_as_its_end(evaluator):
    kept = sg.Always(INSIDE, name="balance", until="termination")
    env = sg.SpecEnv(Falls([[0.0], [0.5], [0.2]]), tree=kept, features=("x",), evaluator=evaluator)
    env.reset(seed=0)
    env.step(0)
    _, reward, terminated, _, info = env.step(0)
    assert (reward, terminated, info["goals"]["balance"]) == (0.0, True, True)


@pytest.mark.parametrize("evaluator", EVALUATORS)
def test_beside_a_reach_goal_the_envs_termination_where_it_is_reached_is_success(evaluator):
    tree = sg.All(BALANCE, sg.Goal("far", x=(0.8, None)), name="carry")  # MiniGrid's goal square ends it
    env = sg.SpecEnv(Falls([[0.0], [0.5], [0.9]]), tree=tree, features=("x",), evaluator=evaluator)
    env.reset(seed=0)
    env.step(0)
    _, _, terminated, _, info = env.step(0)
    assert terminated and info["goals"]["carry"] is True


def test_the_baseline_env_reports_the_fall_too():
    initial = sg.InitialEnv(lambda: gym.wrappers.TimeLimit(Hopper(0.6), 20), features=("x",))
    tree = sg.Always(STAY_TALL, name="stay")
    for env in (make_baseline_env(initial, tree), sg.make_env(initial, tree)):
        env.reset(seed=0)
        for _ in range(5):
            _, _, terminated, truncated, info = env.step(0)
        assert terminated and not truncated
        assert info["goals"] == {"stay": False, "stay/tall": True}  # tall, and fallen: not kept


@pytest.mark.slow
@pytest.mark.parametrize("until", ["horizon", "termination"])
def test_a_run_counts_the_episodes_the_env_ended_before_the_horizon(until):
    initial = sg.InitialEnv(lambda: gym.wrappers.TimeLimit(Hopper(0.6), 20), features=("x",))
    tree = sg.Always(STAY_TALL, name="stay", until=until)
    budget = sg.Budget(timesteps=64, min_seeds=1, max_seeds=1, eval_episodes=6, checkpoints=1)
    spec = sg.Spec(initial, tree, budget=budget, expect=0.5, trainer=sg.SB3(hyperparameters=TINY))
    result = sg.run_spec(spec, workers=1, cache_dir=None, progress=None)
    (run,) = result.runs
    assert run.terminated == run.episodes  # every episode fell at step 5 of 20
    assert run.successes["stay"] == (0 if until == "horizon" else run.episodes)  # Hopper passed 30/30 before
    assert result.passed is (until == "termination")
    line = f"{run.episodes} of {run.episodes} evaluation episodes were ended by termination before their horizon"
    assert line in sg.table(result)
    good_end = "until='termination' takes that as a good end: they were judged on their last state"
    assert (good_end in sg.table(result)) is (until == "termination")
    assert result.to_dict()["runs"][0]["terminated"] == run.episodes


class DeclaresALimit(Endless):
    """Endless, with a ``_max_episode_steps`` of its own that it never enforces (no ``TimeLimit``)."""

    _max_episode_steps = 50


def test_an_env_that_declares_a_limit_it_never_enforces_runs_under_the_cap():
    tree = sg.Always(sg.Goal("up", x=(-2.0, None)), name="stay")
    env = sg.make_env(sg.InitialEnv(lambda: DeclaresALimit(0.6), features=("x",)), tree)
    env.reset(seed=0)
    steps, truncated, info = 0, False, {}
    while not truncated and steps <= EPISODE_CAP:
        _, _, terminated, truncated, info = env.step(0)
        steps += 1
        assert not terminated
    assert steps == EPISODE_CAP and info[CAPPED] == EPISODE_CAP


@pytest.mark.slow
def test_a_run_on_an_env_that_never_ends_finishes_and_says_where_it_cut(monkeypatch):
    monkeypatch.setattr(cap, "EPISODE_CAP", 50)  # in this process: train_run, not run_spec's workers
    initial = sg.InitialEnv(lambda: Endless(0.6), features=("x",))
    tree = sg.Always(sg.Goal("up", x=(-2.0, None)), name="stay")
    budget = sg.Budget(timesteps=64, min_seeds=1, max_seeds=1, eval_episodes=6, checkpoints=1)
    spec = sg.Spec(initial, tree, budget=budget, expect=0.5, trainer=sg.SB3(hyperparameters=TINY))
    run, _ = train_run(spec, 0)
    assert run.capped == run.episodes and run.terminated == 0
    table = sg.table(judged(spec, [run]))
    assert f"{run.episodes} of {run.episodes} evaluation episodes were cut at 50 steps" in table
