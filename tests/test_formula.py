"""The reward formula printed from the tree."""

from __future__ import annotations

import specguard as sg
from example_specs import lunar_lander, pendulum


def test_pendulum_formulas_show_what_each_refinement_changed():
    assert sg.formula(pendulum.trees["a"]) == "R = R[pendulum]"
    assert sg.formula(pendulum.trees["b"]) == "R = 0.5*R[position] + 0.5*R[stabilization]"
    assert sg.formula(pendulum.trees["c"]) == "R = 0.5*(0.5*R[position] + 0.5*D[position]) + 0.5*R[stabilization]"
    assert sg.formula(pendulum.trees["w"]) == "R = 0.8*(0.5*R[position] + 0.5*D[position]) + 0.2*R[stabilization]"


def test_constraint_penalty_is_outside_the_normalisation():
    assert sg.formula(lunar_lander.trees["b"]) == (
        "R = 0.25*R[position] + 0.25*R[velocity] + 0.25*R[stabilization] + 0.25*R[legs] + P[lander:crash]"
    )


def test_repeated_names_are_labelled_by_path():
    tree = sg.All(
        sg.All(sg.Goal("x", a=0), name="left"),
        sg.All(sg.Goal("x", a=1), name="right"),
        name="root",
    )
    assert sg.formula(tree) == "R = 0.5*R[left/x] + 0.5*R[right/x]"


def test_named_and_weighted_annotations():
    g = sg.Goal("g", a=0).annotate(sg.Distance(abs, scale=1.0, weight=2.0, name="near"))
    assert sg.formula(g) == "R = 0.5*R[g] + 2*D[g:near]"


def test_auto_weights_are_shown_where_they_start():
    tree = sg.All(sg.Goal("up", x=(0.9, 1)), sg.Goal("still", v=(-0.1, 0.1)), name="p", weights="auto")
    note = ": as written at the start, adapted during training"
    assert sg.formula(tree) == "R = 0.5*R[up] + 0.5*R[still]\n  weights of p" + note
    fast, kept = sg.Constraint(lambda s, a: s.v > 1, name="fast"), sg.Constraint(lambda s, a: False, weight=2)
    assert sg.formula(tree.annotate(fast, kept)).endswith("weights of p with P[p:fast]" + note)
