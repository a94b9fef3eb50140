"""The falsifier on planted policies: a failure region is found and shrunk to its boundary; a clean one is not."""

from __future__ import annotations

import functools

import gymnasium as gym
import numpy as np
import pytest
from hypothesis.database import InMemoryExampleDatabase

import specguard as sg
from specguard.cli.main import main
from specguard.construction.initial_env import state_type
from specguard.falsify.robustness import box_margin, feature_scales, margins
from specguard.falsify.search import EpisodeRunner, falsify
from specguard.starts.space import StartSpace, starts_of


class Line(gym.Env):
    """A point on a plane that action 0 moves right by 2 per step and action 1 keeps still; four steps an episode."""

    observation_space = gym.spaces.Box(-10.0, 10.0, (2,), np.float32)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state, self.t = np.zeros(2), 0
        return self.state.astype(np.float32), {}

    def step(self, action):
        self.state = self.state + np.array([2.0 * (1 - action), 0.0])
        self.t += 1
        return self.state.astype(np.float32), 0.0, False, self.t >= 4, {}


def set_line(env, values):
    env.unwrapped.state = np.array([values["x"], values["y"]])
    return env.unwrapped.state.astype(np.float32)


LINE = sg.InitialEnv(Line, features=("x", "y"))
TREE = sg.Goal("home", x=(2.0, 10.0))
SPACE = StartSpace({"x": (-1.0, 1.0), "y": (-1.0, 1.0)}, set_state=set_line)


def planted(obs):
    """Keeps still, so never gets home, exactly from starts with 0.7 < x <= 1 and y > -0.2."""
    return ((obs[:, 0] > 0.7) & (obs[:, 0] <= 1.0) & (obs[:, 1] > -0.2)).astype(int)


def clean(obs):
    return np.zeros(len(obs), dtype=int)


class Drift(gym.Env):
    """A point that moves right by the action (0 to 1) each step; the policy's speed is the only thing that varies."""

    observation_space = gym.spaces.Box(-10.0, 10.0, (2,), np.float32)
    action_space = gym.spaces.Box(0.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = np.zeros(2)
        return self.state.astype(np.float32), {}

    def step(self, action):
        self.state = self.state + np.array([float(action[0]), 0.0])
        return self.state.astype(np.float32), 0.0, False, False, {}


def drift():
    return gym.wrappers.TimeLimit(Drift(), max_episode_steps=40)


def slower_near_the_corner(obs):
    """Half the distance to the corner (1, 1) per step: home (x >= 3) in time from all but 1 start in 20,000."""
    return np.clip(0.5 * np.hypot(1.0 - obs[:, 0], 1.0 - obs[:, 1]), 0.0, 1.0)[:, None]


DRIFT_SPACE = StartSpace({"x": (-1.0, 1.0), "y": (-1.0, 1.0)}, set_state=set_line)


def runner(policy, **kwargs):
    return EpisodeRunner(functools.partial(sg.make_env, LINE, TREE), policy, SPACE, ["home"], **kwargs)


def still_at_rest(obs):
    """Keeps still, so never gets home, exactly from starts within 0.01 of the middle (1 start in 10,000)."""
    return (np.abs(obs).max(axis=1) < 0.01).astype(int)


def test_the_runners_envs_are_made_in_its_start_space_and_one_made_without_it_is_refused():
    run = runner(still_at_rest, batch=3)
    outcomes = run.run(np.array([[0.5, -0.25], [0.25, 0.5], [-1.0, 1.0]]))
    assert [(o.steps, o.last) for o in outcomes] == [  # one step right (2) from each start: home from the first two
        (1, {"x": 2.5, "y": -0.25}),
        (1, {"x": 2.25, "y": 0.5}),
        (2, {"x": 3.0, "y": 1.0}),
    ]
    assert [starts_of(env).names for env in run._ready(3)] == [("x", "y")] * 3  # each env made in the space
    with pytest.raises(sg.error.InvalidSpec, match="made without a start space"):
        EpisodeRunner(lambda **kwargs: sg.make_env(LINE, TREE), still_at_rest, SPACE, ["home"])


@pytest.mark.parametrize("seed", range(3))
def test_the_middle_of_the_space_is_the_fourth_start(seed):
    # Not first (where failures are common, it would cost an episode), not last of the exploration (where the middle
    # itself fails, as a trained agent's start at rest may, it is found by the fourth episode).
    found = falsify(runner(still_at_rest), examples=50, uniform=0, seed=seed)
    assert found.episodes_to_first == 4 and found.first.start == {"x": 0.0, "y": 0.0}


def test_a_planted_failure_region_is_found_and_shrunk_to_its_boundary():
    found = falsify(runner(planted), examples=200, uniform=400, seed=1)
    assert found.found and found.first is not None and found.first.failed
    c = found.counterexample
    assert c.judgement.missed == ("home",) and c.judgement.score < 0
    assert c.start["x"] == pytest.approx(0.7, abs=1e-3) and c.start["x"] > 0.7  # on the boundary, still failing
    assert c.start["y"] == 0.0  # the middle of y's range fails too: the simplest value
    # The region is 15% x 60% of the space: 9%.
    assert 0.05 < found.failure_rate < 0.14 and found.interval[0] < 0.09 < found.interval[1]
    assert "counterexample (found after" in found.report() and "missed: home" in found.report()


@pytest.mark.parametrize("seed", range(5))
def test_the_guided_search_follows_slower_episodes_to_a_failure_uniform_draws_would_miss(seed):
    # Reaching home sooner scores higher (1 - steps / 40), so the search steps towards the corner where the policy
    # crawls, and it times out within 0.01 of the corner: 1 start in 20,000, where 100 uniform draws find it 0.5% of
    # the time. With uniform draws instead of steps from the lowest scores, this fails.
    env = sg.InitialEnv(drift, features=("x", "y"))
    slow = EpisodeRunner(functools.partial(sg.make_env, env, TREE), slower_near_the_corner, DRIFT_SPACE, ["home"])
    assert slow.max_steps == 40
    found = falsify(slow, examples=100, uniform=0, seed=seed)
    assert found.found and found.episodes_to_first <= 100
    assert found.counterexample.start["y"] > 0.99 and found.counterexample.judgement.missed == ("home",)


def test_a_failing_uniform_draw_is_the_counterexample_when_the_guided_search_found_none():
    db = InMemoryExampleDatabase()
    found = falsify(runner(planted), examples=1, uniform=200, seed=1, database=db, key="spec-u")
    assert found.first is None and found.guided >= 1  # the one guided start, the middle, passes
    assert found.found and found.from_uniform and found.uniform_failures > 0
    assert found.counterexample.start["x"] == pytest.approx(0.7, abs=1e-3) and found.counterexample.start["x"] > 0.7
    assert "found by the uniform draws" in found.report() and len(list(db.fetch(b"spec-u"))) == 1


def test_a_clean_policy_is_never_reported():
    found = falsify(runner(clean), examples=100, uniform=100, seed=1)
    assert not found.found and found.first is None and found.uniform_failures == 0
    assert found.guided == 100 and "no counterexample in 100 guided episodes" in found.report()


def test_the_counterexample_is_stored_under_the_key_and_replayed_first():
    db = InMemoryExampleDatabase()
    first = falsify(runner(planted), examples=200, uniform=0, database=db, key="spec-a")
    assert first.found and not first.replayed and len(list(db.fetch(b"spec-a"))) == 1
    again = falsify(runner(planted), examples=200, uniform=0, database=db, key="spec-a")
    assert again.replayed and again.guided == 1 and again.counterexample.start == first.counterexample.start
    other = falsify(runner(clean), examples=20, uniform=0, database=db, key="spec-a")  # fixed: the entry is dropped
    assert not other.found and list(db.fetch(b"spec-a")) == []


def test_batches_give_the_same_episodes_as_one_at_a_time():
    points = SPACE.resolve(Line()).uniform(np.random.default_rng(0), 20)
    one = runner(planted, batch=1).run(points)
    many = runner(planted, batch=8).run(points)
    assert [o.start for o in one] == [o.start for o in many]
    assert [o.judgement for o in one] == [o.judgement for o in many]


def test_a_box_margin_is_the_nearest_side_inside_and_the_largest_violation_outside():
    s = state_type(("x", "y"))
    box = {"x": (-1.0, 1.0), "y": (0.0, float("inf"))}
    assert box_margin(box, s(0.5, 3.0), {"x": 1.0, "y": 1.0}) == 0.5
    assert box_margin(box, s(0.5, 3.0), {"x": 0.1, "y": 1.0}) == pytest.approx(3.0)  # y is now the nearer side
    assert box_margin(box, s(2.0, -0.5), {"x": 1.0, "y": 1.0}) == -1.0
    assert feature_scales(("x", "y"), np.array([-4.0, -np.inf]), np.array([4.0, np.inf])) == {"x": 4.0, "y": 1.0}


def test_an_operator_without_a_box_gets_a_margin_signed_by_membership():
    class Either(sg.Node):  # no margin() of its own: the default applies
        kind = "Either"

        def __init__(self, *children, name):
            self.nodes, self.name, self.annotations = children, name, ()

        @property
        def children(self):
            return self.nodes

        def contains(self, ctx):
            return any(ctx.inside)

        def describe(self):
            return f"Either {self.name!r}"

    tree = Either(sg.Goal("a", x=(0.0, 1.0)), sg.Goal("b", x=(2.0, 3.0)), name="e")
    s = state_type(("x",))
    out = margins(tree, s(0.25), {}, {"e": True, "e/a": True, "e/b": False}, {"x": 1.0})
    assert out == {"e/a": 0.25, "e/b": -1.75, "e": 0.25}
    out = margins(tree, s(1.5), {}, {"e": False, "e/a": False, "e/b": False}, {"x": 1.0})
    assert out["e"] == -0.5


# -- bad input: one line naming the culprit -----------------------------------------------------------------------

PENDULUM_FILE = """
import specguard as sg

pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
budget = sg.Budget(timesteps=64, min_seeds=1, eval_episodes=1, checkpoints=1)
up = sg.Spec(pendulum, sg.Goal("still", omega=(-0.25, 0.25)), budget=budget, expect={"still": 0.0},
             trainer=sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1}))
"""


@pytest.fixture
def pendulum_file(tmp_path):
    path = tmp_path / "pendulum_specs.py"
    path.write_text(PENDULUM_FILE)
    return path


@pytest.mark.parametrize("seed", [-1, True, 1.5, "0"])
def test_a_falsification_s_seed_is_an_integer_from_zero(seed):
    with pytest.raises(sg.error.InvalidSpec, match=rf"^Falsify: expected seed to be an integer >= 0 .*got {seed!r}\n"):
        sg.Falsify(seed=seed)
    with pytest.raises(sg.error.InvalidSpec, match=rf"^falsify: expected seed to be an integer >= 0 .*got {seed!r}\n"):
        falsify(runner(clean), examples=1, uniform=0, seed=seed)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"examples": 0}, r"^falsify: expected examples to be an integer >= 1 .*got 0\n"),
        ({"uniform": -1}, r"^falsify: expected uniform to be an integer >= 0 .*got -1\n"),
        ({"uniform": 2.0}, r"^falsify: expected uniform to be an integer >= 0 .*got 2.0\n"),
        ({"confidence": 1.0}, r"^falsify: expected confidence to be a number in \(0, 1\).*got 1.0\n"),
        ({"shrink": "no"}, r"^falsify: expected shrink to be True or False, got 'no'\n"),
    ],
)
def test_the_search_refuses_bad_arguments_naming_them(kwargs, message):
    with pytest.raises(sg.error.InvalidSpec, match=message):
        falsify(runner(clean), **{"examples": 1, "uniform": 0, **kwargs})


def test_the_command_line_refuses_a_negative_seed_in_one_line(pendulum_file, tmp_path, capsys):
    cache = tmp_path / "c"
    with pytest.raises(SystemExit) as exit_info:
        main(["falsify", str(pendulum_file), "--cache-dir", str(cache), "--seed", "-1", "--quiet"])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and "Traceback" not in err and not cache.exists()
    assert err.splitlines()[-1] == (
        "specguard falsify: error: argument --seed: expected an integer >= 0 (the search's seed), got '-1'"
    )


def test_the_command_line_refuses_a_variable_given_twice(pendulum_file, tmp_path, capsys):
    cache = tmp_path / "c"
    argv = ["falsify", str(pendulum_file), "--cache-dir", str(cache), "--examples", "1", "--uniform", "0", "--quiet"]
    code = main([*argv, "--starts", "theta=0:1", "omega=0:1", "theta=-1:0"])
    err = capsys.readouterr().err
    assert code == 2 and not cache.exists()
    assert err.splitlines()[0] == "specguard: error: --starts: 'theta' is given twice: (0.0, 1.0), then (-1.0, 0.0)"
