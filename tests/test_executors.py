"""Executors: the local pool and a real local Dask cluster give the same figures; failures stay per seed."""

from __future__ import annotations

import os
import signal

import gymnasium as gym
import pytest

import specguard as sg
from example_specs import pendulum
from specguard.cache.store import Cache
from specguard.parallel.executors import DaskExecutor, ExecutorError, LocalExecutor, check_address, make_executor
from specguard.utils.numerics import portable_environ

distributed = pytest.importorskip("distributed")

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
DRIVER = "SPECGUARD_TEST_DRIVER_PID"


def spec(initial=None, **kwargs):
    kwargs.setdefault("budget", sg.Budget(timesteps=256, min_seeds=2, eval_episodes=3, checkpoints=1))
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=TINY))
    return sg.Spec(
        initial or pendulum.initial_env,
        pendulum.trees["b"],
        expect={"stabilization": 0.0},
        **kwargs,
    )


@pytest.fixture(scope="module")
def cluster():
    """A real two-worker Dask cluster on this machine (one thread per worker, as on a real cluster)."""
    import dask

    os.environ[DRIVER] = str(os.getpid())  # the workers inherit it: they kill themselves, never the driver
    # Portable numerics on a cluster: its workers start with the settings (a worker without them is refused).
    before = dict(os.environ)
    os.environ.update(portable_environ(os.environ))
    # Fail a seed at the first dead worker (the default retries it on up to 3 more workers first).
    try:
        with (
            dask.config.set({"distributed.scheduler.allowed-failures": 0}),
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as c,
        ):
            yield c
    finally:
        os.environ.clear()
        os.environ.update({**before, DRIVER: str(os.getpid())})


@pytest.mark.parametrize(
    ("text", "ok"),
    [
        ("local", True),
        ("tcp://127.0.0.1:8786", True),
        ("tls://scheduler.example:8786", True),
        ("  local ", True),
        ("dask", False),
        ("127.0.0.1:8786", False),
        ("http://127.0.0.1:8786", False),
        ("tcp://", False),
        (3, False),
    ],
)
def test_check_address(text, ok):
    if ok:
        assert check_address(text) == text.strip()
    else:
        with pytest.raises(ExecutorError, match=r"executor: expected 'local' or a Dask scheduler address"):
            check_address(text)


def test_local_is_the_process_pool():
    executor = make_executor("local", workers=3)
    assert isinstance(executor, LocalExecutor) and executor.workers == 3


def test_an_address_nobody_answers_fails_before_anything_trains():
    with pytest.raises(ExecutorError, match=r"executor 'tcp://127.0.0.1:9': no Dask scheduler answered within 1 s"):
        DaskExecutor("tcp://127.0.0.1:9", timeout=1)


@pytest.mark.slow
def test_the_cluster_gives_the_local_pools_figures_and_a_warm_cache_submits_nothing(cluster, tmp_path):
    s = spec()
    local = sg.run_spec(s, workers=2, cache_dir=None, progress=None)
    lines: list[str] = []
    executor = DaskExecutor(cluster.scheduler_address)
    try:
        remote = sg.run_spec(s, executor=executor, cache_dir=tmp_path, progress=lines.append)
        assert executor.submitted == 2
        assert [r.to_dict() | {"train_seconds": 0} for r in remote.runs] == [
            r.to_dict() | {"train_seconds": 0} for r in local.runs
        ]
        assert remote.passed and remote.cached == {0: False, 1: False}
        assert any("seed 1: " in line and "/256 steps" in line for line in lines)  # live progress from the workers
        # The driver stored what came back: the next run is served from its own cache.
        again = sg.run_spec(s, executor=executor, cache_dir=tmp_path, progress=None)
        assert executor.submitted == 2 and again.cached == {0: True, 1: True}
        assert Cache(tmp_path).load(s, 1) == remote.runs[1]
    finally:
        executor.close()


class KilledOnSeed(gym.Wrapper):
    """SIGKILLs the cluster worker on the 50th step of the run with seed 1."""

    def reset(self, *, seed=None, options=None):
        if seed is not None:
            self.first_seed = seed
        self.steps = 0
        return self.env.reset(seed=seed, options=options)

    def step(self, action):
        self.steps += 1
        in_worker = str(os.getpid()) != os.environ.get(DRIVER)
        if in_worker and getattr(self, "first_seed", None) == 1 and self.steps == 50:
            os.kill(os.getpid(), signal.SIGKILL)
        return self.env.step(action)


def make_killed():
    return KilledOnSeed(gym.make("Pendulum-v1"))


@pytest.mark.slow
def test_a_cluster_worker_killed_mid_run_fails_one_seed(cluster, tmp_path):
    s = spec(initial=sg.InitialEnv(make_killed, features=("x", "y", "omega")))
    result = sg.run_spec(s, executor=cluster.scheduler_address, cache_dir=tmp_path, progress=None)
    assert [r.seed for r in result.runs] == [0]
    assert result.errors[1].startswith("seed 1, training step ")
    assert "cluster worker failed (KilledWorker" in result.errors[1]
    assert Cache(tmp_path).load(s, 0) == result.runs[0]


class FailsInEvaluation(gym.Wrapper):
    def reset(self, *, seed=None, options=None):
        if seed is not None and seed >= 1_000_000:
            raise RuntimeError("evaluation broke")
        return self.env.reset(seed=seed, options=options)


def make_failing_evaluation():
    return FailsInEvaluation(gym.make("Pendulum-v1"))


@pytest.mark.slow
def test_errors_on_the_cluster_are_the_same_one_line_per_seed(cluster):
    s = spec(initial=sg.InitialEnv(make_failing_evaluation, features=("x", "y", "omega")))
    result = sg.run_spec(s, executor=cluster.scheduler_address, cache_dir=None, progress=None)
    assert result.errors == {
        seed: f"Spec 'pendulum', seed {seed}, evaluation episode 0: the environment raised RuntimeError: "
        "evaluation broke"
        for seed in (0, 1)
    }


@pytest.mark.slow
def test_spec_errors_found_on_the_cluster_reach_the_caller(cluster):
    with pytest.raises(
        sg.error.InvalidSpec, match=r"Spec 'pendulum'.trainer.algorithm: DQN cannot act in a Box action space"
    ):
        dqn = spec(trainer=sg.SB3(algorithm="DQN", hyperparameters={}))
        sg.run_spec(dqn, executor=cluster.scheduler_address, cache_dir=None, progress=None)


GOAL_SPEC = """
import specguard as sg


@sg.goal_spec(expect={"stabilization": 0.0})
def test_on_the_cluster():
    pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    tree = sg.All(sg.Goal("position", x=(0.966, 1.0)), sg.Goal("stabilization", omega=(-0.25, 0.25)), name="pendulum")
    budget = sg.Budget(timesteps=128, min_seeds=2, eval_episodes=2)
    tiny = sg.SB3(hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1})
    return sg.Spec(pendulum, tree, budget=budget, trainer=tiny)
"""


def test_pytest_goal_specs_runs_on_the_cluster(cluster, pytester):
    pytester.makepyfile(test_specs=GOAL_SPEC)
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", "--goal-specs", f"--goal-specs-executor={cluster.scheduler_address}"
    )
    result.assert_outcomes(passed=1)
    result.stdout.fnmatch_lines(["test_specs.py::test_on_the_cluster*pendulum/stabilization*2/2*passed*"])


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("bogus", "*--goal-specs-executor: expected 'local' or a Dask scheduler address*got 'bogus'*"),
        ("tcp://127.0.0.1:9", "*--goal-specs-executor: executor 'tcp://127.0.0.1:9': no Dask scheduler answered*"),
    ],
)
def test_a_bad_executor_is_a_usage_error_before_anything_trains(pytester, address, message):
    pytester.makepyfile(test_specs=GOAL_SPEC)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--goal-specs", f"--goal-specs-executor={address}")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines([message])


@pytest.mark.slow
def test_specguard_run_takes_an_executor(cluster, tmp_path, capsys):
    from specguard.cli.main import main

    path = tmp_path / "specs.py"
    path.write_text(
        GOAL_SPEC.replace('@sg.goal_spec(expect={"stabilization": 0.0})\ndef test_on_the_cluster():', "def make():")
        + '\nimport dataclasses\n\nspec = dataclasses.replace(make(), expect={"stabilization": 0.0})\n'
    )
    assert main(["run", str(path), "--executor", cluster.scheduler_address, "--cache-dir", str(tmp_path / "c")]) == 0
    assert "== spec: passed" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exit_info:
        main(["run", str(path), "--executor", "127.0.0.1:8786"])
    assert exit_info.value.code == 2
    assert "argument --executor: expected 'local' or a Dask scheduler address" in capsys.readouterr().err
