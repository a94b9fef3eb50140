"""The paper's four case studies, and specs beyond them (CartPole, MiniGrid, InvertedPendulum), as goal specs.

Run them with ``pytest --goal-specs example_specs``. Every spec, its
thresholds and the goals it is expected to miss are declared once, in its
case-study module (``specs``); this file only gates them.

The main job keeps every case study and at least one spec of each that must
pass. The paper's negative results (specs with an ``xfail`` goal), which must
train their whole budget to show that they still miss, and the LunarLander
baseline (a 1M-step budget) are marked ``paper``: opt in with ``-m paper``, or run them all with
``specguard reproduce``. LunarLander (auto), which passes but trains for most of its 1M-step budget, is marked
``long`` (``-m long``). Everything: ``-m "paper or long or not paper"``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import pytest

import specguard as sg
from example_specs import (
    acrobot,
    cartpole,
    inverted_pendulum,
    lunar_lander,
    minigrid_empty,
    minigrid_image,
    mountain_car,
    pendulum,
)

paper = pytest.mark.paper


def opt_in(specs: Mapping[str, sg.Spec], also: Iterable[str] = ()) -> dict[str, pytest.MarkDecorator]:
    """The ``paper`` mark for every spec expected to miss (it trains its whole budget), and for ``also``."""
    return {key: paper for key, spec in specs.items() if spec.xfail or key in also}


test_pendulum = sg.goal_specs(pendulum.specs, marks=opt_in(pendulum.specs))
test_acrobot = sg.goal_specs(acrobot.specs, marks=opt_in(acrobot.specs))
test_mountain_car = sg.goal_specs(mountain_car.specs, marks=opt_in(mountain_car.specs))
# LunarLander (auto), beyond the paper, trained 0.7M-1M steps a seed (half the main job's time): opt in with -m long.
test_lunar_lander = sg.goal_specs(
    lunar_lander.specs, marks={**opt_in(lunar_lander.specs, also=["baseline"]), "auto": pytest.mark.long}
)
test_cartpole = sg.goal_specs(cartpole.specs)
test_minigrid = sg.goal_specs(minigrid_empty.specs)
test_minigrid_image = sg.goal_specs(minigrid_image.specs)  # the agent sees MiniGrid's image beside the features
test_inverted_pendulum = sg.goal_specs(inverted_pendulum.specs)
