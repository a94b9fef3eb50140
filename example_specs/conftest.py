"""Fixtures of the case studies: initial envs and goal trees, one per refinement step."""

from __future__ import annotations

import pytest

import specguard as sg
from example_specs import acrobot, lunar_lander, mountain_car, pendulum


@pytest.fixture
def pendulum_env() -> sg.InitialEnv:
    return pendulum.initial_env


@pytest.fixture
def pendulum_trees() -> dict[str, sg.Node]:
    """(a) one leaf, (b) refined by All, (c) with a distance, (w) with the paper's weights."""
    return pendulum.trees


@pytest.fixture
def acrobot_env() -> sg.InitialEnv:
    return acrobot.initial_env


@pytest.fixture
def mountain_car_env() -> sg.InitialEnv:
    return mountain_car.initial_env


@pytest.fixture
def lunar_lander_env() -> sg.InitialEnv:
    return lunar_lander.initial_env
