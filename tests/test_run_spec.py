"""run_spec: parallel seeds, sequential stopping, verdicts, errors kept per seed."""

from __future__ import annotations

import json
import multiprocessing
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import pytest

import specguard as sg
from example_specs import pendulum
from specguard.cache.store import Cache
from specguard.parallel.workers import resolve_workers

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}


def spec(tree="w", **kwargs):
    kwargs.setdefault("budget", sg.Budget(timesteps=128, min_seeds=2, max_seeds=4, eval_episodes=4))
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=TINY))
    return sg.Spec(pendulum.initial_env, pendulum.trees[tree], **kwargs)


@pytest.mark.slow
def test_clearly_missed_goal_stops_after_the_minimum_seeds(tmp_path):
    # 128 steps of PPO never hold the pendulum up in 95% of episodes: missed in both runs.
    result = sg.run_spec(spec(expect={"pendulum": 0.95}), workers=2, cache_dir=tmp_path, progress=None)
    assert [r.seed for r in result.runs] == [0, 1]
    goal = result.goals["pendulum"]
    assert goal.verdict == "failed" and goal.required == 4
    assert not result.passed
    assert json.loads(json.dumps(result.to_dict()))["goals"]["pendulum"]["verdict"] == "failed"
    assert "pendulum" in sg.table(result) and "failed" in sg.table(result)


@pytest.mark.slow
def test_trivially_met_goal_passes_with_a_quorum(tmp_path):
    s = spec(expect={"stabilization": 0.0}, quorum=2)
    result = sg.run_spec(s, workers=1, cache_dir=None, progress=None)
    assert result.passed
    assert result.goals["pendulum/stabilization"].runs == ["met", "met"]
    assert len(result.runs) == 2


@pytest.mark.slow
def test_open_quorum_trains_more_seeds(tmp_path):
    # Quorum 3 of 4 with a goal met by every run: after 2 runs the quorum is open, one more settles it.
    s = spec(expect={"stabilization": 0.0}, quorum=3)
    result = sg.run_spec(s, workers=2, cache_dir=None, progress=None)
    assert result.passed and len(result.runs) == 3


class FailsOnSeed(gym.Wrapper):
    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self.first_seed = seed
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        if getattr(self, "first_seed", None) == 1:
            raise RuntimeError("boom")
        return self.env.step(action)


def make_failing():
    return FailsOnSeed(gym.make("Pendulum-v1"))


@pytest.mark.slow
def test_a_failing_seed_keeps_the_others(tmp_path):
    initial = sg.InitialEnv(make_failing, features=("x", "y", "omega"))
    s = sg.Spec(
        initial,
        pendulum.trees["b"],
        budget=sg.Budget(timesteps=128, eval_episodes=2),
        trainer=sg.SB3(hyperparameters=TINY),
    )
    lines = []
    result = sg.run_spec(s, workers=2, cache_dir=tmp_path, progress=lines.append)
    assert [r.seed for r in result.runs] == [0]
    assert "seed 1, training step" in result.errors[1] and "RuntimeError: boom" in result.errors[1]
    assert not result.passed
    assert any("seed 1: failed" in line for line in lines)


@pytest.mark.slow
def test_spec_errors_from_workers_reach_the_caller(tmp_path):
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Spec 'pendulum'.trainer.algorithm: DQN cannot act in a Box action space"
    ):
        sg.run_spec(spec(trainer=sg.SB3(algorithm="DQN", hyperparameters={})), workers=1, cache_dir=None, progress=None)


def test_workers():
    assert resolve_workers(3) == 3
    assert resolve_workers("auto") >= 1
    with pytest.raises(sg.SpecError, match=r"workers: expected an integer >= 1 \(or 'auto': .*\), got 0"):
        resolve_workers(0)


# -- workers that fail alone -------------------------------------------------------------

PARENT = "SPECGUARD_TEST_PARENT_PID"


class KilledOnSeed(gym.Wrapper):
    """SIGKILLs its own (worker) process on the 50th step of the run with seed 1."""

    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self.first_seed = seed
        self.steps = 0
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        self.steps += 1
        in_worker = str(os.getpid()) != os.environ.get(PARENT)
        if in_worker and getattr(self, "first_seed", None) == 1 and self.steps == 50:
            os.kill(os.getpid(), signal.SIGKILL)
        return self.env.step(action)


def make_killed():
    return KilledOnSeed(gym.make("Pendulum-v1"))


@pytest.mark.slow
def test_a_killed_worker_fails_its_seed_alone_and_the_other_seed_is_stored(tmp_path, monkeypatch):
    monkeypatch.setenv(PARENT, str(os.getpid()))
    initial = sg.InitialEnv(make_killed, features=("x", "y", "omega"))
    s = sg.Spec(
        initial,
        pendulum.trees["b"],
        budget=sg.Budget(timesteps=128, eval_episodes=2),
        trainer=sg.SB3(hyperparameters=TINY),
    )
    result = sg.run_spec(s, workers=2, cache_dir=tmp_path, progress=None)
    assert [r.seed for r in result.runs] == [0]
    assert result.errors[1].startswith("seed 1, training step ")
    assert result.errors[1].endswith(": worker process died (killed by signal SIGKILL)")
    assert Cache(tmp_path).load(s, 0) == result.runs[0]
    assert Cache(tmp_path).load(s, 1) is None


def raising_factory():
    raise RuntimeError("no env today")


class FailsInEvaluation(gym.Wrapper):
    def reset(self, *, seed=None, options=None):
        if seed is not None and seed >= 1_000_000:
            raise RuntimeError("evaluation broke")
        return self.env.reset(seed=seed, options=options)


@pytest.mark.parametrize(
    ("initial", "message"),
    [
        (
            sg.InitialEnv(raising_factory, features=("x", "y", "omega")),
            r"InitialEnv raising_factory: building it with its factory raised RuntimeError: no env today",
        ),
        (
            sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"), no_such_kwarg=1),
            r"InitialEnv 'Pendulum-v1': building it with gymnasium.make and \{'no_such_kwarg': 1\} raised TypeError",
        ),
    ],
    ids=["factory raises", "unknown make kwarg"],
)
@pytest.mark.parametrize("cached", [True, False], ids=["cache", "no cache"])
def test_an_env_that_cannot_be_built_is_a_spec_error_naming_it(tmp_path, initial, message, cached):
    # Every seed would fail the same way: a mistake in the spec, raised once, not a failure per seed.
    s = sg.Spec(
        initial,
        pendulum.trees["b"],
        budget=sg.Budget(timesteps=64, eval_episodes=2),
        trainer=sg.SB3(hyperparameters=TINY),
    )
    with pytest.raises(sg.error.InitialEnvError, match=message):
        sg.run_spec(s, workers=2, cache_dir=tmp_path if cached else None, progress=None)


@pytest.mark.slow
@pytest.mark.parametrize("cached", [True, False], ids=["cache", "no cache"])
def test_env_failures_are_one_clean_line_per_seed(tmp_path, cached):
    initial = sg.InitialEnv(lambda: FailsInEvaluation(gym.make("Pendulum-v1")), features=("x", "y", "omega"))
    message = (
        r"Spec 'pendulum', seed {seed}, evaluation episode 0: the environment raised RuntimeError: evaluation broke"
    )
    budget = sg.Budget(timesteps=64, eval_episodes=2, checkpoints=1)
    s = sg.Spec(initial, pendulum.trees["b"], budget=budget, trainer=sg.SB3(hyperparameters=TINY))
    result = sg.run_spec(s, workers=2, cache_dir=tmp_path if cached else None, progress=None)
    assert not result.passed and result.runs == []
    for seed in (0, 1):
        assert re.fullmatch(message.format(seed=seed), result.errors[seed]), result.errors[seed]
        assert "\n" not in result.errors[seed] and "Traceback" not in result.errors[seed]


CLI_SPEC = """
import specguard as sg

pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
tree = sg.All(sg.Goal("position", x=(0.966, 1.0)), sg.Goal("stabilization", omega=(-0.25, 0.25)), name="pendulum")
spec = sg.Spec(
    pendulum, tree, budget=sg.Budget(timesteps={steps}, min_seeds=1, eval_episodes=2),
    trainer=sg.SB3(hyperparameters={{"n_steps": 64, "batch_size": 64, "n_epochs": 1}}),
    expect={{"position": {threshold}}},
)
"""


def _children(pid: int) -> list[int]:
    found = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            fields = dict(line.split(":\t", 1) for line in status.read_text().splitlines() if ":\t" in line)
        except OSError:
            continue
        if fields.get("PPid", "").strip() == str(pid):
            found.append(int(status.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "State:\tZ" not in state


def _cli(spec_file: Path, cache: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "specguard", "run", str(spec_file), "--workers", "1", "--cache-dir", str(cache)],
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )


def _wait_for_line(process: subprocess.Popen[str], needle: str, timeout: float = 60) -> str:
    deadline = time.monotonic() + timeout
    seen = ""
    assert process.stderr is not None
    while time.monotonic() < deadline:
        line = process.stderr.readline()
        seen += line
        if needle in line:
            return seen
        if not line and process.poll() is not None:
            break
    raise AssertionError(f"never saw {needle!r}; stderr so far:\n{seen}")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads child processes from /proc")
def test_sigterm_to_specguard_run_ends_every_worker_promptly_and_stores_nothing(tmp_path):
    spec_file = tmp_path / "long.py"
    # The first progress line comes at 5 000 steps; 0.99 is never met on 2 episodes: no checkpoint stops training.
    spec_file.write_text(CLI_SPEC.format(steps=50_000, threshold=0.99))
    process = _cli(spec_file, tmp_path / "cache")
    try:
        _wait_for_line(process, "root goal")  # a worker is training
        workers = _children(process.pid)
        assert workers
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=15)
    finally:
        process.kill()
    assert process.returncode == 130
    deadline = time.monotonic() + 10
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_alive(w) for w in workers)
    entries = [p for p in (tmp_path / "cache").rglob("result.json")]
    assert entries == []


@pytest.mark.slow
def test_two_processes_asking_for_the_same_run_train_it_once(tmp_path):
    spec_file = tmp_path / "same.py"
    spec_file.write_text(CLI_SPEC.format(steps=6_000, threshold=0.0))  # met: both processes exit 0
    first, second = _cli(spec_file, tmp_path / "cache"), _cli(spec_file, tmp_path / "cache")
    outputs = [p.communicate(timeout=300) for p in (first, second)]
    assert [p.returncode for p in (first, second)] == [0, 0]
    stderr = [err for _, err in outputs]
    assert sum("seed 0: training" in err for err in stderr) == 1, stderr
    assert sum("seed 0: from cache" in err for err in stderr) == 1, stderr
    tables = [out.splitlines()[1:] for out, _ in outputs]  # the first line holds the wall time
    assert tables[0] == tables[1]


# -- safety rates: judged, tabled and serialised like goals ---------------------------------------------------

FAST = sg.Constraint(lambda s, a: abs(s.omega) > 7.5, name="fast")
SAFE_TREE = sg.All(*pendulum.trees["b"].children, name="pendulum").annotate(FAST)


def _safety_result(per_seed, expect):
    from specguard.engine.judging import judge as _judge
    from specguard.engine.spec_result import SpecResult
    from specguard.training.result import RunResult

    s = sg.Spec(pendulum.initial_env, SAFE_TREE, budget=sg.Budget(timesteps=10), expect=expect)
    runs = [
        RunResult(
            spec="pendulum",
            seed=i,
            timesteps=10,
            episodes=30,
            # the safety key first: tables put the goals first whatever the order a run reports
            successes={"pendulum:fast": safe, "pendulum": 30, "pendulum/position": 30, "pendulum/stabilization": 30},
            train_seconds=1.0,
        )
        for i, safe in enumerate(per_seed)
    ]
    result = SpecResult(spec="pendulum", runs=runs, goals={})
    result.goals = _judge(s, runs, 0)
    return result


def test_safety_rates_are_judged_tabled_and_serialised_like_goals():
    result = _safety_result([12, 30], {"fast": 0.8, "pendulum": 0.5})
    crash = result.goals["pendulum:fast"]
    assert crash.runs == ["missed", "met"] and crash.verdict == "failed" and not result.passed
    assert (crash.successes, crash.episodes) == (42, 60) and result.success("pendulum:fast") == (42, 60)
    assert crash.interval[0] < 0.7 < crash.interval[1]
    lines = sg.table(result).splitlines()
    assert [line.split()[0] for line in lines[2:]] == [
        "pendulum",
        "pendulum/position",
        "pendulum/stabilization",
        "pendulum:fast",
    ]
    assert lines[-1].split("  ")[0] == "pendulum:fast (safe)"
    assert lines[-1].split()[2:] == ["70%", "(42/60)", "[0.57,", "0.81]", ">=", "0.8", "1/2", "(need", "2)", "failed"]
    data = json.loads(json.dumps(result.to_dict()))
    assert data["goals"]["pendulum:fast"]["kind"] == "safety" and data["goals"]["pendulum"]["kind"] == "goal"
    assert data["runs"][0]["successes"]["pendulum:fast"] == 12


def test_progress_lines_label_safety_rates():
    from specguard.engine.seeds import Runs as _Runs

    run = _safety_result([12], {"fast": 0.0}).runs[0]
    assert _Runs._rates(run).startswith("pendulum:fast (safe) 12/30, pendulum 30/30")


@pytest.mark.slow
def test_a_safety_threshold_is_asserted_end_to_end(tmp_path):
    # A constraint nothing violates (|omega| <= 8 in Pendulum): its safety rate is 100%, met in both runs.
    never = sg.Constraint(lambda s, a: abs(s.omega) > 8.5, name="never")
    tree = sg.All(*pendulum.trees["b"].children, name="pendulum").annotate(never)
    budget = sg.Budget(timesteps=128, min_seeds=2, max_seeds=4, eval_episodes=4, checkpoints=1)
    s = sg.Spec(
        pendulum.initial_env, tree, budget=budget, expect={"never": 0.3}, quorum=2, trainer=sg.SB3(hyperparameters=TINY)
    )
    result = sg.run_spec(s, workers=2, cache_dir=None, progress=None)
    assert result.passed and result.goals["pendulum:never"].runs == ["met", "met"]
    assert result.success("pendulum:never") == (8, 8)
    *_, row, digests = sg.table(result).splitlines()  # the last row, then each run's weights digest
    assert row.split()[:4] == ["pendulum:never", "(safe)", "100%", "(8/8)"] and digests.startswith("weights seed ")


@pytest.mark.slow
def test_a_script_without_a_main_guard_fails_fast_instead_of_hanging(tmp_path):
    import subprocess
    import sys
    import textwrap

    script = tmp_path / "no_guard.py"
    script.write_text(
        textwrap.dedent(
            f"""
            import specguard as sg
            env = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
            budget = sg.Budget(timesteps=64, min_seeds=1, eval_episodes=1)
            tiny = {{"n_steps": 64, "batch_size": 32, "n_epochs": 1}}
            trainer = sg.SB3(hyperparameters=tiny)
            spec = sg.Spec(env, sg.Goal("up", x=(0.9, 1.0)), budget=budget, trainer=trainer, expect=0.5)
            result = sg.run_spec(spec, workers=1, cache_dir={str(tmp_path / "cache")!r}, progress=None)
            print("errors:", result.errors)
            """
        )
    )
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert 'if __name__ == "__main__":' in done.stderr
    assert "errors: {0:" in done.stdout  # the run failed its seed, reported; nothing waited forever


def test_the_table_lists_each_seeds_adapted_weights():
    result = _safety_result([30, 30], {"fast": 0.8})
    result.runs[1].weights = {"pendulum": [0.75, 0.25]}
    assert sg.table(result).splitlines()[-1] == "seed 1 adapted weights: pendulum (0.75, 0.25)"
    assert "adapted weights" not in sg.table(_safety_result([30], {"fast": 0.8}))


@pytest.mark.slow
def test_a_worker_running_other_code_than_the_key_names_refuses_to_train(tmp_path, monkeypatch):
    # The driver keyed its runs with one specguard; the spawned workers import another (sources edited meanwhile).
    from specguard.cache.versions import versions
    from specguard.engine import seeds as engine

    keyed = {**versions(), "specguard": "0.0.0+edited"}
    monkeypatch.setattr(engine, "versions", lambda: keyed)
    with pytest.raises(
        sg.error.VersionMismatch, match=r"seed \d: .*specguard 0\.0\.0\+edited \(keyed\) != \S+ \(here\)"
    ):
        sg.run_spec(spec(), workers=2, cache_dir=tmp_path, progress=None)
    assert not list(tmp_path.rglob("result.json"))  # nothing stored under a key that does not describe the code


def test_a_worker_whose_loaded_library_is_not_the_installed_one_refuses(monkeypatch):
    # A process forked from a fork server that imported a library before it was upgraded runs the old code, while
    # the installed version (what the key names) is the new one.
    import cloudpickle

    from specguard.cache.versions import check_versions, versions

    keyed = versions()
    check_versions(keyed, "seed 0")  # the loaded libraries are the installed ones
    monkeypatch.setattr(cloudpickle, "__version__", "0.0.1")
    with pytest.raises(
        sg.error.VersionMismatch, match=r"seed 0: .* cloudpickle 0\.0\.1 \(loaded\) != \S+ \(installed\)"
    ):
        check_versions(keyed, "seed 0")


def test_a_local_version_label_alone_is_the_installed_library(monkeypatch):
    # PyPI's torch wheel is installed as 2.13.0 and says 2.13.0+cu130 itself: the same code, not an upgrade.
    import cloudpickle

    from specguard.cache.versions import check_versions, versions

    keyed = versions()
    monkeypatch.setattr(cloudpickle, "__version__", keyed["cloudpickle"] + "+local.build")
    check_versions(keyed, "seed 0")


@pytest.mark.slow
def test_a_worker_with_the_keyed_versions_trains():
    from specguard.cache.versions import versions
    from specguard.engine.worker_task import train_task as _train_task

    native = spec().as_run(numerics="native")  # this process is no worker: its torch has chosen its own kernels
    out = _train_task(native, 0, versions(), report=lambda phase, step=None, line=None: None)
    assert out["result"]["timesteps"] == 128 and out["files"]


class WaitsForAStoredRun(gym.Wrapper):
    """Seed 1's training env (in a worker; the parent's fingerprint probe resets too) blocks until a run is stored."""

    def __init__(self, env, cache):
        super().__init__(env)
        self.cache = Path(cache)

    def reset(self, *, seed=None, options=None):
        if seed == 1 and multiprocessing.parent_process() is not None:
            deadline = time.monotonic() + 120
            while not list(self.cache.rglob("result.json")):
                if time.monotonic() > deadline:
                    raise RuntimeError("seed 0's run was never stored while seed 1 trained")
                time.sleep(0.1)
        return self.env.reset(seed=seed, options=options)


@pytest.mark.slow
def test_a_finished_seed_is_stored_while_the_other_still_trains(tmp_path):
    cache = tmp_path / "cache"
    initial = sg.InitialEnv(lambda: WaitsForAStoredRun(gym.make("Pendulum-v1"), cache), features=("x", "y", "omega"))
    s = sg.Spec(
        initial,
        pendulum.trees["b"],
        budget=sg.Budget(timesteps=128, eval_episodes=2),
        trainer=sg.SB3(hyperparameters=TINY),
    )
    result = sg.run_spec(s, workers=2, cache_dir=cache, progress=None)
    assert result.errors == {} and [r.seed for r in result.runs] == [0, 1]


class _ForgingExecutor:
    """An executor whose 'worker' sends back a result that is not what a run measures."""

    def __init__(self, forge):
        self.forge = forge

    def run(self, tasks, *, on_line=None, stop_on=None, on_outcome=None):
        from specguard.parallel.protocol import Done

        outcomes = {}
        for task in tasks:
            outcome = Done(task.key, {"result": self.forge(task.key), "files": {}})
            outcomes[task.key] = outcome
            if on_outcome is not None:
                on_outcome(task.key, outcome)
        return outcomes

    def close(self):
        pass


@pytest.mark.parametrize(
    "forge",
    [
        lambda seed: None,
        lambda seed: {"seed": seed},
        lambda seed: {
            "spec": "w",
            "seed": seed,
            "timesteps": 10,
            "episodes": 4,
            "successes": {"pendulum": 9},
            "train_seconds": 0.1,
            "hit_wall_clock": False,
            "curve": [],
            "met_early": False,
            "weights": {},
        },
    ],
    ids=["none", "fields missing", "more successes than episodes"],
)
def test_a_malformed_result_from_a_worker_fails_its_seed_and_is_never_stored(tmp_path, forge):
    result = sg.run_spec(
        spec(expect={"pendulum": 0.5}), cache_dir=tmp_path, progress=None, executor=_ForgingExecutor(forge)
    )
    assert result.runs == [] and not result.passed
    assert set(result.errors) == {0, 1}
    assert all("malformed result" in message for message in result.errors.values()), result.errors
    assert not list(tmp_path.rglob("result.json"))


def _a_file_in_the_cache_dirs_place(tmp_path):
    path = tmp_path / "cache"
    path.write_text("not a folder")
    return path


def _a_read_only_cache(tmp_path):
    path = tmp_path / "cache"
    path.mkdir()
    path.chmod(0o555)
    return path


@pytest.mark.slow
@pytest.mark.parametrize("make_cache", [_a_file_in_the_cache_dirs_place, _a_read_only_cache], ids=["file", "read-only"])
def test_a_cache_that_cannot_be_written_warns_once_and_keeps_the_trained_result(tmp_path, make_cache):
    import os

    cache = make_cache(tmp_path)
    if os.geteuid() == 0 and make_cache is _a_read_only_cache:
        pytest.skip("root writes into read-only folders")
    expected = sg.run_spec(spec(expect={"pendulum": 0.95}), workers=2, cache_dir=None, progress=None)
    with pytest.warns(sg.error.CacheWarning) as caught:
        result = sg.run_spec(spec(expect={"pendulum": 0.95}), workers=2, cache_dir=cache, progress=None)
    assert len(caught) == 1 and str(cache) in str(caught[0].message)
    assert [r.successes for r in result.runs] == [r.successes for r in expected.runs] and len(result.runs) == 2
    assert result.passed == expected.passed and not result.errors


@pytest.mark.slow
def test_a_full_disk_warns_with_its_cause_and_keeps_every_run(tmp_path, monkeypatch):
    import errno

    from specguard.cache.store import Cache

    def full(self, key, result, files):
        raise OSError(errno.ENOSPC, "No space left on device", str(self.folder(key)))

    monkeypatch.setattr(Cache, "store_files", full)
    with pytest.warns(sg.error.CacheWarning, match="No space left on device") as caught:
        result = sg.run_spec(spec(expect={"pendulum": 0.95}), workers=2, cache_dir=tmp_path, progress=None)
    assert len(caught) == 1
    assert len(result.runs) == 2 and not result.errors  # both seeds kept, judged


@pytest.mark.slow
def test_a_lock_that_cannot_be_created_warns_and_keeps_every_run(tmp_path, monkeypatch):
    import errno

    from specguard.cache.store import Cache

    def denied(self, key, timeout):
        raise PermissionError(errno.EACCES, "Permission denied", str(self.folder(key).parent / f"{key}.lock"))

    monkeypatch.setattr(Cache, "lock", denied)
    with pytest.warns(sg.error.CacheWarning, match="Permission denied") as caught:
        result = sg.run_spec(spec(expect={"pendulum": 0.95}), workers=2, cache_dir=tmp_path, progress=None)
    assert len(caught) == 1 and len(result.runs) == 2 and not result.errors
