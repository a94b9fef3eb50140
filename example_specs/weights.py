"""Manual against automatic weights: the paper's hand-tuned weights beside ``weights="auto"``.

Pendulum (w) and LunarLander (w) weight their subgoals by hand (position 0.8
and stabilization 0.2; position 200, velocity 100, stabilisation 50, legs 20);
their (auto) specs are the same trees with ``All(..., weights="auto")``
(:mod:`specguard.training.auto_weights`). This module only gathers the four specs,
declared once in their case-study modules, so that one reproduction trains
them side by side with the same code and seeds::

    specguard reproduce example_specs/weights.py --seeds 5

which writes the "weights" section of ``docs/reproduction.md``.
"""

from __future__ import annotations

from example_specs import lunar_lander, pendulum

specs = {
    f"{case.__name__.rsplit('.', 1)[-1]}-{key}": case.specs[key]
    for case in (pendulum, lunar_lander)
    for key in ("w", "auto")
}

PAPER = {
    f"{case.__name__.rsplit('.', 1)[-1]}-{key}": case.PAPER[key]
    for case in (pendulum, lunar_lander)
    for key in ("w", "auto")
}
