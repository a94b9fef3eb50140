"""A spec's plan as text: what its gate can see (:mod:`specguard.gate.plan`), for ``specguard plan`` and
``pytest --goal-specs --goal-specs-plan``."""

from __future__ import annotations

import math

from specguard.gate.plan import OFFSETS, VISIBLE_DROP, GoalPlan, SpecPlan
from specguard.tree.keys import label
from specguard.utils.text import render_table

__all__ = ["plan_lines"]


def _points(drop: float | None) -> str:
    """A drop in whole points, rounded up (the plan's figure is the smallest drop seen, to 0.01)."""
    return "none" if drop is None else f"{math.ceil(round(drop * 100, 6))} points"


def _met_cells(goal: GoalPlan) -> list[str]:
    cells = []
    for d in OFFSETS:
        p = round(goal.threshold + d, 4)
        cells.append(f"{p:.2f}: {goal.met[p]:.0%} ({goal.passed[p]:.0%})" if p in goal.met else "-")
    return cells


def _baseline_text(goal: GoalPlan, seeds: int) -> str:
    source = f"from its {seeds} seeds" if goal.estimated else "assumed"
    return f"{seeds} seeds at {goal.success:.0%}, spread {goal.spread:.2f} ({source})"


def plan_lines(plan: SpecPlan) -> list[str]:
    """The plan: per goal, the chance of a met run around its threshold; per comparison, the drops it can see."""
    stages = ", ".join(map(str, plan.stages))
    lines = [
        f"== {plan.label}: {plan.runs} seed{'s' if plan.runs != 1 else ''} (quorum {plan.quorum} of {plan.runs}); "
        f"{stages} evaluation episodes while undecided; runs judged at {plan.confidence:.2%} per look",
        "thresholds: the chance one run is judged met at true success p (the goal passes its quorum)",
    ]
    offsets = [("t" if not d else f"t{d:+.2f}") for d in OFFSETS]
    rows = [[label(g.path), f">= {g.threshold:g}", *_met_cells(g)] for g in plan.goals]
    lines += ["  " + line for line in render_table(["goal", "threshold", *offsets], rows)]
    family = f"{plan.family} comparison{'s' if plan.family != 1 else ''}"
    lines.append(
        f"comparison with a baseline: each judged at {plan.level:.2g} (5% over {family}, Holm's "
        f"first step); {plan.start} seed{'s' if plan.start != 1 else ''}, up to {plan.ceiling} while a "
        "comparison is open"
    )
    header = ["goal", "baseline", f"drop seen (80% power), {plan.start} seeds", f"up to {plan.ceiling} seeds"]
    blind = f": cannot detect a {VISIBLE_DROP * 100:.0f}-point drop"
    rows = [
        [
            label(g.path),
            _baseline_text(g, plan.baseline_seeds[g.path]),
            _points(g.at_start),
            _points(g.with_extra) + (blind if g.blind else ""),
        ]
        for g in plan.goals
    ]
    lines += ["  " + line for line in render_table(header, rows)]
    return lines
