"""The run cache: fingerprints, hits, atomic entries, corrupt entries retrained."""

from __future__ import annotations

import json

import pytest

import specguard as sg
from example_specs import pendulum
from specguard.cache import Cache, fingerprint
from specguard.train import train_run

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
BUDGET = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=2)


def spec(tree=None, **kwargs):
    kwargs.setdefault("budget", BUDGET)
    kwargs.setdefault("hyperparameters", TINY)
    return sg.Spec(pendulum.initial_env, tree or pendulum.trees["w"], **kwargs)


def distance_tree(target):
    def near(s):
        return abs(s.x - target)

    return sg.All(sg.Goal("up", x=(0.9, 1.0)).annotate(sg.Distance(near, scale=2.0)), name="pendulum")


def test_fingerprint_is_stable_and_sensitive():
    base = fingerprint(spec(), 0)
    assert fingerprint(spec(), 0) == base
    assert fingerprint(spec(), 1) != base
    assert fingerprint(spec(budget=sg.Budget(timesteps=256, min_seeds=1, eval_episodes=2)), 0) != base
    assert fingerprint(spec(hyperparameters={**TINY, "gamma": 0.9}), 0) != base
    assert fingerprint(spec(pendulum.trees["c"]), 0) != base
    assert fingerprint(spec(expect={"pendulum": 0.5}), 0) != base
    # A captured value or a changed lambda body changes the key; an equal one does not.
    assert fingerprint(spec(distance_tree(1.0)), 0) == fingerprint(spec(distance_tree(1.0)), 0)
    assert fingerprint(spec(distance_tree(1.0)), 0) != fingerprint(spec(distance_tree(0.5)), 0)
    other = sg.All(sg.Goal("up", x=(0.9, 1.0)).annotate(sg.Distance(lambda s: abs(s.y), scale=2.0)), name="pendulum")
    assert fingerprint(spec(other), 0) != fingerprint(spec(distance_tree(1.0)), 0)


def test_store_then_load_and_the_model_loads_with_sb3(tmp_path):
    from stable_baselines3 import PPO

    s = spec()
    cache = Cache(tmp_path)
    assert cache.load(s, 0) is None
    result, model = train_run(s, 0)
    folder = cache.store(s, 0, result, model)
    assert cache.load(s, 0) == result
    assert PPO.load(cache.model_path(s, 0)).observation_space == model.observation_space
    assert not [p for p in folder.parent.iterdir() if p.name.startswith(".tmp-")]


def test_run_spec_uses_the_cache(tmp_path):
    s = spec()
    first = sg.run_spec(s, workers=1, cache_dir=tmp_path, progress=None)
    second = sg.run_spec(s, workers=1, cache_dir=tmp_path, progress=None)
    assert first.cached == {0: False} and second.cached == {0: True}
    assert [r.to_dict() for r in first.runs] == [r.to_dict() for r in second.runs]
    changed = sg.run_spec(spec(pendulum.trees["c"]), workers=1, cache_dir=tmp_path, progress=None)
    assert changed.cached == {0: False}


@pytest.mark.parametrize("damage", ["garbage json", "wrong model", "missing model"])
def test_corrupt_entries_are_retrained_never_trusted(tmp_path, damage):
    s = spec()
    cache = Cache(tmp_path)
    result, model = train_run(s, 0)
    folder = cache.store(s, 0, result, model)
    if damage == "garbage json":
        (folder / "result.json").write_text("{not json")
    elif damage == "wrong model":
        (folder / "model.zip").write_bytes(b"truncated")
    else:
        (folder / "model.zip").unlink()
    with pytest.warns(UserWarning, match="discarded a corrupt entry"):
        assert cache.load(s, 0) is None
    assert not folder.exists()
    cache.store(s, 0, result, model)
    assert cache.load(s, 0) == result


def test_a_run_killed_midway_leaves_nothing_trusted(tmp_path):
    s = spec()
    cache = Cache(tmp_path)
    entry = cache.entry(s, 0)
    partial = entry.parent / ".tmp-killed"
    partial.mkdir(parents=True)
    (partial / "result.json").write_text(json.dumps({"fingerprint": entry.name}))
    assert cache.load(s, 0) is None


def test_a_second_writer_of_the_same_entry_leaves_it_intact(tmp_path):
    s = spec()
    result, model = train_run(s, 0)
    first, second = Cache(tmp_path), Cache(tmp_path)  # e.g. two xdist workers
    assert first.store(s, 0, result, model) == second.store(s, 0, result, model)
    assert first.load(s, 0) == result
    assert not [p for p in first.entry(s, 0).parent.iterdir() if p.name.startswith(".tmp-")]
