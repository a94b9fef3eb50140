"""Holm's procedure over a session's comparisons."""

from __future__ import annotations

import numpy as np
import pytest

from specguard.stats.family import first_level, holm, holm_rejections, procedure_text


def test_holm_steps_down_and_stops_at_the_first_miss():
    assert holm({"a": 0.001, "b": 0.02, "c": 0.04}, 0.05) == {"a": 1, "b": 2, "c": 3}
    assert holm({"a": 0.001, "b": 0.04, "c": 0.03}, 0.05) == {"a": 1, "b": None, "c": None}
    assert holm({"a": 0.02, "b": 0.001}, 0.05) == {"a": 2, "b": 1}  # 0.02 <= 0.05 / 1 at the second step
    assert holm({"a": 0.03, "b": 0.03}, 0.05) == {"a": None, "b": None}  # 0.03 > 0.05 / 2
    assert holm({}, 0.05) == {}


def test_its_first_step_is_bonferronis_level():
    assert first_level(0.05, 15) == pytest.approx(0.05 / 15)
    p = {f"g{i}": 0.5 for i in range(14)} | {"hit": 0.05 / 15}
    assert holm(p, 0.05)["hit"] == 1  # at the first step's level, whatever the others
    with pytest.raises(ValueError, match="at least one comparison"):
        first_level(0.05, 0)


def test_the_vectorised_procedure_is_the_same_as_the_one_by_name():
    rng = np.random.default_rng(0)
    p = rng.random((200, 6)) ** 3
    rejected = holm_rejections(p, 0.05)
    for row, flags in zip(p, rejected):
        named = holm({str(i): float(x) for i, x in enumerate(row)}, 0.05)
        assert [named[str(i)] is not None for i in range(6)] == list(flags)


def test_family_wise_false_alarms_stay_under_the_level():
    rng = np.random.default_rng(1)
    null = rng.random((40_000, 15))  # 15 comparisons, nothing changed
    assert holm_rejections(null, 0.05).any(axis=1).mean() <= 0.05
    assert (null <= 0.05).any(axis=1).mean() > 0.5  # each at 5% alone: most sessions raise a false alarm


def test_the_procedure_says_what_it_is():
    assert procedure_text(0.05, 15) == "Holm's step-down procedure over 15 comparisons at family-wise 5%"
    assert procedure_text(0.05, 1) == "Holm's step-down procedure over 1 comparison at family-wise 5%"
