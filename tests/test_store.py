"""The run cache: hits, atomic entries, and stored results that are checked before they are trusted."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest

import specguard as sg
from example_specs import pendulum
from specguard.cache.store import SECRET_ENV, Cache
from specguard.training.result import RunResult
from specguard.training.train import train_run

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
BUDGET = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=2)


def spec(tree=None, **kwargs):
    kwargs.setdefault("budget", BUDGET)
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=TINY))
    return sg.Spec(pendulum.initial_env, tree or pendulum.trees["w"], **kwargs)


@pytest.fixture(scope="module")
def trained():
    """One tiny trained run, shared by the tests that store it."""
    s = spec()
    result, model = train_run(s, 0)
    return s, result, model


@pytest.mark.slow
def test_store_then_load_and_the_model_loads_with_sb3(tmp_path, trained):
    from stable_baselines3 import PPO

    s, result, model = trained
    cache = Cache(tmp_path)
    assert cache.load(s, 0) is None
    folder = cache.store(s, 0, result, model)
    assert cache.load(s, 0) == result
    assert PPO.load(cache.model_path(s, 0)).observation_space == model.observation_space
    assert sorted(p.name for p in folder.iterdir()) == ["model.zip", "result.json"]
    assert not [p for p in folder.parent.iterdir() if p.name.startswith(".tmp-")]


@pytest.mark.slow
def test_run_spec_uses_the_cache(tmp_path):
    s = spec()
    first = sg.run_spec(s, workers=1, cache_dir=tmp_path, progress=None)
    second = sg.run_spec(s, workers=1, cache_dir=tmp_path, progress=None)
    assert first.cached == {0: False} and second.cached == {0: True}
    assert [r.to_dict() for r in first.runs] == [r.to_dict() for r in second.runs]
    changed = sg.run_spec(spec(pendulum.trees["c"]), workers=1, cache_dir=tmp_path, progress=None)
    assert changed.cached == {0: False}


def _edit(folder: Path, change) -> None:
    record = json.loads((folder / "result.json").read_text())
    change(record)
    (folder / "result.json").write_text(json.dumps(record))


def _resign(record) -> None:
    """Recompute the checksum after an edit: the forger who knows the format (but not a secret)."""
    from specguard.cache.store import _checksum

    record["checksum"] = _checksum(record)


DAMAGE = {
    "garbage json": lambda f: (f / "result.json").write_text("{not json"),
    "not an object": lambda f: (f / "result.json").write_text("[1, 2]"),
    "wrong model": lambda f: (f / "model.zip").write_bytes(b"truncated"),
    "missing model": lambda f: (f / "model.zip").unlink(),
    "forged successes": lambda f: _edit(f, lambda r: r["result"]["successes"].update(pendulum=2)),
    "forged episodes": lambda f: _edit(f, lambda r: r["result"].update(episodes=1000)),
    "missing goal": lambda f: _edit(f, lambda r: (r["result"]["successes"].pop("pendulum"), _resign(r))),
    "unknown safety key": lambda f: _edit(
        f, lambda r: (r["result"]["successes"].update({"pendulum:x": 0}), _resign(r))
    ),
    "successes above episodes": lambda f: _edit(
        f, lambda r: (r["result"]["successes"].update(pendulum=r["result"]["episodes"] + 1), _resign(r))
    ),
    "string episodes": lambda f: _edit(f, lambda r: (r["result"].update(episodes="30"), _resign(r))),
    "boolean successes": lambda f: _edit(f, lambda r: (r["result"]["successes"].update(pendulum=True), _resign(r))),
    "other seed": lambda f: _edit(f, lambda r: (r["result"].update(seed=7), _resign(r))),
    "other versions": lambda f: _edit(f, lambda r: (r["versions"].update(torch="0.0.1"), _resign(r))),
    "unknown field": lambda f: _edit(f, lambda r: (r["result"].update(extra=1), _resign(r))),
    "missing weights": lambda f: _edit(f, lambda r: (r["result"].pop("weights"), _resign(r))),
    "string weights": lambda f: _edit(f, lambda r: (r["result"].update(weights={"pendulum": ["0.5"]}), _resign(r))),
    "other fingerprint": lambda f: _edit(f, lambda r: (r.update(fingerprint="0" * 64), _resign(r))),
    "other format": lambda f: _edit(f, lambda r: (r.update(format=1), _resign(r))),
    "stray file recorded": lambda f: _edit(f, lambda r: (r["files"].update({"x.pkl": "0"}), _resign(r))),
}


@pytest.mark.slow
@pytest.mark.parametrize("damage", sorted(DAMAGE))
def test_damaged_forged_or_malformed_entries_are_discarded_never_trusted(tmp_path, trained, damage):
    s, result, model = trained
    cache = Cache(tmp_path)
    folder = cache.store(s, 0, result, model)
    DAMAGE[damage](folder)
    with pytest.warns(UserWarning, match="specguard cache: discarded entry"):
        assert cache.load(s, 0) is None
    assert not folder.exists()
    cache.store(s, 0, result, model)
    assert cache.load(s, 0) == result


@pytest.mark.slow
def test_a_forged_entry_is_retrained_by_run_spec(tmp_path):
    s = spec(expect={"pendulum": 0.5})
    first = sg.run_spec(s, workers=1, cache_dir=tmp_path, progress=None)
    assert not first.passed
    folder = Cache(tmp_path).entry(s, 0)
    _edit(folder, lambda r: r["result"]["successes"].update(pendulum=r["result"]["episodes"]))
    with pytest.warns(UserWarning, match="checksum does not match"):
        again = sg.run_spec(s, workers=1, cache_dir=tmp_path, progress=None)
    assert again.cached == {0: False} and not again.passed


@pytest.mark.slow
def test_an_entry_without_the_safety_rates_is_discarded_and_retrained(tmp_path):
    # An entry stored before safety rates were measured (same key, no "path:name" counts) must not crash the
    # verdicts with a KeyError: it fails validation, is discarded with a warning, and the run is trained again.
    fast = sg.Constraint(lambda s, a: abs(s.omega) > 7.5, name="fast")
    s = spec(sg.All(*pendulum.trees["b"].children, name="pendulum").annotate(fast), expect={"fast": 0.0})
    first = sg.run_spec(s, workers=1, cache_dir=tmp_path, progress=None)
    assert "pendulum:fast" in first.runs[0].successes
    folder = Cache(tmp_path).entry(s, 0)
    _edit(folder, lambda r: (r["result"]["successes"].pop("pendulum:fast"), _resign(r)))
    missing = r"successes do not list exactly the tree's goals and safety rates \(missing 'pendulum:fast'\)\)"
    with pytest.warns(UserWarning, match=missing):
        again = sg.run_spec(s, workers=1, cache_dir=tmp_path, progress=None)
    assert again.cached == {0: False} and again.passed
    assert again.runs[0].successes == first.runs[0].successes  # the same run, retrained
    assert Cache(tmp_path).load(s, 0) is not None


@pytest.mark.slow
def test_with_a_secret_only_entries_signed_with_it_are_trusted(tmp_path, trained):
    s, result, model = trained
    unsigned = Cache(tmp_path)
    unsigned.store(s, 0, result, model)
    with pytest.warns(UserWarning, match=f"no valid signature for the key in {SECRET_ENV}"):
        assert Cache(tmp_path, secret=b"ours").load(s, 0) is None
    Cache(tmp_path, secret=b"theirs").store(s, 0, result, model)
    with pytest.warns(UserWarning, match="no valid signature"):
        assert Cache(tmp_path, secret=b"ours").load(s, 0) is None
    Cache(tmp_path, secret=b"ours").store(s, 0, result, model)
    assert Cache(tmp_path, secret=b"ours").load(s, 0) == result
    # A forger without the key recomputes the checksum, but cannot sign.
    _edit(Cache(tmp_path).entry(s, 0), lambda r: (r["result"]["successes"].update(pendulum=2), _resign(r)))
    with pytest.warns(UserWarning, match="no valid signature"):
        assert Cache(tmp_path, secret=b"ours").load(s, 0) is None


def test_the_secret_comes_from_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv(SECRET_ENV, "k")
    assert Cache(tmp_path).secret == b"k"
    monkeypatch.delenv(SECRET_ENV)
    assert Cache(tmp_path).secret is None


class _SlowModel:
    """Stands in for an SB3 model whose save() can be made to wait or die midway."""

    def __init__(self, before_write=None) -> None:
        self.before_write = before_write

    def save(self, path) -> None:
        Path(path).write_bytes(b"part")
        if self.before_write is not None:
            self.before_write()
        Path(path).write_bytes(b"model bytes")

    def get_env(self):
        return None


RESULT = RunResult(spec="s", seed=0, timesteps=1, episodes=1, successes={"pendulum": 1}, train_seconds=0.0)


@pytest.mark.slow
def test_a_store_killed_midway_leaves_no_entry_only_a_temporary_folder(tmp_path):
    # A separate process dies (os._exit, no cleanup) while writing the entry's model file.
    script = textwrap.dedent(
        f"""
        import os
        from pathlib import Path
        from specguard.cache.store import Cache
        from specguard.training.result import RunResult

        def dies(path, data):
            with open(path, "wb") as f:
                f.write(data[:3])
            os._exit(9)

        Path.write_bytes = dies
        result = RunResult(spec="s", seed=0, timesteps=1, episodes=1, successes={{"pendulum": 1}}, train_seconds=0.0)
        Cache({str(tmp_path)!r}).store_files("ab" * 32, result, {{"model.zip": b"model bytes"}})
        """
    )
    done = subprocess.run([sys.executable, "-c", script], check=False)
    assert done.returncode == 9
    cache = Cache(tmp_path)
    assert not cache.folder("ab" * 32).exists()  # written in place, a killed store would leave a partial entry
    assert [p.name[:5] for p in cache.folder("ab" * 32).parent.iterdir()] == [".tmp-"]
    assert cache.load_key("ab" * 32, seed=0, paths=["pendulum"]) is None
    cache.store_key("ab" * 32, RESULT, _SlowModel(), normalize=False)
    assert cache.load_key("ab" * 32, seed=0, paths=["pendulum"]) == RESULT


def test_concurrent_stores_of_the_same_entry_leave_one_intact_entry(tmp_path):
    # Eight writers reach the rename at the same moment (e.g. xdist workers that trained the same run).
    writers = 8
    barrier = threading.Barrier(writers)
    folders, errors = [], []

    def store() -> None:
        try:
            folders.append(Cache(tmp_path).store_key("cd" * 32, RESULT, _SlowModel(barrier.wait), normalize=False))
        except BaseException as e:
            errors.append(e)

    threads = [threading.Thread(target=store) for _ in range(writers)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert len(set(folders)) == 1
    assert Cache(tmp_path).load_key("cd" * 32, seed=0, paths=["pendulum"]) == RESULT
    assert not [p for p in folders[0].parent.iterdir() if p.name.startswith(".tmp-")]


@pytest.mark.slow
def test_lock_is_released_by_the_os_when_its_holder_dies(tmp_path):
    cache = Cache(tmp_path)
    script = textwrap.dedent(
        f"""
        import os
        from specguard.cache.store import Cache
        Cache({str(tmp_path)!r}).lock("ef" * 32, 1).acquire()
        os._exit(0)
        """
    )
    subprocess.run([sys.executable, "-c", script], check=True, env={**os.environ})
    lock = cache.lock("ef" * 32, 1)
    lock.acquire(timeout=0)
    lock.release()


def test_waiting_for_a_lock_held_too_long_is_a_clear_error(tmp_path):
    from specguard.cache.store import CacheLockTimeout, try_acquire, wait_for

    holder = Cache(tmp_path).lock("12" * 32, 1)
    assert try_acquire(holder)
    try:
        waiter = Cache(tmp_path).lock("12" * 32, 1)
        assert not try_acquire(waiter)
        with pytest.raises(CacheLockTimeout, match=r"Spec 'x', seed 0: another process has been training this run"):
            wait_for(waiter, "Spec 'x', seed 0", 0.2)
    finally:
        holder.release()
    wait_for(waiter, "Spec 'x', seed 0", 0.2)
    waiter.release()


@pytest.mark.parametrize("model", [True, False], ids=["trained run", "agent's evaluation"])
def test_a_result_json_nested_too_deep_is_a_damaged_entry_discarded_not_a_crash(tmp_path, model):
    cache, key = Cache(tmp_path), "cd" * 32
    if model:
        cache.store_files(key, RESULT, {"model.zip": b"model bytes"})
    else:
        cache.store_evaluation(key, RESULT)
    (cache.folder(key) / "result.json").write_text("[" * 100_000 + "]" * 100_000)  # json.loads: RecursionError
    with pytest.warns(UserWarning, match=r"specguard cache: discarded entry .*(recursion|nested|deep)"):
        assert cache.load_key(key, seed=0, paths=["pendulum"], model=model) is None
    assert not cache.folder(key).exists()  # removed, so that the run is trained (or evaluated) again in its place
