"""The falsifier that learns: a failure predictor fitted on related, weaker agents' episodes steers its ``learned``
arm, and estimates the failure rate by importance sampling (planted policies on ``test_falsify``'s plane)."""

from __future__ import annotations

import numpy as np
import pytest
from test_falsify import runner

from specguard.construction.episode_policy import EpisodePolicy
from specguard.falsify.portfolio import Portfolio
from specguard.falsify.predictor import FailureData, FailurePredictor, from_looks
from specguard.falsify.related import EpsilonRandom
from specguard.falsify.search import falsify


def corner(obs):
    """Keeps still, so never gets home, exactly from starts with x > 0.9 and y > 0.9 (1 start in 400; a start moved
    right is past x = 1, where it moves on)."""
    return ((obs[:, 0] > 0.9) & (obs[:, 0] <= 1.0) & (obs[:, 1] > 0.9)).astype(int)


def weaker_agents(n=300, seed=0):
    """Episodes of weaker agents, which failed from the whole square x > 0.5, y > 0.5 (a sixteenth of the plane; the
    corner within it)."""
    x = np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 2))
    return FailureData(x, np.full(n, 0.5), (x[:, 0] > 0.5) & (x[:, 1] > 0.5), np.ones(n))


def test_the_predictor_ranks_the_starts_where_weaker_agents_failed_first():
    # Mutation: dropping the features from the design (only the intercept and the weakness) makes every chance alike.
    p = FailurePredictor().fit(weaker_agents())
    chances = p.predict(np.array([[0.95, 0.95], [0.0, 0.0], [-0.9, -0.9]]))
    assert chances[0] > 0.5 and chances[0] > 10 * max(chances[1:])


def test_a_weaker_agent_is_a_worse_one():
    # The weakness is an input: the same start is riskier for a weaker agent where weaker agents failed more.
    x = np.random.default_rng(1).uniform(-1.0, 1.0, (400, 1))
    weakness = np.repeat([0.1, 0.5], 200)
    failed = x[:, 0] > np.where(weakness > 0.3, 0.0, 0.8)
    p = FailurePredictor().fit(FailureData(x, weakness, failed, np.ones(400)))
    assert p.predict(np.array([[0.5]]), weakness=0.5)[0] > p.predict(np.array([[0.5]]), weakness=0.1)[0]


def test_looks_become_failure_data_of_the_asserted_keys_only():
    looks = [
        {"timesteps": 100, "features": [[0.0], [1.0]], "held": {"g": "10", "other": "00"}},
        {"timesteps": 400, "features": [[2.0]], "held": {"g": "1", "other": "0"}},
    ]
    data = from_looks(looks, ["g"])
    assert data is not None and data.failed.tolist() == [False, True, False]
    assert data.weakness.tolist() == [0.75, 0.75, 0.0] and data.weights.tolist() == [0.25, 0.25, 1.0]
    assert from_looks(looks, ["missing"]) is None and from_looks([], ["g"]) is None


def test_failure_data_refuses_rows_that_disagree():
    with pytest.raises(ValueError, match="expected 3 failed"):
        FailureData(np.zeros((3, 2)), np.zeros(3), np.zeros(2, dtype=bool), np.ones(3))
    with pytest.raises(ValueError, match="2-D array of finite numbers"):
        FailureData(np.array([[np.nan]]), np.zeros(1), np.zeros(1, dtype=bool), np.ones(1))


def test_the_learned_arm_proposes_where_the_predictor_expects_failures():
    # Mutation: taking a random candidate instead of the argmax puts the learned starts where uniform ones are.
    predictor = FailurePredictor().fit(weaker_agents())
    portfolio = Portfolio(2, np.random.default_rng(0), predict=predictor.predict)
    learned = np.stack(list(portfolio._learned(200)))
    assert np.mean((learned[:, 0] > 0.5) & (learned[:, 1] > 0.5)) > 0.75  # uniform draws: a sixteenth
    assert "learned" not in Portfolio(2, np.random.default_rng(0)).shares()


def test_weaker_agents_data_steers_the_search_to_a_rare_failure():
    # The corner fails from 1 start in 400. Over 10 searches the learned arm's, fitted on the weaker agents' square,
    # need fewer than half the episodes of the search without it. Mutation: not giving the portfolio the predictor.
    def episodes(**kwargs):
        spent = 0
        for seed in range(10):
            found = falsify(runner(corner), examples=400, uniform=0, seed=seed, shrink=False, **kwargs)
            spent += found.episodes_to_first if found.found else 400
        return spent

    learned, plain = episodes(related=weaker_agents()), episodes()
    assert learned < plain / 2, (learned, plain)


def test_the_agent_made_weaker_supplies_data_counted_among_the_episodes():
    found = falsify(runner(corner), examples=200, uniform=0, seed=0, shrink=False, weaker=8)
    assert found.drawn_by["related"] == 24 and found.related is not None and len(found.related) == 24
    assert sum(found.drawn_by.values()) == (found.episodes_to_first if found.found else found.guided)


def test_importance_sampling_gives_a_rate_with_an_interval_narrower_than_uniform_draws():
    found = falsify(
        runner(corner), examples=60, uniform=400, seed=0, shrink=False, related=weaker_agents(), importance=400
    )
    estimate = found.importance
    assert estimate is not None and estimate.episodes == 400 and estimate.failures >= 5
    assert estimate.low <= 0.0025 <= estimate.high
    assert estimate.high - estimate.low < (found.interval[1] - found.interval[0]) / 2
    assert "importance sampling" in found.report() and found.to_dict()["importance"] == estimate.summary()
    assert "failure predictor: fitted on 17 failures in 300 episodes of related agents" in found.report()
    assert falsify(runner(corner), examples=20, uniform=0, importance=100).importance is None  # no predictor


class Counting:
    """An episode policy that counts the episodes it was told of."""

    def __init__(self):
        self.started = 0

    def start(self, envs):
        self.started += len(envs)

    def __call__(self, observations, rows=None):
        return np.zeros(len(observations), dtype=np.int64)


def test_epsilon_random_keeps_the_agent_at_zero_and_tells_an_episode_policy():
    import gymnasium as gym

    agent = Counting()
    noisy = EpsilonRandom(agent, gym.spaces.Discrete(2), 0.0, np.random.default_rng(0))
    assert isinstance(noisy, EpisodePolicy)
    noisy.start([None, None])
    assert agent.started == 2 and noisy(np.zeros((50, 2)), [0, 1]).tolist() == [0] * 50
    with pytest.raises(ValueError, match="epsilon in"):
        EpsilonRandom(agent, gym.spaces.Discrete(2), 1.5, np.random.default_rng(0))


def test_falsify_runs_gives_each_run_its_own_looks_without_being_told(tmp_path, monkeypatch):
    # Mutation: dropping related= from falsify_runs' call of falsify_run leaves the search without the looks.
    from types import SimpleNamespace

    from test_robustness import BALANCE, lean_rows

    import specguard as sg
    from specguard.engine import falsify_run

    given = {}

    def search(runner, **kwargs):
        given[kwargs["seed"]] = kwargs["related"]
        raise StopIteration

    monkeypatch.setattr(falsify_run, "falsify", search)
    monkeypatch.setattr(falsify_run, "load_run", lambda result, seed: (BALANCE, None, None))
    monkeypatch.setattr(falsify_run, "batch_policy", lambda model, normalizer, deterministic: lean_rows)
    looks = [{"timesteps": 10, "features": [[0.0, 0.0, 0.1, 0.0], [0.0, 0.0, -0.1, 0.0]], "held": {"balance": "01"}}]
    trained = SimpleNamespace(runs=[SimpleNamespace(seed=3, looks=looks)], spec_key=None, cache_dir=str(tmp_path))
    with pytest.raises(StopIteration):
        sg.falsify_runs(trained, sg.StartSpace({"theta": (-0.05, 0.05)}), examples=1, uniform=0)
    related = given[0]
    assert related is not None and related.failed.tolist() == [True, False] and related.features.shape == (2, 4)


def test_the_command_line_passes_weaker_and_importance_to_the_search(tmp_path, monkeypatch):
    # Mutation: dropping weaker= (or importance=) from the CLI's call of falsify_agent leaves the defaults, 0.
    from test_robustness import SPEC_FILE

    from specguard.cli.main import main
    from specguard.engine import falsify_run

    given = {}

    def search(runner, **kwargs):
        given.update(kwargs)
        raise StopIteration

    monkeypatch.setattr(falsify_run, "falsify", search)
    specs = tmp_path / "cartpole_specs.py"
    specs.write_text(SPEC_FILE)
    argv = ["falsify", f"{specs}::balance", "--agent", f"{specs}::lean", "--weaker", "3", "--importance", "7"]
    with pytest.raises(StopIteration):
        main([*argv, "--cache-dir", str(tmp_path / "c"), "--quiet"])
    assert given["weaker"] == 3 and given["importance"] == 7 and given["related"] is None


def test_a_predictor_whose_data_started_elsewhere_is_not_used_and_the_report_says_so():
    # Looks from a narrow default start (here within 0.05 of the middle), searched over the whole plane: the
    # predictor would extrapolate. Mutation: COVERAGE = 0 fits it anyway.
    x = np.random.default_rng(0).uniform(-0.05, 0.05, (200, 2))
    narrow = FailureData(x, np.full(200, 0.5), x[:, 0] > 0.03, np.ones(200))
    found = falsify(runner(corner), examples=40, uniform=0, seed=0, shrink=False, related=narrow)
    assert found.predictor is None and found.coverage is not None and found.coverage < 0.1
    assert "failure predictor: not used: 54 failures in 200 episodes of related agents" in found.report()
    assert "learned" not in found.drawn_by
    wide = falsify(runner(corner), examples=40, uniform=0, seed=0, shrink=False, related=weaker_agents())
    assert wide.predictor is not None and wide.coverage is not None and wide.coverage > 0.9
