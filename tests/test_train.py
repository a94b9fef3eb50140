"""Training one run and measuring its goals, with tiny budgets."""

from __future__ import annotations

import dataclasses
import json
import re
import tempfile

import gymnasium as gym
import pytest

import specguard as sg
from example_specs import pendulum
from specguard.construction.env import make_baseline_env
from specguard.engine.result_models import load_normalizer
from specguard.error import TrainingError
from specguard.evaluation.episodes import EVAL_SEED_BASE, evaluate
from specguard.stats.anytime import min_successes_to_meet
from specguard.testing import ReplayEnv
from specguard.training.train import train_run

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}


def tiny_spec(**kwargs):
    kwargs.setdefault("budget", sg.Budget(timesteps=128, eval_episodes=2, max_eval_episodes=4))
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=TINY))
    return sg.Spec(pendulum.initial_env, pendulum.trees["w"], **kwargs)


@pytest.mark.slow
def test_run_result_is_plain_data_and_deterministic_per_seed():
    spec = tiny_spec(expect={"position": 0.2})
    first, model = train_run(spec, seed=3)
    again, _ = train_run(spec, seed=3)
    data = first.to_dict()
    assert json.loads(json.dumps(data)) == data
    assert set(first.successes) == {"pendulum", "pendulum/position", "pendulum/stabilization"}
    assert first.timesteps == 128 and first.episodes in (2, 4)
    assert (first.successes, first.episodes) == (again.successes, again.episodes)
    assert hasattr(model, "predict")


@pytest.mark.slow
def test_a_run_leaves_no_logger_folder_in_the_temporary_directory(tmp_path, monkeypatch):
    # SB3's learn() makes a quiet model's logger in a new empty folder, <tmp>/SB3-<time>, at every call
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    result, model = train_run(tiny_spec(expect={"position": 0.2}), seed=0)
    assert result.timesteps > 0
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith("SB3-")] == []
    assert model.logger.output_formats == []  # SB3's own logger writes nothing either


@pytest.mark.slow
def test_a_run_compiles_its_tree_once_for_all_its_envs(build_counts):
    train_run(
        tiny_spec(trainer=sg.SB3(n_envs=2, hyperparameters=TINY)), seed=0
    )  # two training envs and the evaluation env
    assert build_counts == {"compile": 1, "codegen": 1}


def test_evaluate_counts_the_last_state_of_each_episode():
    initial = sg.InitialEnv(lambda: ReplayEnv([[0.0], [1.0], [0.0], [1.0]]), features=("x",))
    tree = sg.All(sg.Goal("up", x=(0.5, None)), sg.Goal("any", x=(-1.0, None)), name="root")
    env = make_baseline_env(initial, tree)  # the replay truncates after 3 steps, in "up"
    counts = evaluate(lambda obs: 0, env, episodes=3, seeds=[EVAL_SEED_BASE, EVAL_SEED_BASE + 1, EVAL_SEED_BASE + 2])
    assert counts == {"root": 3, "root/up": 3, "root/any": 3}


def test_evaluate_keeps_each_episodes_start_features_and_outcome():
    initial = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    env = sg.make_env(initial, sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="kept"))
    starts, outcomes = [], []
    seeds = [EVAL_SEED_BASE, EVAL_SEED_BASE + 1]
    counts = evaluate(lambda obs: 0, env, 2, seeds, outcomes=outcomes, starts=starts)
    reset = gym.make("CartPole-v1")
    assert starts == [reset.reset(seed=s)[0].astype(float).tolist() for s in seeds]  # the state each began in
    assert outcomes == [{"kept": 0, "kept/upright": 0}] * 2 and counts == {"kept": 0, "kept/upright": 0}


def test_a_run_stored_before_its_looks_were_kept_still_reads_and_a_bad_look_is_refused():
    from specguard.training.result import RunResult

    look = {"timesteps": 64, "features": [[0.5], [-0.25]], "held": {"p": "10"}}
    run = RunResult(spec="p", seed=0, timesteps=64, episodes=2, successes={"p": 1}, train_seconds=1.0, looks=[look])
    data = run.to_dict()
    assert RunResult.from_dict(data, seed=0, paths=["p"]) == run
    old = {k: v for k, v in data.items() if k != "looks"}
    assert RunResult.from_dict(old, seed=0, paths=["p"]).looks == []
    bad = {
        "looks[0].held['p'] is not one 0 or 1 per episode": {**look, "held": {"p": "1"}},
        "looks[0].held is not an object of the run's goal": {**look, "held": {"q": "10"}},
        "looks[0].features is not a list of lists of finite numbers": {**look, "features": [[float("nan")], [0.0]]},
        "looks[0].features has episodes of different lengths": {**look, "features": [[0.5], [0.1, 0.2]]},
        "looks[0].timesteps -1 is not an integer": {**look, "timesteps": -1},
        "looks[0] is not an object of features, held, timesteps": {"timesteps": 64},
    }
    for message, broken in bad.items():
        with pytest.raises(ValueError, match=re.escape(message)):
            RunResult.from_dict({**data, "looks": [broken]}, seed=0, paths=["p"])


def test_evaluate_tells_an_episode_policy_as_each_episode_starts():
    initial = sg.InitialEnv(lambda: ReplayEnv([[0.0], [1.0], [0.0], [1.0]]), features=("x",))
    env = sg.make_env(initial, sg.Goal("up", x=(0.5, None)))

    class Counting:
        """Acts 0; its action is the number of steps since it was last told an episode started."""

        def __init__(self):
            self.starts, self.steps = [], []

        def start(self, envs):
            self.starts.append(list(envs))
            self.steps.append(0)

        def __call__(self, observations, rows=None):
            self.steps[-1] += 1
            return 0

    policy = Counting()
    evaluate(policy, env, episodes=3, seeds=range(3))
    assert policy.starts == [[env]] * 3 and policy.steps == [1, 1, 1]  # each episode reaches "up" in one step


@pytest.mark.slow
def test_algorithm_must_fit_the_action_space():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Spec 'pendulum'.trainer.algorithm: DQN cannot act in a Box action space"
    ):
        train_run(tiny_spec(trainer=sg.SB3(algorithm="DQN", hyperparameters={})), seed=0)


@pytest.mark.slow
def test_hyperparameters_sb3_rejects_are_attributed_to_the_spec():
    # A value SB3 refuses (names it does not take are refused by the Spec: tests/test_algorithms.py).
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Spec 'pendulum'.trainer.hyperparameters: PPO rejected them: .*batch_size"
    ):
        train_run(tiny_spec(trainer=sg.SB3(hyperparameters={**TINY, "batch_size": 1})), seed=0)


class Exploding(gym.Wrapper):
    def __init__(self, env, at):
        super().__init__(env)
        self.at, self.t = at, 0

    def step(self, action):
        self.t += 1
        if self.t == self.at:
            raise RuntimeError("simulator diverged")
        return self.env.step(action)


@pytest.mark.slow
def test_env_failures_name_the_seed_and_step():
    initial = sg.InitialEnv(lambda: Exploding(gym.make("Pendulum-v1"), at=50), features=("x", "y", "omega"))
    spec = sg.Spec(initial, pendulum.trees["b"], budget=sg.Budget(timesteps=128), trainer=sg.SB3(hyperparameters=TINY))
    with pytest.raises(
        TrainingError, match=r"Spec 'pendulum', seed 5, training step 4\d: .*RuntimeError: simulator diverged"
    ):
        train_run(spec, seed=5)


class ExplodingInEvaluation(gym.Wrapper):
    """Trains fine; raises on the first reset of an evaluation episode (its seeds start at EVAL_SEED_BASE)."""

    def reset(self, *, seed=None, options=None):
        if seed is not None and seed >= EVAL_SEED_BASE:
            raise RuntimeError("simulator diverged")
        return self.env.reset(seed=seed, options=options)


@pytest.mark.slow
def test_an_env_failure_in_a_checkpoint_evaluation_names_the_evaluation_not_a_training_step():
    initial = sg.InitialEnv(lambda: ExplodingInEvaluation(ReplayEnv([[0.0], [1.0]])), features=("x",))
    budget = sg.Budget(timesteps=256, eval_episodes=2, checkpoints=4)
    spec = sg.Spec(
        initial, sg.Goal("up", x=(0.5, None)), budget=budget, expect=0.8, trainer=sg.SB3(hyperparameters=TINY)
    )
    with pytest.raises(TrainingError) as raised:
        train_run(spec, seed=5)
    message = str(raised.value)
    assert re.match(
        r"Spec 'up', seed 5, checkpoint evaluation at step 64, evaluation episode 0: "
        r"the environment raised RuntimeError: simulator diverged",
        message,
    ), message
    assert "training step" not in message


@pytest.mark.slow
def test_baseline_trains_on_the_initial_env_and_reports_goals():
    result, model = train_run(tiny_spec(baseline=True), seed=0)
    assert model.observation_space.shape == (3,)
    assert set(result.successes) == {"pendulum", "pendulum/position", "pendulum/stabilization"}


@pytest.mark.slow
def test_wall_clock_cap_stops_training():
    spec = tiny_spec(budget=sg.Budget(timesteps=100_000, eval_episodes=1, wall_clock_s=0.5))
    result, _ = train_run(spec, seed=0)
    assert result.hit_wall_clock and result.timesteps < 100_000


# -- safety rates: episodes without a violation, counted beside the goals ------------------------------------


def replay_initial():
    return sg.InitialEnv(lambda: ReplayEnv([[0.0], [1.0], [0.0], [1.0]]), features=("x",))


def scripted(actions):
    """A policy playing ``actions`` in order, whatever it observes."""
    it = iter(actions)
    return lambda obs: next(it)


SEEDS = [EVAL_SEED_BASE, EVAL_SEED_BASE + 1, EVAL_SEED_BASE + 2]


def test_evaluate_counts_episodes_without_a_violation_in_the_baseline_env():
    tree = sg.All(
        sg.Goal("up", x=(0.5, None)).annotate(sg.Constraint(lambda s, a: s.x > 0.5, name="hot")),
        sg.Goal("any", x=(-1.0, None)),
        name="root",
    ).annotate(sg.Constraint(lambda s, a: a == 2, name="two"))
    env = make_baseline_env(replay_initial(), tree)  # 3 steps an episode: s = 0, 1, 0, 1
    counts = evaluate(scripted([0, 0, 0, 2, 0, 0, 0, 0, 0]), env, episodes=3, seeds=SEEDS)
    # "hot" is violated at step 2 of every episode (s = 1); "two" only in the second episode's first step.
    assert counts == {"root": 3, "root/up": 3, "root/any": 3, "root/up:hot": 0, "root:two": 2}
    assert list(counts)[:3] == ["root", "root/up", "root/any"]  # goals first, then the safety rates


def test_evaluate_counts_an_episode_ended_by_its_constraint_as_unsafe():
    tree = sg.Goal("far", x=(5.0, None)).annotate(
        sg.Constraint(lambda s, a: a == 2, name="two"),  # budget 1: a violation ends the episode
        sg.Constraint(lambda s, a: s.x > 0.5, budget=3, name="hot"),
    )
    env = sg.make_env(replay_initial(), tree)
    # Episode 1 is ended by "two" after one step, at s = 1: its last state, which "hot" judges too (every state is
    # judged, the last included); episodes 2 and 3 run 3 steps and meet "hot".
    counts = evaluate(scripted([2, 0, 0, 0, 0, 0, 0]), env, episodes=3, seeds=SEEDS)
    assert counts == {"far": 0, "far:two": 2, "far:hot": 0}


@pytest.mark.slow
@pytest.mark.parametrize("baseline", [False, True])
def test_runs_measure_the_safety_rate_of_every_constraint(baseline):
    fast = sg.Constraint(lambda s, a: abs(s.omega) > 7.5, budget=2, name="fast")
    tree = sg.All(*pendulum.trees["b"].children, name="pendulum").annotate(fast)
    budget = sg.Budget(timesteps=128, eval_episodes=2, max_eval_episodes=4)
    spec = sg.Spec(
        pendulum.initial_env,
        tree,
        budget=budget,
        baseline=baseline,
        expect={"fast": 0.0},
        trainer=sg.SB3(hyperparameters=TINY),
    )
    result, _ = train_run(spec, seed=0)
    assert set(result.successes) == {"pendulum", "pendulum/position", "pendulum/stabilization", "pendulum:fast"}
    assert 0 <= result.successes["pendulum:fast"] <= result.episodes


# -- anytime verdicts: judged at checkpoints, stopped once every threshold is met ------------------------------


def reached_initial():
    """Every episode ends in x = 1 whatever the policy does: a goal on x >= 0.5 is met from the first checkpoint."""
    return sg.InitialEnv(lambda: ReplayEnv([[0.0], [1.0], [1.0]]), features=("x",))


@pytest.mark.slow
def test_a_run_whose_thresholds_are_met_stops_at_the_first_checkpoint():
    budget = sg.Budget(timesteps=4096, eval_episodes=30, checkpoints=4)
    spec = sg.Spec(
        reached_initial(), sg.Goal("up", x=(0.5, None)), budget=budget, expect=0.8, trainer=sg.SB3(hyperparameters=TINY)
    )
    result, model = train_run(spec, seed=0)
    assert result.met_early and result.timesteps == 1024  # judged at the first quarter, stopped there
    assert (result.successes, result.episodes) == ({"up": 30}, 30)
    assert result.curve[-1]["timesteps"] == 1024 and result.curve[-1]["evaluation"] == {"up": 1.0}
    assert model.num_timesteps == 1024  # the model kept is the one judged: training stopped at the checkpoint


@pytest.mark.slow
def test_a_run_stopped_by_a_met_checkpoint_did_not_hit_the_wall_clock(monkeypatch):
    import time

    from specguard.training import train

    budget = sg.Budget(timesteps=4096, eval_episodes=30, checkpoints=4, wall_clock_s=60)
    spec = sg.Spec(
        reached_initial(), sg.Goal("up", x=(0.5, None)), budget=budget, expect=0.8, trainer=sg.SB3(hyperparameters=TINY)
    )
    late, perf_counter, interim_look = [0.0], time.perf_counter, train.interim_look
    monkeypatch.setattr(time, "perf_counter", lambda: perf_counter() + late[0])

    def slow_look(*args):
        late[0] = 3600.0  # the look's evaluation runs past the cap
        return interim_look(*args)

    monkeypatch.setattr(train, "interim_look", slow_look)
    result, _ = train_run(spec, seed=0)
    assert result.met_early and result.timesteps == 1024 and not result.hit_wall_clock


@pytest.mark.slow
def test_the_cached_model_of_a_run_stopped_at_a_checkpoint_is_the_one_judged(tmp_path):
    budget = sg.Budget(timesteps=4096, eval_episodes=30, checkpoints=4)
    spec = sg.Spec(
        reached_initial(), sg.Goal("up", x=(0.5, None)), budget=budget, expect=0.8, trainer=sg.SB3(hyperparameters=TINY)
    )
    result = sg.run_spec(spec, workers=1, cache_dir=tmp_path, progress=None)
    assert result.runs[0].met_early
    assert sg.load_model(result, 0).num_timesteps == result.runs[0].timesteps == 1024
    # The look that met every threshold is the run's last, kept in its cache entry and in the result's data.
    (look,) = result.runs[0].looks
    assert look["timesteps"] == 1024 and look["held"]["up"].count("1") == result.runs[0].successes["up"]
    again = sg.run_spec(spec, workers=1, cache_dir=tmp_path, progress=None)
    assert all(again.cached.values()) and again.runs[0].looks == [look]
    assert type(result).from_dict(json.loads(json.dumps(result.to_dict()))).runs[0].looks == [look]


@pytest.mark.slow
def test_a_run_whose_thresholds_are_not_met_trains_its_whole_budget():
    budget = sg.Budget(timesteps=4096, eval_episodes=30, checkpoints=4)
    spec = sg.Spec(
        reached_initial(),
        sg.Goal("far", x=(5.0, None)),
        budget=budget,
        expect=0.5,
        trainer=sg.SB3(hyperparameters=TINY),
    )
    result, _ = train_run(spec, seed=0)
    assert not result.met_early and result.timesteps == 4096
    evaluated = [p for p in result.curve if "evaluation" in p]
    assert [p["timesteps"] for p in evaluated] == [1024, 2048, 3072, 4096]  # 3 checkpoints, then the end
    # Each look stopped once a pass was out of reach: after 30 - need + 1 misses in a row.
    need = min_successes_to_meet(30, 0.5, spec.verdict_confidence)
    assert [p["evaluation_episodes"] for p in evaluated[:3]] == [30 - need + 1] * 3
    assert result.episodes == 30
    # What each evaluation saw is kept, episode by episode: the starts' features and each key's outcome.
    assert [look["timesteps"] for look in result.looks] == [1024, 2048, 3072, 4096]
    for look, point in zip(result.looks, evaluated):
        assert len(look["features"]) == point["evaluation_episodes"]
        assert all(len(start) == 1 for start in look["features"])  # the spec's one feature, x, at reset
        assert set(look["held"]) == set(result.successes)
    final = result.looks[-1]
    assert {key: bits.count("1") for key, bits in final["held"].items()} == result.successes
    assert all(start == [0.0] for start in final["features"])  # every episode of this env starts at x = 0


@pytest.mark.slow
def test_one_checkpoint_trains_the_whole_budget_even_when_met():
    budget = sg.Budget(timesteps=4096, eval_episodes=30, checkpoints=1)
    spec = sg.Spec(
        reached_initial(), sg.Goal("up", x=(0.5, None)), budget=budget, expect=0.8, trainer=sg.SB3(hyperparameters=TINY)
    )
    result, _ = train_run(spec, seed=0)
    assert not result.met_early and result.timesteps == 4096


@pytest.mark.slow
def test_auto_weights_adapt_during_training_and_are_recorded():
    initial = sg.InitialEnv(lambda: ReplayEnv([[0.0], [1.0], [0.0], [1.0]]), features=("x",))
    tree = sg.All(sg.Goal("up", x=(0.5, None)), sg.Goal("low", x=(None, 0.7)), name="p", weights="auto")
    spec = sg.Spec(
        initial, tree, budget=sg.Budget(timesteps=128, eval_episodes=2), trainer=sg.SB3(hyperparameters=TINY)
    )
    result, model = train_run(spec, seed=0)
    # Every episode ends at x = 1: in "up", not in "low", so "low" takes the weight.
    assert result.weights == {"p": pytest.approx([0.1 / 1.2, 1.1 / 1.2])}
    assert model.get_env().get_attr("adapted_weights") == [{"p": tuple(result.weights["p"])}]
    assert result.curve[0]["weights"] == {"p": [0.5, 0.5]}  # before the first rollout ended
    assert result.curve[-1]["weights"] == result.weights
    baseline, _ = train_run(dataclasses.replace(spec, baseline=True), seed=0)
    assert baseline.weights == {} and "weights" not in baseline.curve[0]


@pytest.mark.slow
def test_auto_weights_see_the_safety_of_the_nodes_own_constraints():
    initial = sg.InitialEnv(lambda: ReplayEnv([[0.0], [1.0], [0.0], [1.0]]), features=("x",))
    never = sg.Constraint(lambda s, a: False, name="never")
    tree = sg.All(sg.Goal("up", x=(0.5, None)), sg.Goal("low", x=(None, 0.7)), name="p", weights="auto").annotate(never)
    spec = sg.Spec(
        initial, tree, budget=sg.Budget(timesteps=128, eval_episodes=2), trainer=sg.SB3(hyperparameters=TINY)
    )
    result, _ = train_run(spec, seed=0)
    # "up" reached and "never" kept in every episode: "low" takes the weight, both others keep the floor.
    assert result.weights == {"p": pytest.approx([0.1 / 1.3, 1.1 / 1.3, 0.1 / 1.3])}
    assert result.curve[0]["weights"] == {"p": [0.5, 0.5, 1.0]}


# -- what a run computed: the digest of the judged weights -------------------------------------------------------

CARTPOLE = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
BALANCE = sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance")


@pytest.fixture(scope="module")
def digested(tmp_path_factory):
    """Two seeds of a normalizing CartPole spec, a few hundred steps each, run through a cache."""
    budget = sg.Budget(timesteps=256, eval_episodes=2, max_eval_episodes=4, min_seeds=2, max_seeds=2, checkpoints=1)
    spec = sg.Spec(CARTPOLE, BALANCE, budget=budget, expect=0.5, trainer=sg.SB3(hyperparameters=TINY, normalize=True))
    return spec, sg.run_spec(spec, workers=1, cache_dir=tmp_path_factory.mktemp("digests"), progress=None)


@pytest.mark.slow
def test_a_runs_weights_digest_is_the_digest_of_its_model_loaded_back_from_the_cache(digested):
    from specguard.cache.weights import weights_digest

    spec, result = digested
    digests = [run.weights_digest for run in result.runs]
    assert all(re.fullmatch("[0-9a-f]{64}", d) for d in digests) and len(set(digests)) == 2  # each seed its own
    for run in result.runs:
        model, normalizer = sg.load_model(result, run.seed), load_normalizer(result, run.seed)
        assert normalizer is not None
        assert weights_digest(model, normalizer, name="PPO") == run.weights_digest
        assert weights_digest(model, None, name="PPO") != run.weights_digest  # its statistics are part of it
        # the same digest as the loaded model's own identity as an agent: a check of it says the same weights
        assert sg.load_agent(model, normalizer=normalizer).identity == run.weights_digest
    again = sg.run_spec(spec, workers=1, cache_dir=None, progress=None)  # each seed again, uncached
    assert [run.weights_digest for run in again.runs] == digests  # the same seed, the same weights


@pytest.mark.slow
def test_a_runs_weights_digest_is_in_its_json_the_table_and_the_junit_properties(digested):
    from specguard.pytest_plugin.judge import judge_goal

    spec, result = digested
    data = json.loads(json.dumps(result.to_dict()))
    assert [r["weights_digest"] for r in data["runs"]] == [r.weights_digest for r in result.runs]
    assert [r.weights_digest for r in sg.SpecResult.from_dict(data).runs] == [r.weights_digest for r in result.runs]
    short = "; ".join(f"seed {r.seed}: {r.weights_digest[:12]}" for r in result.runs)
    assert f"weights {short} (portable numerics)" in sg.table(result).splitlines()
    check = judge_goal(result, spec, "balance", "s")
    assert dict(check.junit_properties())["weights"] == short
    assert dict(check.junit_properties())["numerics"] == "portable numerics"
    assert [s["weights_digest"] for s in check.to_row()["per_seed"]] == [r.weights_digest for r in result.runs]


@pytest.mark.slow
def test_an_agent_checked_against_a_spec_carries_its_identity_as_its_weights_digest(digested):
    spec, result = digested
    run = result.runs[0]
    agent = sg.load_agent(sg.load_model(result, run.seed), normalizer=load_normalizer(result, run.seed))
    checked = sg.check_agent(spec, agent, episodes=2, max_episodes=2, observation="spec", cache_dir=None)
    assert checked.runs[0].weights_digest == agent.identity == run.weights_digest  # the trained run's weights
    assert f"weights seed 0: {run.weights_digest[:12]}" in sg.table(checked).splitlines()


def test_a_run_stored_before_weights_digests_were_recorded_still_reads():
    from specguard.training.result import RunResult

    run = RunResult(spec="p", seed=0, timesteps=64, episodes=4, successes={"p": 1}, train_seconds=1.0)
    old = run.to_dict()
    del old["weights_digest"]
    assert RunResult.from_dict(old, seed=0, paths=["p"]) == run and run.weights_digest is None
    digest = "3c61144ad8e8" + "0" * 52
    assert RunResult.from_dict({**old, "weights_digest": digest}, seed=0, paths=["p"]).weights_digest == digest
    for bad in (3, "3c61144ad8e8", digest.upper()):
        with pytest.raises(ValueError, match=r"weights_digest .* is neither a SHA-256 hex digest nor null"):
            RunResult.from_dict({**old, "weights_digest": bad}, seed=0, paths=["p"])
