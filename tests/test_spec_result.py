"""A spec result is plain data: ``to_dict`` round-trips, and every word it reports comes from one vocabulary.

``SpecResult.from_dict(r.to_dict())`` equals ``r`` in everything it reports (goals, their successes,
episodes, intervals and verdicts, ``passed``, the status, the notes and the table), for results drawn by
Hypothesis over runs, thresholds, quorums, crashed seeds, ``undecided`` and ``xfail``.
"""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

import specguard as sg
from specguard.engine.judging import judged
from specguard.engine.spec_result import GoalVerdict, SpecResult
from specguard.stats.intervals import quorum_verdict, run_verdict, success_interval
from specguard.stats.verdicts import (
    COUNTED,
    UNDECIDED_OUTCOMES,
    VERDICT_WORDS,
    GoalOutcome,
    QuorumVerdict,
    RunVerdict,
    Word,
    counted,
    goal_outcome,
    spec_word,
    verdict_word,
)
from specguard.training.result import RunResult

KEYS = ("root", "root/a", "root/b", "root:safe")


@st.composite
def spec_results(draw: st.DrawFn) -> SpecResult:
    """A result as ``run_spec`` makes one: runs over ``KEYS``, some keys thresholded and judged, maybe crashes."""
    n_runs = draw(st.integers(0, 3))
    crashed = draw(st.lists(st.integers(n_runs, 6), unique=True, max_size=2))
    runs = []
    for seed in range(n_runs):
        episodes = draw(st.integers(1, 30))
        runs.append(
            RunResult(
                spec="s",
                seed=seed,
                timesteps=draw(st.integers(0, 10_000)),
                episodes=episodes,
                successes={k: draw(st.integers(0, episodes)) for k in KEYS},
                train_seconds=draw(st.floats(0, 100)),
                met_early=draw(st.booleans()),
                started_in_goal=draw(st.integers(0, episodes)),
                weights=draw(st.sampled_from([{}, {"root": [0.25, 0.75]}])),
            )
        )
    thresholds = draw(st.dictionaries(st.sampled_from(KEYS), st.floats(0.05, 0.95), max_size=len(KEYS)))
    required = draw(st.integers(1, 3))
    goals = {}
    for path, threshold in thresholds.items():
        verdicts = [run_verdict(r.successes[path], r.episodes, threshold) for r in runs]
        k, n = sum(r.successes[path] for r in runs), sum(r.episodes for r in runs)
        goals[path] = GoalVerdict(
            path=path,
            threshold=threshold,
            required=required,
            runs=verdicts,
            verdict=quorum_verdict(verdicts + [RunVerdict.MISSED] * len(crashed), required, 6),
            successes=k,
            episodes=n,
            interval=success_interval(k, n) if n else (0.0, 1.0),
        )
    return SpecResult(
        spec="s",
        runs=runs,
        goals=goals,
        errors={seed: f"seed {seed}: the worker died" for seed in crashed},
        tracebacks={seed: "Traceback ..." for seed in crashed[:1]},
        cached={r.seed: draw(st.booleans()) for r in runs},
        seconds=draw(st.floats(0, 1e4)),
        spec_key=draw(st.none() | st.just("3f2a")),
        undecided=draw(st.sampled_from(UNDECIDED_OUTCOMES)),
        xfail={p: "the paper's local optimum" for p in goals if draw(st.booleans())},
        notes=draw(st.lists(st.sampled_from(["3 of 30 evaluation episodes started inside the root goal 'root'"]))),
        agent=draw(st.none() | st.just("PPO (ppo-CartPole-v1.zip)")),
    )


@given(spec_results())
def test_to_dict_round_trips_everything_a_result_reports(result: SpecResult):
    data = json.loads(json.dumps(result.to_dict()))
    back = SpecResult.from_dict(data)
    assert back == result
    assert back.passed is result.passed and back.as_expected is result.as_expected
    assert back.status() == result.status()
    for path, goal in result.goals.items():
        assert (back.goals[path].successes, back.goals[path].episodes) == (goal.successes, goal.episodes)
        assert back.goals[path].interval == goal.interval
        assert back.goals[path].verdict is goal.verdict and back.goals[path].runs == goal.runs
        assert back.word(path) is result.word(path)
        assert data["goals"][path]["word"] == result.word(path) and data["goals"][path]["outcome"] == result.outcome(
            path
        )
    assert back.notes == result.notes
    assert sg.table(back) == sg.table(result)


@given(spec_results())
def test_a_result_reports_only_the_vocabularys_words(result: SpecResult):
    for path in result.goals:
        assert result.counted(path) in COUNTED
        assert result.word(path) in VERDICT_WORDS
    assert result.status() in {"FAILED", *VERDICT_WORDS} or result.status().startswith("undecided, counted as ")
    assert result.passed is (not result.errors and all(result.counted(p) is Word.PASSED for p in result.goals))


def test_a_result_read_back_is_judged_by_what_it_recorded_not_by_a_spec():
    spec = sg.Spec(
        sg.InitialEnv("Pendulum-v1", features=("x",)),
        sg.Goal("up", x=(0.9, 1.0)),
        budget=sg.Budget(timesteps=64, min_seeds=1, max_seeds=1),
        expect=0.5,
        xfail=["up"],
        undecided="pass",
    )
    runs = [RunResult(spec="up", seed=0, timesteps=64, episodes=30, successes={"up": 2}, train_seconds=1.0)]
    result = judged(spec, runs)
    assert (result.undecided, result.xfail) == ("pass", {"up": "expected to miss its threshold"})
    back = SpecResult.from_dict(result.to_dict())
    assert back.trained is None and back.word("up") is Word.XFAILED and back.as_expected
    with pytest.raises(sg.SpecError, match="no model kept for seed 0") as e:
        sg.load_model(back, 0)
    assert "trained=spec" in e.value.hint


def test_from_dict_names_what_is_malformed():
    with pytest.raises(ValueError, match=r"needs goals, runs, got the fields \['spec'\]"):
        SpecResult.from_dict({"spec": "s"})
    with pytest.raises(ValueError, match="run seed 0: episodes 0 is not an integer >= 1"):
        run = RunResult(spec="s", seed=0, timesteps=1, episodes=1, successes={"g": 1}, train_seconds=0.0).to_dict()
        SpecResult.from_dict({"spec": "s", "runs": [{**run, "episodes": 0}], "goals": {}})
    lacks = "lacks episodes, interval, required, runs, successes, threshold, verdict"
    with pytest.raises(ValueError, match=f"goal verdict 'g' {lacks}"):
        SpecResult.from_dict({"spec": "s", "runs": [], "goals": {"g": {"path": "g"}}})
    with pytest.raises(ValueError, match=r"expected undecided to be one of .*, got 'maybe'"):
        SpecResult(spec="s", runs=[], goals={}, undecided="maybe")


@pytest.mark.parametrize(
    ("verdict", "runs", "crashed", "outcome"),
    [
        (QuorumVerdict.PASSED, [RunVerdict.MET], True, GoalOutcome.PASSED),
        (QuorumVerdict.FAILED, [RunVerdict.UNDECIDED, RunVerdict.MET], False, GoalOutcome.UNDECIDED),
        (QuorumVerdict.FAILED, [RunVerdict.UNDECIDED], True, GoalOutcome.FAILED),  # a crash is no undecided run
        (QuorumVerdict.FAILED, [RunVerdict.UNDECIDED, RunVerdict.MISSED], False, GoalOutcome.FAILED),
        (QuorumVerdict.FAILED, [], False, GoalOutcome.FAILED),  # no run at all decided nothing
    ],
)
def test_goal_outcome(verdict, runs, crashed, outcome):
    assert goal_outcome(verdict, runs, crashed=crashed) is outcome


@pytest.mark.parametrize(
    ("outcome", "crashed", "undecided_as", "expected_miss", "counts_as"),
    [
        (GoalOutcome.PASSED, True, "fail", True, Word.PASSED),
        (GoalOutcome.FAILED, False, "pass", False, Word.FAILED),  # undecided="pass" passes undecided goals only
        (GoalOutcome.FAILED, False, "fail", True, Word.XFAILED),
        (GoalOutcome.FAILED, True, "xfail", True, Word.FAILED),  # a crash is not the miss xfail expects
        (GoalOutcome.UNDECIDED, False, "fail", False, Word.FAILED),
        (GoalOutcome.UNDECIDED, False, "xfail", False, Word.XFAILED),
        (GoalOutcome.UNDECIDED, False, "pass", True, Word.PASSED),  # then xpassed, as pytest says
        (GoalOutcome.UNDECIDED, False, "fail", True, Word.XFAILED),
    ],
)
def test_counted(outcome, crashed, undecided_as, expected_miss, counts_as):
    assert counted(outcome, crashed=crashed, undecided_as=undecided_as, expected_miss=expected_miss) is counts_as


def test_counted_and_verdict_word_refuse_words_outside_the_vocabulary():
    with pytest.raises(ValueError, match=r"expected undecided_as to be one of \('fail', 'xfail', 'pass'\), got 'x'"):
        counted(GoalOutcome.UNDECIDED, crashed=False, undecided_as="x")
    with pytest.raises(ValueError, match=r"expected counts_as to be one of .*, got 'xpassed'"):
        verdict_word("xpassed", "passed")


def test_spec_word_is_the_worst_goal_word():
    assert spec_word([Word.PASSED, Word.XPASSED, Word.XFAILED], crashed=False) == "xfailed"
    assert spec_word([Word.XFAILED, Word.FAILED], crashed=False) == "FAILED"
    assert spec_word([], crashed=False) == "passed"
    assert (
        spec_word([Word.UNDECIDED], crashed=False, undecided_counts_as=Word.XFAILED) == "undecided, counted as xfailed"
    )


def _stored() -> dict:
    run = RunResult(spec="s", seed=0, timesteps=1, episodes=10, successes={"g": 9}, train_seconds=0.0)
    goal = GoalVerdict("g", 0.5, 1, [RunVerdict.MET], QuorumVerdict.PASSED, 9, 10, (0.555, 0.997))
    return json.loads(json.dumps(SpecResult(spec="s", runs=[run], goals={"g": goal}, cached={0: True}).to_dict()))


def _damaged(path: tuple, value: object) -> dict:
    data = _stored()
    where = data
    for key in path[:-1]:
        where = where[key]
    if value is KeyError:
        del where[path[-1]]
    else:
        where[path[-1]] = value
    return data


@pytest.mark.parametrize(
    ("path", "value", "culprit"),
    [
        (("spec",), 3, "spec 3"),
        (("runs",), 5, "runs 5"),
        (("runs",), {"0": {}}, "runs {'0': {}}"),
        (("goals",), ["g"], "goals ['g']"),
        (("goals", "g"), "passed", "goal verdict 'g': expected an object, got 'passed'"),
        (("goals", "g", "interval"), 0.5, "goal verdict 'g': interval 0.5"),
        (("goals", "g", "interval"), [0.1, "x"], "goal verdict 'g': interval [0.1, 'x']"),
        (("goals", "g", "runs"), None, "goal verdict 'g': runs None"),
        (("goals", "g", "runs"), ["met", "maybe"], "goal verdict 'g': runs ['met', 'maybe']"),
        (("goals", "g", "verdict"), "won", "goal verdict 'g': verdict 'won'"),
        (("goals", "g", "threshold"), "0.5", "goal verdict 'g': threshold '0.5'"),
        (("goals", "g", "required"), 1.5, "goal verdict 'g': required 1.5"),
        (("goals", "g", "successes"), None, "goal verdict 'g': successes None"),
        (("goals", "g", "episodes"), "10", "goal verdict 'g': episodes '10'"),
        (("goals", "g", "path"), 7, "goal verdict 7: path 7 is not a string"),
        (("errors",), ["seed 0 died"], "errors ['seed 0 died']"),
        (("errors",), {"zero": "died"}, "errors {'zero': 'died'}"),
        (("tracebacks",), {"0": 1}, "tracebacks {'0': 1}"),
        (("cached",), {"0": "yes"}, "cached {'0': 'yes'}"),
        (("cached",), 1, "cached 1"),
        (("seconds",), "1s", "seconds '1s'"),
        (("confidence",), None, "confidence None"),
        (("spec_key",), 5, "spec_key 5"),
        (("xfail",), 5, "xfail 5"),
        (("xfail",), {"g": None}, "xfail {'g': None}"),
        (("notes",), 5, "notes 5"),
        (("notes",), "a note", "notes 'a note'"),
        (("agent",), ["PPO"], "agent ['PPO']"),
        (("undecided",), 3, "undecided"),
    ],
)
def test_from_dict_on_damaged_data_is_one_value_error_naming_the_field(path, value, culprit):
    with pytest.raises(ValueError) as info:
        SpecResult.from_dict(_damaged(path, value))
    assert type(info.value) is ValueError  # not a raw KeyError, TypeError or AttributeError
    message = str(info.value)
    assert "\n" not in message and message.startswith("spec result ") and culprit in message, message


@pytest.mark.parametrize("data", [None, [], "result", 3, {"spec": "s", "runs": [], "goals": {"g": None}}])
def test_from_dict_on_no_object_is_one_value_error(data):
    with pytest.raises(ValueError) as info:
        SpecResult.from_dict(data)
    assert type(info.value) is ValueError and "\n" not in str(info.value)


def test_from_dict_still_reads_what_to_dict_wrote_and_the_optional_fields_may_be_absent():
    assert SpecResult.from_dict(_stored()).goals["g"].interval == (0.555, 0.997)
    bare = {k: v for k, v in _stored().items() if k in ("spec", "runs", "goals")}
    assert SpecResult.from_dict(bare).cached == {}
