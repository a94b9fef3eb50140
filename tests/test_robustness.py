"""The falsifier's robustness score: by default each key's margin in the episode's last state (main's); opted in
(``score="episode"``), over the whole episode, STL's running minimum for the keys that hold throughout, its sign
always the verdict's; a bad ``score`` refused in one line; and the guided search's episodes accounted to the
samplers that drew them."""

from __future__ import annotations

import functools
import re
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest
from specguard_plugins import AnyOf, Avoid

import specguard as sg
from specguard.cli.main import main
from specguard.engine import falsify_run
from specguard.falsify import robustness
from specguard.falsify.robustness import SCORES
from specguard.falsify.search import EpisodeRunner, falsify
from specguard.starts.space import StartSpace

DIP = (0.15, 0.05, 0.12, 0.0)
"""The pole's angle after each step, over its start's: it dips, recovers, leans again, and ends upright."""


class Dip(gym.Env):
    """An angle that follows ``start + DIP[t]`` whatever the action: four steps an episode, then truncated."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.start, self.theta, self.t = 0.0, 0.0, 0
        return np.array([self.theta], np.float32), {}

    def step(self, action):
        self.theta = self.start + DIP[self.t]
        self.t += 1
        return np.array([self.theta], np.float32), 0.0, False, self.t >= len(DIP), {}


def set_dip(env, values):
    env.unwrapped.start = env.unwrapped.theta = values["theta"]
    return np.array([values["theta"]], np.float32)


DIPPING = sg.InitialEnv(Dip, features=("theta",))
SPACE = StartSpace({"theta": (-0.1, 0.1)}, set_state=set_dip)
UPRIGHT = sg.Goal("upright", theta=(-0.2, 0.2))
EDGE = sg.Goal("edge", theta=(0.18, None))


def still(obs):
    return np.zeros(len(obs))


def run(tree, keys, starts, **kwargs):
    runner = EpisodeRunner(functools.partial(sg.make_env, DIPPING, tree), still, SPACE, keys, **kwargs)
    return runner.run(np.asarray(starts, dtype=np.float64)[:, None])


def test_by_default_a_key_is_scored_in_the_last_state_and_no_margin_is_taken_before_it(monkeypatch):
    # The score as it always was: the Always by where the episode ended (0, a margin of 0.2), a kept Avoid by a flat 1.
    tree = sg.Always(UPRIGHT, name="balance").annotate(Avoid(EDGE, name="edge"))
    [kept] = run(tree, ["balance", "balance:edge"], [0.0])
    assert kept.judgement.margins == pytest.approx({"balance": 0.2, "balance:edge": 1.0}, abs=1e-6)
    # The cost: one walk of the tree per episode, at its end (score="episode" walks it after every step too).
    walks = []
    visit = robustness._visit
    monkeypatch.setattr(robustness, "_visit", lambda node, path, *a: walks.append(path) or visit(node, path, *a))
    run(tree, ["balance", "balance:edge"], [0.0, 0.05])
    assert walks.count("balance") == 2
    run(tree, ["balance", "balance:edge"], [0.0], score="episode")
    assert walks.count("balance") == 2 + 1 + len(DIP)


def test_an_always_goal_is_scored_by_its_deepest_dip_not_by_its_last_state():
    # From 0: the angle reaches 0.15 after one step and ends at 0. Its margin is 0.05 (of half the range, 1), not 0.2.
    [kept] = run(sg.Always(UPRIGHT, name="balance"), ["balance"], [0.0], score="episode")
    assert not kept.failed and kept.last == {"theta": 0.0}
    assert kept.judgement.margins["balance"] == pytest.approx(0.05, abs=1e-6)
    # From 0.06 it dips past 0.2 and comes back: missed, and negative although the last state is upright.
    [dipped] = run(sg.Always(UPRIGHT, name="balance"), ["balance"], [0.06], score="episode")
    assert dipped.judgement.missed == ("balance",) and dipped.judgement.score < 0


def test_a_kept_avoid_is_scored_by_its_closest_approach_to_its_region():
    tree = sg.Always(UPRIGHT, name="balance").annotate(Avoid(EDGE, name="edge"))
    # closest at 0.15: 0.03 from the edge (ends 0.18 away)
    [kept] = run(tree, ["balance", "balance:edge"], [0.0], score="episode")
    assert not kept.failed and kept.judgement.margins["balance:edge"] == pytest.approx(0.03, abs=1e-6)
    [entered] = run(tree, ["balance", "balance:edge"], [0.04], score="episode")  # 0.19 after one step: one violation
    assert entered.judgement.missed == ("balance:edge",) and entered.judgement.margins["balance:edge"] == -1.0


def test_a_constraint_violated_mid_episode_within_its_budget_is_missed_and_negative():
    tree = sg.Always(UPRIGHT, name="balance").annotate(sg.Constraint(lambda s, a: s.theta > 0.12, budget=3))
    # 0.15 on the first step: within budget
    [episode] = run(tree, ["balance", "balance:constraint"], [0.0], score="episode")
    assert episode.steps == len(DIP)  # the budget kept it running
    assert episode.judgement.missed == ("balance:constraint",) and episode.judgement.margins["balance:constraint"] < 0


@pytest.mark.parametrize("reach", [False, True])
@pytest.mark.parametrize("score", SCORES)
def test_every_keys_margin_has_the_sign_of_its_verdict(reach, score):
    # Every key kind over starts where the minimum is mid-episode and the last state is fine: an Always, its box
    # child, an Avoid, a Constraint within budget, and a union of an Always and a goal met only at the end (its margin
    # there is its last state's: the Always's dip says nothing of a union met by the other child).
    balance = sg.Always(UPRIGHT, name="balance").annotate(
        Avoid(EDGE, budget=4, name="edge"), sg.Constraint(lambda s, a: s.theta > 0.14, budget=4)
    )
    calm = sg.Goal("calm", theta=(None, 0.07))  # from 0.05 to 0.07 met at the end alone; above, the union is missed
    tree = AnyOf(balance, calm, name="either")
    keys = ["either", "either/balance", "either/balance/upright", "either/balance:edge", "either/balance:constraint"]
    if reach:  # a reach root: ends where reached, scored by how early
        tree, keys = sg.Goal("far", theta=(0.11, None)), ["far"]
    outcomes = run(tree, keys, np.linspace(-0.1, 0.1, 81), score=score)
    seen = set()
    for o in outcomes:
        for key, margin in o.judgement.margins.items():
            assert (margin < 0) == (key in o.judgement.missed), (o.start, key, margin, o.judgement.missed)
            seen.add((key, margin < 0))
    judged_over_time = [k for k in keys if k != "either/balance/upright"]  # the box child (at the end) is always met
    assert seen >= {(k, sign) for k in judged_over_time for sign in (False, True)}  # each both met and missed


def test_a_union_met_at_the_end_keeps_its_last_states_margin_where_its_always_child_dipped():
    tree = AnyOf(sg.Always(UPRIGHT, name="balance"), sg.Goal("calm", theta=(None, 0.1)), name="either")
    # 0.22 after one step: neither child; ends calm at 0.07
    [o] = run(tree, ["either", "either/balance"], [0.07], score="episode")
    assert o.judgement.missed == ("either/balance",)
    assert o.judgement.margins["either"] == pytest.approx(0.03, abs=1e-6)  # calm's margin at the end


LINE_SPACE = StartSpace({"theta": (-0.1, 0.1)}, set_state=set_dip)


def lean_right(obs):
    return np.zeros(len(obs), dtype=int)


@pytest.mark.parametrize("seed", range(6))
def test_the_search_s_episodes_by_sampler_sum_to_its_episodes_to_the_first_failure(seed):
    # Always(upright) fails from starts above 0.09: 5% of the space, past the exploration in most searches.
    balance = sg.Always(sg.Goal("upright", theta=(-0.2, 0.24)), name="balance")
    runner = EpisodeRunner(functools.partial(sg.make_env, DIPPING, balance), lean_right, SPACE, ["balance"])
    found = falsify(runner, examples=400, uniform=0, seed=seed, shrink=False)
    assert found.found and found.found_by in found.drawn_by
    assert sum(found.drawn_by.values()) == found.episodes_to_first
    assert found.drawn_by.get("middle", 0) <= 1 and set(found.drawn_by) <= {"uniform", "middle", "trend", "local"}
    assert found.to_dict()["found_by"] == found.found_by


def test_a_search_that_finds_nothing_accounts_every_episode_to_a_sampler():
    # Upright from every start: no failure, so every one of the 120 episodes is counted, most beyond the exploration.
    wide = sg.Always(sg.Goal("upright", theta=(-1.0, 1.0)), name="balance")
    runner = EpisodeRunner(functools.partial(sg.make_env, DIPPING, wide), lean_right, SPACE, ["balance"])
    found = falsify(runner, examples=120, uniform=0, seed=0)
    assert not found.found and found.found_by is None
    assert sum(found.drawn_by.values()) == found.guided == 120
    assert found.drawn_by["middle"] == 1 and found.drawn_by["uniform"] >= 60  # the uniform floor: half of each round
    assert found.drawn_by.get("trend", 0) + found.drawn_by.get("local", 0) > 0


SPEC_FILE = """
import specguard as sg

cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
balance = sg.Spec(cartpole, sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance"),
                  budget=sg.Budget(timesteps=1))


def lean(obs):
    return int(obs[2] > 0)
"""
BALANCE = sg.Spec(
    sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega")),
    sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance"),
    budget=sg.Budget(timesteps=1),
)


def lean_rows(obs):
    return (obs[:, 2] > 0).astype(int)


class Ran(Exception):
    """Raised by the first episode of a patched runner: the score it was made with is ``args[0]``."""


@pytest.mark.parametrize("score", [None, *SCORES])
def test_the_score_travels_from_falsify_agent_falsify_runs_falsify_and_the_cli_to_the_runner(
    score, tmp_path, monkeypatch, capsys
):
    def first_episode(self, points):  # type: ignore[no-untyped-def]
        raise Ran(self.score)

    monkeypatch.setattr(EpisodeRunner, "run", first_episode)
    given = {} if score is None else {"score": score}
    expected = score or "last"
    space = StartSpace({"theta": (-0.05, 0.05)})
    with pytest.raises(Ran) as ran:
        sg.falsify_agent(BALANCE, lambda obs: int(obs[2] > 0), space, examples=1, uniform=0, **given)
    assert ran.value.args == (expected,)
    assert sg.Falsify(**given).kwargs()["score"] == expected  # the [falsify] item's arguments of falsify_runs
    # falsify_runs, through falsify_run, on a trained run (its loading and policy stood in for)
    monkeypatch.setattr(falsify_run, "load_run", lambda result, seed: (BALANCE, None, None))
    monkeypatch.setattr(falsify_run, "batch_policy", lambda model, normalizer, deterministic: lean_rows)
    trained = SimpleNamespace(runs=[SimpleNamespace(seed=0, looks=[])], spec_key=None, cache_dir=str(tmp_path))
    with pytest.raises(Ran) as ran:
        sg.falsify_runs(trained, space, examples=1, uniform=0, **given)
    assert ran.value.args == (expected,)
    specs = tmp_path / "cartpole_specs.py"
    specs.write_text(SPEC_FILE)
    argv = ["falsify", f"{specs}::balance", "--agent", f"{specs}::lean", "--examples", "1", "--uniform", "0"]
    with pytest.raises(Ran) as ran:
        main([*argv, "--cache-dir", str(tmp_path / "c"), "--quiet", *(["--score", score] if score else [])])
    assert ran.value.args == (expected,)


@pytest.mark.parametrize("bad", ["best", "Last", None, 1])
def test_a_score_that_is_not_one_of_the_choices_is_refused_in_one_line_naming_it(bad, tmp_path, capsys):
    line = rf"expected score to be one of last, episode, got {re.escape(repr(bad))}\n"
    with pytest.raises(sg.error.InvalidSpec, match=rf"^EpisodeRunner: {line}"):
        run(sg.Always(UPRIGHT, name="balance"), ["balance"], [0.0], score=bad)
    with pytest.raises(sg.error.InvalidSpec, match=rf"^falsify_agent\('balance'\): {line}"):
        sg.falsify_agent(BALANCE, lambda obs: 0, StartSpace({"theta": (-0.05, 0.05)}), score=bad)
    with pytest.raises(sg.error.InvalidSpec, match=rf"^Falsify: {line}"):
        sg.Falsify(score=bad)
    if isinstance(bad, str):
        with pytest.raises(SystemExit) as exit_info:
            main(["falsify", "specs.py", "--cache-dir", str(tmp_path / "c"), "--score", bad])
        err = capsys.readouterr().err
        assert exit_info.value.code == 2 and "Traceback" not in err
        assert err.splitlines()[-1] == (
            f"specguard falsify: error: argument --score: invalid choice: {bad!r} (choose from 'last', 'episode')"
        )
