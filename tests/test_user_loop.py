"""A trainer of the user's (``Spec(trainer=...)``): its checkpoints judged, the generator closed once met, its agent
cached; every mistake one line."""

from __future__ import annotations

import dataclasses
import functools
import threading
import time
from pathlib import Path

import pytest

import specguard as sg
from specguard.cache.fingerprint import fingerprint_spec
from specguard.cache.store import Cache
from specguard.error import CacheWarning, InvalidSpec, TrainingError
from specguard.spec.loading import import_file
from specguard.stats.anytime import checkpoint_steps
from specguard.training.train import train_run

SHORT = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"), max_episode_steps=24)
BALANCE = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")
BUDGET = sg.Budget(timesteps=1000, eval_episodes=10, checkpoints=4, min_seeds=1, max_seeds=1)
REINFORCE = Path(__file__).parent.parent / "examples" / "trainers" / "reinforce.py"


def lean(obs):
    """Pushes the cart under the pole: keeps it upright for 24 steps."""
    return int(obs[2] + 0.5 * obs[3] > 0)


def push_left(obs):
    """Always left: the pole falls within 24 steps."""
    return 0


def improving(make_env, timesteps, seed, *, good_from=500, log=None):
    """Yields every 100 steps: ``push_left`` before ``good_from``, ``lean`` from there; records what it was asked."""
    log = [] if log is None else log
    env = make_env()
    try:
        for steps in range(100, timesteps + 1, 100):
            log.append(steps)
            yield steps, (lean if steps >= good_from else push_left)
    finally:
        env.close()
        log.append("closed")


def spec(trainer=improving, **kwargs):
    kwargs.setdefault("budget", BUDGET)
    kwargs.setdefault("expect", 0.5)
    return sg.Spec(SHORT, BALANCE, trainer=trainer, **kwargs)


@pytest.mark.slow
def test_checkpoints_are_judged_at_the_planned_looks_and_the_generator_closed_once_met():
    log: list = []
    result, agent = train_run(spec(functools.partial(improving, log=log)), seed=0)
    looks = checkpoint_steps(BUDGET.timesteps, BUDGET.checkpoints)
    first_good = next(s for s in looks if s >= 500)
    met_at = -(-first_good // 100) * 100  # the first checkpoint at or past that look
    assert result.met_early and not result.hit_wall_clock
    assert result.timesteps == met_at and agent is lean
    assert result.successes["balance"] == result.episodes
    assert [p["timesteps"] for p in result.curve] == [-(-s // 100) * 100 for s in looks if s <= met_at]
    assert log[-2:] == [met_at, "closed"]  # closed: asked for nothing past the met checkpoint, its finally ran
    # What each look at the loop's agents saw is kept, as for SB3's: the last one met every threshold.
    assert [look["timesteps"] for look in result.looks] == [p["timesteps"] for p in result.curve]
    assert result.looks[-1]["held"]["balance"] == "1" * result.episodes


@pytest.mark.slow
def test_a_trainer_never_met_runs_to_its_budget_and_its_last_agent_gets_the_final_evaluation():
    log: list = []
    result, agent = train_run(spec(functools.partial(improving, good_from=10**9, log=log)), seed=0)
    assert not result.met_early and result.timesteps == 1000 and agent is push_left
    assert result.successes["balance"] == 0 and result.episodes >= BUDGET.eval_episodes
    assert result.curve[-1]["timesteps"] == 1000 and "evaluation" in result.curve[-1]
    assert log[-2:] == [1000, "closed"]


@pytest.mark.slow
def test_a_trainer_that_ends_early_is_judged_at_its_last_checkpoint():
    def short(make_env, timesteps, seed):
        yield 7, lean

    result, agent = train_run(spec(short), seed=0)
    assert result.timesteps == 7 and agent is lean and result.successes["balance"] == result.episodes


@pytest.mark.slow
def test_a_trainer_is_stopped_at_its_first_checkpoint_past_the_budget():
    log: list = []

    def overshoots(make_env, timesteps, seed):
        try:
            for steps in range(300, 10 * timesteps, 300):
                log.append(steps)
                yield steps, push_left
        finally:
            log.append("closed")

    result, _ = train_run(spec(overshoots, expect={}), seed=0)
    assert result.timesteps == 1200 and log == [300, 600, 900, 1200, "closed"]


class Checkpoints:
    """A trainer that returns an iterator of its own (no generator): closed by its ``close``, never by the GC."""

    def __init__(self):
        self.asked: list = []

    def __call__(self, make_env, timesteps, seed):
        return self

    def __iter__(self):
        return self

    def __next__(self):
        self.asked.append(len(self.asked) * 100 + 100)
        return self.asked[-1], lean

    def close(self):
        self.asked.append("closed")


@pytest.mark.slow
def test_a_met_look_closes_the_trainers_iterator_at_once():
    trainer = Checkpoints()
    result, _ = train_run(spec(trainer), seed=0)
    assert result.met_early and trainer.asked[-1] == "closed" and trainer.asked[-2] == result.timesteps


@pytest.mark.slow
def test_the_wall_clock_cap_stops_a_trainer():
    def slow(make_env, timesteps, seed):
        for steps in range(1, timesteps + 1):
            time.sleep(0.02)
            yield steps, push_left

    budget = dataclasses.replace(BUDGET, wall_clock_s=0.1)
    result, _ = train_run(spec(slow, budget=budget, expect={}), seed=0)
    assert result.hit_wall_clock and result.timesteps < 100


# -- validation ------------------------------------------------------------------------------------------------


def not_a_generator(make_env, timesteps, seed):
    return [(1, lean)]


class ReturnsAList:
    def __call__(self, make_env, timesteps, seed):
        return [(1, lean)]


class ProtocolShaped:
    """Has the Trainer protocol's methods, but is no trainer specguard runs (nor a function to call)."""

    title = "mine"

    def checked(self, where, *, observation, baseline, tree):
        return self

    def identity(self, *, observation):
        return {}

    def logging_to(self, where, folder):
        return self

    def steps_text(self, timesteps):
        return ""


@pytest.mark.parametrize(
    ("trainer", "match"),
    [
        (3, r"Spec 'balance'\.trainer: expected sg.SB3\(\.\.\.\) or a generator function .* got 3"),
        (ProtocolShaped(), r"Spec 'balance'\.trainer: expected sg.SB3\(\.\.\.\) or a generator function .* got"),
        (not_a_generator, r"the function .*not_a_generator, which does not yield"),
        (functools.partial(not_a_generator), r"the function .*not_a_generator, which does not yield"),
    ],
)
def test_a_trainer_that_is_no_generator_function_is_refused_when_the_spec_is_made(trainer, match):
    with pytest.raises(InvalidSpec, match=match):
        spec(trainer)


@pytest.mark.slow
def test_a_callable_returning_no_iterator_is_refused_when_it_runs():
    with pytest.raises(InvalidSpec, match=r"expected trainer .*ReturnsAList.* to return a generator"):
        train_run(spec(ReturnsAList()), seed=0)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("items", "match"),
    [
        ([lean], r"checkpoint 1: expected a \(steps, agent\) pair, got <function lean"),
        ([(1, lean, 2)], r"checkpoint 1: expected a \(steps, agent\) pair"),
        ([(1.5, lean)], r"checkpoint 1: expected steps to be a natural int, got 1\.5"),
        ([(True, lean)], r"checkpoint 1: expected steps to be a natural int, got True"),
        ([(5, lean), (5, lean)], r"checkpoint 2: expected steps to increase past 5, got 5"),
        ([(1, "model.zip")], r"checkpoint 1: expected the agent to be a callable .*got 'model\.zip'"),
        ([], r"trainer .*yields: it yielded no \(steps, agent\) checkpoint"),
    ],
)
def test_a_bad_checkpoint_fails_the_run_in_one_line_naming_the_trainer(items, match):
    def yields(make_env, timesteps, seed):
        yield from items

    with pytest.raises(TrainingError, match=match) as e:
        train_run(spec(yields, expect={}), seed=0)
    assert "Spec 'balance', seed 0, trainer" in str(e.value) and "\n" not in e.value.message


@pytest.mark.slow
def test_a_trainer_that_raises_fails_its_seed_naming_the_trainer_the_seed_and_its_last_steps():
    def breaks(make_env, timesteps, seed):
        yield 100, push_left
        raise RuntimeError("out of memory")

    with pytest.raises(TrainingError) as e:
        train_run(spec(breaks, expect={}), seed=3)
    assert e.value.message.startswith("Spec 'balance', seed 3, trainer ")
    assert e.value.message.endswith("breaks, after step 100: it raised RuntimeError: out of memory")


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("callbacks", [object]),
        ("hyperparameters", {"n_steps": 64}),
        ("normalize", True),
        ("n_envs", 2),
        ("policy", "MultiInputPolicy"),
        ("algorithm", "A2C"),
        ("tensorboard_log", "tb"),
    ],
)
def test_the_keywords_that_only_configure_sb3_are_refused_beside_a_trainer_of_its_own(field, value):
    # Spec(algorithm=...) is the old form of Spec(trainer=sg.SB3(algorithm=...)): beside a loop it would be ignored.
    with pytest.raises(InvalidSpec, match=rf"^Spec: {field}= configure SB3's training, and the spec trains with its "):
        spec(**{field: value})


def test_the_old_sb3_keywords_still_make_an_sb3_trainer_with_a_deprecation_warning():
    with pytest.warns(DeprecationWarning, match=r"Spec\(algorithm=, n_envs=\.\.\.\) moved into the spec's trainer"):
        old = sg.Spec(SHORT, sg.Goal("up", theta=(-0.2, 0.2)), budget=BUDGET, algorithm="A2C", n_envs=2)
    assert old.trainer == sg.SB3("A2C", n_envs=2, policy="MlpPolicy")


def test_auto_weights_are_refused_with_a_trainer():
    tree = sg.All(sg.Goal("up", theta=(-0.2, 0.2)), sg.Goal("mid", x=(-1, 1)), name="p", weights="auto")
    with pytest.raises(InvalidSpec, match=r"weights='auto' at p adapts SB3's training envs' weights"):
        sg.Spec(SHORT, tree, budget=BUDGET, trainer=improving)


def test_the_doors_tensorboard_folder_leaves_a_trainer_spec_as_it_is_and_says_so(tmp_path):
    s = spec()
    with pytest.warns(sg.error.SpecWarning, match=r"trains with its own trainer .*improving.*: the TensorBoard folder"):
        assert s.as_run(tensorboard_log=tmp_path) is s


# -- identity, cache, workers ----------------------------------------------------------------------------------


def test_the_trainer_is_part_of_the_key_and_a_spec_without_one_keeps_its_key():
    keys = {fingerprint_spec(spec(t)).run_key(0) for t in (improving, functools.partial(improving, good_from=600))}
    assert len(keys) == 2
    plain = sg.Spec(SHORT, BALANCE, budget=BUDGET, expect=0.5)
    assert fingerprint_spec(plain).run_key(0) == fingerprint_spec(dataclasses.replace(plain)).run_key(0)
    assert fingerprint_spec(plain).run_key(0) not in keys


@pytest.mark.slow
def test_a_trainer_run_is_cached_and_its_agent_loaded_back(tmp_path):
    first = sg.run_spec(spec(), workers=1, cache_dir=tmp_path, progress=None)
    again = sg.run_spec(spec(), workers=1, cache_dir=tmp_path, progress=None)
    assert first.passed and again.passed and again.cached == {0: True} and first.cached == {0: False}
    assert again.runs[0].to_dict() == first.runs[0].to_dict()
    agent = sg.load_model(again, 0)
    assert agent([0.0, 0.0, 0.1, 0.0]) == 1 and agent([0.0, 0.0, -0.1, 0.0]) == 0
    steps = sg.rollout(again, 0, episodes=1)[0]
    assert steps[-1]["info"]["goals"]["balance"]


class Locked:
    """An agent that acts and cannot be pickled (it holds a lock)."""

    def __init__(self):
        self.lock = threading.Lock()

    def __call__(self, obs):
        return lean(obs)


def unpicklable(make_env, timesteps, seed):
    yield 100, Locked()


@pytest.mark.slow
def test_an_agent_that_cannot_be_pickled_is_warned_about_and_its_run_kept(tmp_path):
    with pytest.warns(CacheWarning, match=r"seed 0: its agent Locked cannot be pickled .*kept and judged, not cached"):
        result = sg.run_spec(spec(unpicklable), workers=1, cache_dir=tmp_path, progress=None)
    assert result.passed and result.runs[0].timesteps == 100 and result.cached == {0: False}
    assert Cache(tmp_path).load(spec(unpicklable), 0) is None


@pytest.mark.slow
def test_a_trainer_spec_trains_its_seeds_in_two_worker_processes(tmp_path):
    two = spec(budget=dataclasses.replace(BUDGET, min_seeds=2, max_seeds=2))
    result = sg.run_spec(two, workers=2, cache_dir=tmp_path, progress=None)
    assert result.passed and sorted(r.seed for r in result.runs) == [0, 1] and not result.errors
    assert sg.load_model(result, 1)([0.0, 0.0, 0.1, 0.0]) == 1


# -- the example -----------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_the_reinforce_example_trains_cartpole_through_the_protocol_and_is_cached(tmp_path):
    example = import_file(REINFORCE)
    one = example.balance.scaled(1.0)
    one = dataclasses.replace(one, budget=dataclasses.replace(one.budget, min_seeds=1, max_seeds=1))
    result = sg.run_spec(one, workers=1, cache_dir=tmp_path, progress=None)
    assert result.passed, sg.table(result)
    assert result.runs[0].met_early and result.runs[0].timesteps < one.budget.timesteps
    again = sg.run_spec(one, workers=1, cache_dir=tmp_path, progress=None)
    assert again.cached == {0: True} and again.passed
    agent = sg.load_model(again, 0)
    obs, _ = one.make_env().reset(seed=0)
    assert agent(obs) in (0, 1)


@pytest.mark.slow
def test_an_agent_that_raises_in_evaluation_is_named_as_the_agent_not_the_environment():
    def fails_to_act(obs):
        raise ValueError("logits are NaN")

    def trains(make_env, timesteps, seed):
        yield 100, fails_to_act

    with pytest.raises(TrainingError) as e:
        train_run(spec(trains, expect={}), seed=3)
    assert "evaluation episode 0: the agent raised ValueError: logits are NaN" in e.value.message
    assert "environment" not in e.value.message.split("\nHint:")[0]
    assert "weights went NaN" in str(e.value)


@pytest.mark.slow
def test_a_trainer_run_reports_its_progress_at_each_tenth_of_its_budget():
    events: list = []
    train_run(spec(functools.partial(improving, good_from=10**9)), seed=0, progress=events.append)
    updates = [e for e in events if e.kind == "update"]
    assert [e.steps for e in updates] == list(range(100, 1001, 100))
    looked = {-(-s // 100) * 100 for s in checkpoint_steps(BUDGET.timesteps, BUDGET.checkpoints)}
    assert {e.steps for e in updates if e.episodes} == looked  # a looked-at checkpoint tells its look's success
    assert all(e.success == 0 for e in updates if e.episodes)


def raising_after_one(make_env, timesteps, seed, *, error):
    yield 100, push_left
    raise error


@pytest.mark.slow
def test_a_partial_trainer_is_named_by_the_function_it_wraps():
    trainer = functools.partial(raising_after_one, error=ValueError("boom"))
    with pytest.raises(TrainingError, match=r"trainer raising_after_one, after step 100: it raised ValueError: boom"):
        train_run(spec(trainer), seed=0)


@pytest.mark.slow
def test_a_warning_of_run_spec_points_at_the_users_line(tmp_path):
    with pytest.warns(sg.error.SpecWarning, match="gets nothing from it") as caught:
        sg.run_spec(spec(), workers=1, cache_dir=None, progress=None, tensorboard_log=tmp_path / "runs")
    assert [w.filename for w in caught if issubclass(w.category, sg.error.SpecWarning)] == [__file__]


@pytest.mark.slow
def test_a_trainers_agent_has_its_weights_digest_or_none_where_it_cannot_be_digested():
    from specguard.engine.worker_task import judged_digest

    result, agent = train_run(spec(), seed=0)
    assert agent is lean and judged_digest(spec(), agent) == sg.load_agent(lean).identity  # as a check of it says
    lock = threading.Lock()

    def locked(obs):
        with lock:  # a lock has no canonical form: nothing to digest
            return lean(obs)

    def once(make_env, timesteps, seed):
        yield timesteps, locked

    result, agent = train_run(spec(once), seed=0)
    assert agent is locked and judged_digest(spec(once), agent) is None  # judged all the same
    assert result.successes["balance"] == result.episodes
