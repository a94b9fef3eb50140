"""Anytime verdicts: the looks' correction, checked by simulating runs with a known success probability."""

from __future__ import annotations

import numpy as np
import pytest

from specguard.spec.budget import Budget
from specguard.stats.anytime import (
    checkpoint_steps,
    evaluation_stages,
    final_evaluation,
    interim_look,
    look_confidence,
    looks,
    met,
    min_successes_to_meet,
)
from specguard.stats.intervals import success_interval


def test_stages_double_up_to_the_maximum():
    assert evaluation_stages(30, 120) == [30, 60, 120]
    assert evaluation_stages(30, 100) == [30, 60, 100]
    assert evaluation_stages(30, 30) == [30]
    assert Budget(timesteps=10, eval_episodes=30, checkpoints=1).looks == 3  # the final evaluation's stages alone
    assert Budget(timesteps=10, eval_episodes=30).looks == 12  # by default, 9 interim checkpoints too
    assert Budget(timesteps=10, eval_episodes=30, checkpoints=10).looks == 12


def test_checkpoints_split_the_budget_and_leave_the_end_to_the_final_evaluation():
    assert checkpoint_steps(1000, 1) == []
    assert checkpoint_steps(1000, 10) == list(range(100, 1000, 100))
    assert checkpoint_steps(10, 3) == [4, 7]


def test_min_successes_is_the_first_count_whose_interval_clears_the_threshold():
    for n, t, c in [(30, 0.8, 0.95), (30, 0.05, 0.99583), (60, 0.5, 0.99), (30, 0.99, 0.95)]:
        k = min_successes_to_meet(n, t, c)
        if k <= n:
            assert success_interval(k, n, c)[0] >= t
        if k > 0:
            assert success_interval(k - 1, n, c)[0] < t


def counter(outcomes):
    """An evaluator replaying fixed per-episode outcomes ``{key: [0/1, ...]}``; records what it was asked."""
    asked = []

    def evaluate(start, count):
        asked.append((start, count))
        return {key: int(sum(v[start : start + count])) for key, v in outcomes.items()}

    evaluate.asked = asked
    return evaluate


def test_an_interim_look_stops_evaluating_once_a_pass_is_out_of_reach():
    evaluate = counter({"g": [1, 0] + [1] * 28})
    counts, episodes, ok = interim_look(evaluate, 30, {"g": 0.8}, 0.95)  # a pass needs 29 of 30
    assert (ok, episodes) == (True, 30)
    evaluate = counter({"g": [1, 0, 0] + [1] * 27})
    counts, episodes, ok = interim_look(evaluate, 30, {"g": 0.8}, 0.95)
    assert (ok, episodes, counts) == (False, 3, {"g": 1})  # the second miss decides it: 27 more cannot make 29


def test_an_interim_look_needs_every_threshold():
    outcomes = {"a": [1] * 30, "b": [1] * 10 + [0] * 20}
    assert interim_look(counter(outcomes), 30, {"a": 0.8}, 0.95)[2]
    assert not interim_look(counter(outcomes), 30, {"a": 0.8, "b": 0.8}, 0.95)[2]
    assert met({"a": 30, "b": 10}, 30, {"a": 0.8, "b": 0.1}, 0.95)


def test_the_final_evaluation_extends_only_while_undecided():
    decided = counter({"g": [1] * 120})
    assert final_evaluation(decided, [30, 60, 120], {"g": 0.8}, 0.95) == ({"g": 30}, 30)
    close = counter({"g": ([1] * 9 + [0]) * 12})  # 90%: undecided against 0.85 at 30 and 60 episodes
    counts, episodes = final_evaluation(close, [30, 60, 120], {"g": 0.85}, 0.95)
    assert (counts, episodes) == ({"g": 108}, 120) and close.asked == [(0, 30), (30, 30), (60, 60)]


# -- the promise: at most (1 - confidence) / 2 false passes over every look -------------------------------------

RUNS = 10_000
CONFIDENCE = 0.95
PROMISE = (1 - CONFIDENCE) / 2


def false_pass_rate(p, threshold, checkpoints, confidence, *, seed=0, eval_episodes=30, max_eval_episodes=120):
    """Simulate ``RUNS`` runs whose every episode succeeds with probability ``p``, judged as train_run judges them.

    Each look draws fresh episodes. Returns the share of runs called met at
    any interim checkpoint or by the final evaluation.
    """
    rng = np.random.default_rng(seed)
    stages = evaluation_stages(eval_episodes, max_eval_episodes)
    passed = 0
    for _ in range(RUNS):

        def evaluate(start, count):
            return {"g": int(rng.binomial(count, p))}

        if any(interim_look(evaluate, eval_episodes, {"g": threshold}, confidence)[2] for _ in range(checkpoints - 1)):
            passed += 1
            continue
        counts, episodes = final_evaluation(evaluate, stages, {"g": threshold}, confidence)
        passed += met(counts, episodes, {"g": threshold}, confidence)
    return passed / RUNS


@pytest.mark.parametrize("threshold", [0.05, 0.5, 0.8])
def test_corrected_looks_keep_the_false_pass_rate_of_one_look(threshold):
    corrected = look_confidence(CONFIDENCE, looks(10, len(evaluation_stages(30, 120))))
    rate = false_pass_rate(threshold, threshold, checkpoints=10, confidence=corrected)
    assert rate <= PROMISE, f"{rate:.4f} of {RUNS} runs at p = threshold = {threshold} passed"


def test_uncorrected_looks_break_the_promise():
    """The same simulation without the correction: the check above is one that can fail."""
    rate = false_pass_rate(0.5, 0.5, checkpoints=10, confidence=CONFIDENCE)
    assert rate > PROMISE, f"{rate:.4f}"
