"""A spec's comparisons with a baseline, and the runs a baseline stores, with a stand-in trainer."""

from __future__ import annotations

import specguard as sg
from example_specs import pendulum
from specguard.engine.spec_result import SpecResult
from specguard.gate.baseline import Baseline
from specguard.gate.comparison import baseline_runs, compare_spec, gate_ceiling
from specguard.training.result import RunResult

SPEC = sg.Spec(
    pendulum.initial_env,
    pendulum.trees["b"],
    budget=sg.Budget(timesteps=10, min_seeds=2),
    expect={"pendulum": 0.1, "stabilization": 0.1},
)
PATHS = {"pendulum": "g::pendulum", "pendulum/stabilization": "g::pendulum/stabilization"}


def run(seed, k, n=30):
    return RunResult(
        spec="pendulum",
        seed=seed,
        timesteps=10,
        episodes=n,
        successes={p: k for p, _ in SPEC.tree.walk()},
        train_seconds=1.0,
    )


def trainer(successes, failing=()):
    """Trains seed s to ``successes(s)`` of 30 (a seed in ``failing`` crashes); records the seeds asked for."""
    asked = []

    def train(seeds):
        asked.append(list(seeds))
        result = SpecResult(spec="pendulum", runs=[], goals={})
        for s in seeds:
            if s in failing:
                result.errors[s] = f"seed {s} crashed"
            else:
                result.runs.append(run(s, successes(s)))
        return result

    train.asked = asked
    return train


def own(*counts):
    return SpecResult(spec="pendulum", runs=[run(i, k) for i, k in enumerate(counts)], goals={}, spec_key="new")


def baseline(counts, spec_key="old"):
    return Baseline({key: [(k, 30) for k in counts] for key in PATHS.values()}, dict.fromkeys(PATHS.values(), spec_key))


def test_a_clearly_fine_spec_stops_at_its_own_seeds():
    train = trainer(lambda s: 29)
    gate = compare_spec(SPEC, own(29, 28), baseline([29, 28] * 4), PATHS, level=0.05 / 3, ceiling=8, train=train)
    assert train.asked == [] and {look.state.value for look in gate.looks.values()} == {"fine"}
    assert gate.seeds == [0, 1]


def test_a_drop_trains_more_seeds_until_it_is_flagged():
    train = trainer(lambda s: 10)
    gate = compare_spec(SPEC, own(10, 11), baseline([29, 30] * 4), PATHS, level=0.05 / 15, ceiling=8, train=train)
    assert train.asked == [[2, 3], [4, 5]]  # 2 more at a time, the spec's min_seeds
    assert gate.looks["pendulum"].state.value == "dropped" and gate.looks["pendulum"].seeds == (2, 4, 6)


def test_an_open_comparison_stops_at_the_ceiling():
    counts = [25, 15, 28, 10, 20, 27, 12, 22]
    train = trainer(lambda s: counts[s])
    gate = compare_spec(
        SPEC, own(*counts[:2]), baseline([29, 12, 27, 18] * 2), PATHS, level=0.001, ceiling=6, train=train
    )
    assert train.asked == [[2, 3], [4, 5]] and gate.seeds == [0, 1, 2, 3, 4, 5]
    assert gate.looks["pendulum"].state.value == "open"
    assert (
        gate.looks["pendulum"].describe().endswith("6 seeds vs 8 in the baseline, looks at 2, 4, 6, the most allowed)")
    )


def test_failed_extra_seeds_are_skipped_and_noted():
    train = trainer(lambda s: 10, failing={2, 4})
    gate = compare_spec(SPEC, own(10, 11), baseline([29, 30] * 4), PATHS, level=0.05 / 15, ceiling=8, train=train)
    assert gate.errors == {2: "seed 2 crashed", 4: "seed 4 crashed"}
    assert train.asked[:2] == [[2, 3], [4, 5]] and gate.seeds[:4] == [0, 1, 3, 5]
    train = trainer(lambda s: 10, failing=set(range(2, 10)))
    stuck = compare_spec(SPEC, own(10, 11), baseline([29, 30] * 4), PATHS, level=0.05 / 3, ceiling=8, train=train)
    assert train.asked == [[2, 3]] and stuck.seeds == [0, 1]  # every extra seed failed: no endless retry


def test_the_baselines_own_runs_are_not_compared():
    train = trainer(lambda s: 10)
    stored = baseline([29, 28, 27], spec_key="new")
    stored = Baseline(stored.runs, stored.specs, {key: [0, 1, 2] for key in PATHS.values()})
    gate = compare_spec(SPEC, own(29, 28), stored, PATHS, level=0.05, ceiling=8, train=train)
    assert gate.unchanged and gate.looks == {} and train.asked == []


def test_paths_the_baseline_lacks_are_left_out():
    train = trainer(lambda s: 10)
    gate = compare_spec(SPEC, own(10, 11), Baseline({}, {}), PATHS, level=0.05, ceiling=8, train=train)
    assert gate.looks == {} and train.asked == []


def test_a_baseline_stores_seeds_up_to_the_ceiling():
    train = trainer(lambda s: 20 + s)
    stored = baseline_runs(own(20, 21), ceiling=gate_ceiling(SPEC, 5), train=train)
    assert train.asked == [[2, 3, 4]] and [r.seed for r in stored.runs] == [0, 1, 2, 3, 4]
    big = sg.Spec(pendulum.initial_env, pendulum.trees["b"], budget=sg.Budget(timesteps=10, max_seeds=10), quorum=2)
    assert gate_ceiling(big, 8) == 10 and gate_ceiling(SPEC, 8) == 8
    train = trainer(lambda s: 20)
    assert baseline_runs(own(20, 21), ceiling=2, train=train).seeds == [0, 1] and train.asked == []
