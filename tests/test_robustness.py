"""The falsifier's score over the whole episode: STL's running minimum for the keys that hold throughout, its sign
always the verdict's, and the guided search's episodes accounted to the samplers that drew them."""

from __future__ import annotations

import functools

import gymnasium as gym
import numpy as np
import pytest
from specguard_plugins import AnyOf, Avoid

import specguard as sg
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


def run(tree, keys, starts):
    runner = EpisodeRunner(functools.partial(sg.make_env, DIPPING, tree), lambda obs: np.zeros(len(obs)), SPACE, keys)
    return runner.run(np.asarray(starts, dtype=np.float64)[:, None])


def test_an_always_goal_is_scored_by_its_deepest_dip_not_by_its_last_state():
    # From 0: the angle reaches 0.15 after one step and ends at 0. Its margin is 0.05 (of half the range, 1), not 0.2.
    [kept] = run(sg.Always(UPRIGHT, name="balance"), ["balance"], [0.0])
    assert not kept.failed and kept.last == {"theta": 0.0}
    assert kept.judgement.margins["balance"] == pytest.approx(0.05, abs=1e-6)
    # From 0.06 it dips past 0.2 and comes back: missed, and negative although the last state is upright.
    [dipped] = run(sg.Always(UPRIGHT, name="balance"), ["balance"], [0.06])
    assert dipped.judgement.missed == ("balance",) and dipped.judgement.score < 0


def test_a_kept_avoid_is_scored_by_its_closest_approach_to_its_region():
    tree = sg.Always(UPRIGHT, name="balance").annotate(Avoid(EDGE, name="edge"))
    [kept] = run(tree, ["balance", "balance:edge"], [0.0])  # closest at 0.15: 0.03 from the edge (ends 0.18 away)
    assert not kept.failed and kept.judgement.margins["balance:edge"] == pytest.approx(0.03, abs=1e-6)
    [entered] = run(tree, ["balance", "balance:edge"], [0.04])  # 0.19 after one step: one violation
    assert entered.judgement.missed == ("balance:edge",) and entered.judgement.margins["balance:edge"] == -1.0


def test_a_constraint_violated_mid_episode_within_its_budget_is_missed_and_negative():
    tree = sg.Always(UPRIGHT, name="balance").annotate(sg.Constraint(lambda s, a: s.theta > 0.12, budget=3))
    [episode] = run(tree, ["balance", "balance:constraint"], [0.0])  # 0.15 on the first step: within budget
    assert episode.steps == len(DIP)  # the budget kept it running
    assert episode.judgement.missed == ("balance:constraint",) and episode.judgement.margins["balance:constraint"] < 0


@pytest.mark.parametrize("reach", [False, True])
def test_every_keys_margin_has_the_sign_of_its_verdict(reach):
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
    outcomes = run(tree, keys, np.linspace(-0.1, 0.1, 81))
    seen = set()
    for o in outcomes:
        for key, margin in o.judgement.margins.items():
            assert (margin < 0) == (key in o.judgement.missed), (o.start, key, margin, o.judgement.missed)
            seen.add((key, margin < 0))
    judged_over_time = [k for k in keys if k != "either/balance/upright"]  # the box child (at the end) is always met
    assert seen >= {(k, sign) for k in judged_over_time for sign in (False, True)}  # each both met and missed


def test_a_union_met_at_the_end_keeps_its_last_states_margin_where_its_always_child_dipped():
    tree = AnyOf(sg.Always(UPRIGHT, name="balance"), sg.Goal("calm", theta=(None, 0.1)), name="either")
    [o] = run(tree, ["either", "either/balance"], [0.07])  # 0.22 after one step: neither child; ends calm at 0.07
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
