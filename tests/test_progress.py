"""Progress events: their one-line layout, and how `pytest --goal-specs` and the engine deliver them."""

from __future__ import annotations

import re

import pytest
from test_plugin import run, write

import specguard as sg
from example_specs import pendulum
from specguard.training.progress import ProgressEvent, decode_update, encode_update, format_duration, format_event

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}

# Every line a run prints, whole: a prefix naming one spec and one seed, then one event's text.
LINE = re.compile(
    r"\[specguard\] (?P<spec>[\w/.-]+) seed (?P<seed>\d+): "
    r"(training, \d+ steps"
    r"| *\d+/\d+ steps +\d+% \| \d+(s|m\d\ds) elapsed, ~\d+(s|m\d\ds) left"
    r" \| root goal( \d+% of \d+ episodes|: no episode finished yet)"
    r"|done, \d+/\d+ steps in \d+s \| root goal \d+% of \d+ episodes \| [\w/ ,]+"
    r"|from cache \| root goal \d+% of \d+ episodes \| [\w/ ,]+"
    r"|failed: .+)"
)


def update(steps: int, elapsed: float, success: float | None = 0.42, budget: int = 50_000) -> ProgressEvent:
    return ProgressEvent(
        "pendulum", 3, "update", steps=steps, budget=budget, elapsed_s=elapsed, success=success, episodes=17
    )


def test_update_line_has_steps_elapsed_eta_and_success():
    assert format_event(update(5_000, 12.0)) == (
        "[specguard] pendulum seed 3:  5000/50000 steps  10% | 12s elapsed, ~1m48s left | root goal 42% of 17 episodes"
    )


def test_eta_comes_from_the_rate_so_far():
    assert update(10_000, 30.0).eta_s == pytest.approx(120.0)
    assert update(50_000, 30.0).eta_s == 0.0
    assert update(0, 0.0).eta_s is None  # no rate yet
    assert "~2m00s left" in format_event(update(10_000, 30.0))
    assert "~1h00m left" in format_event(update(1, 1.0, budget=3601))


def test_update_without_a_finished_episode():
    assert format_event(update(5_000, 2.0, success=None)).endswith("| root goal: no episode finished yet")


def test_layout_is_fixed_width_across_a_run():
    lines = [format_event(update(s, s / 1000)) for s in range(5_000, 50_001, 5_000)]
    assert len({line.index(" steps") for line in lines}) == 1  # steps right-aligned to the budget's width
    assert len({line.index(" | ") for line in lines}) == 1
    assert all(LINE.fullmatch(line) for line in lines)


@pytest.mark.parametrize(
    ("event", "text"),
    [
        (ProgressEvent("p", 0, "start", budget=256), "[specguard] p seed 0: training, 256 steps"),
        (
            ProgressEvent(
                "p", 1, "done", steps=256, budget=256, elapsed_s=3.4, success=0.75, episodes=4, message="p 3/4"
            ),
            "[specguard] p seed 1: done, 256/256 steps in 3s | root goal 75% of 4 episodes | p 3/4",
        ),
        (
            ProgressEvent("p", 2, "cached", success=0.5, episodes=4, message="p 2/4"),
            "[specguard] p seed 2: from cache | root goal 50% of 4 episodes | p 2/4",
        ),
        (
            ProgressEvent("p", 3, "failed", message="seed 3, training step 7: boom\nmore"),
            "[specguard] p seed 3: failed: seed 3, training step 7: boom more",
        ),
        (ProgressEvent("p", 4, "waiting"), "[specguard] p seed 4: being trained by another process; waiting"),
    ],
)
def test_each_kind_is_one_line(event, text):
    assert format_event(event) == str(event) == text
    assert "\n" not in text
    assert "seed" in event  # sinks that collect events search them like lines


def test_format_duration():
    assert [format_duration(s) for s in (0, 59.4, 60, 125, 3599, 3600, 3725)] == [
        "0s", "59s", "1m00s", "2m05s", "59m59s", "1h00m", "1h02m",
    ]  # fmt: skip


def test_a_workers_update_round_trips_and_foreign_lines_pass_through():
    event = decode_update("p", 2, encode_update(500, 1000, 7.25, 0.5, 8))
    assert event == ProgressEvent("p", 2, "update", steps=500, budget=1000, elapsed_s=7.25, success=0.5, episodes=8)
    assert decode_update("p", 2, encode_update(500, 1000, 7.25, None, 0)).success is None
    assert format_event(decode_update("p", 2, "hello")) == "[specguard] p seed 2: hello"


@pytest.mark.slow
def test_two_seeds_lines_never_share_a_line(tmp_path):
    budget = sg.Budget(timesteps=640, min_seeds=2, eval_episodes=2)
    spec = sg.Spec(pendulum.initial_env, pendulum.trees["b"], budget=budget, trainer=sg.SB3(hyperparameters=TINY))
    events: list[ProgressEvent] = []
    sg.run_spec(spec, workers=2, cache_dir=tmp_path, progress=events.append)
    lines = [format_event(e) for e in events]
    assert all(LINE.fullmatch(line) for line in lines), lines
    for seed in (0, 1):
        kinds = [e.kind for e in events if e.seed == seed]
        assert kinds == ["start", *["update"] * 10, "done"], kinds
        steps = [e.steps for e in events if e.seed == seed and e.kind == "update"]
        assert steps == sorted(steps) and steps[-1] == 640
    again: list[ProgressEvent] = []
    sg.run_spec(spec, workers=2, cache_dir=tmp_path, progress=again.append)
    assert [(e.seed, e.kind) for e in again] == [(0, "cached"), (1, "cached")]
    assert all(LINE.fullmatch(str(e)) for e in again)


ONE_SPEC = """
@sg.goal_spec(expect={"stabilization": 0.0})
def test_tiny(pendulum, tree):
    return tiny(pendulum, tree, seeds=2)
"""

DONE = re.compile(
    r"\[specguard\] pendulum seed (\d): done, \d+/128 steps in \d+s \| root goal \d+% of 4 episodes \| .+"
)


def test_pytest_goal_specs_shows_one_line_per_finished_run_without_dash_s(pytester):
    write(pytester, ONE_SPEC)
    result = run(pytester, "--goal-specs")  # not a tty: no per-update lines, one per finished run
    result.assert_outcomes(passed=1)
    lines = [line for line in result.outlines if "[specguard]" in line]
    assert len(lines) == 2, result.outlines
    assert sorted(DONE.fullmatch(line).group(1) for line in lines) == ["0", "1"]  # type: ignore[union-attr]
    assert "[specguard]" not in result.stderr.str()


def test_pytest_goal_specs_is_quiet_under_dash_q(pytester):
    write(pytester, ONE_SPEC)
    result = run(pytester, "--goal-specs", "-q")
    result.assert_outcomes(passed=1)
    assert "[specguard]" not in result.stdout.str() + result.stderr.str()
