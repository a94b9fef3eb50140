"""The flat evaluator agrees with the reference Algorithm 1 (differential tests)."""

from __future__ import annotations

import ast
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import specguard as sg
from specguard import strategies as sgst
from specguard.construction.compiled import compile_tree
from specguard.construction.initial_env import state_type
from specguard.construction.reference import ExtendedState, ReferenceEvaluator, process

FEATURES = ("a", "b", "c")
State = state_type(FEATURES)


@given(sgst.trees(FEATURES), sgst.trajectories(FEATURES, max_size=25), st.data())
def test_flat_and_reference_agree_step_by_step(tree, trajectory, data):
    actions = data.draw(st.lists(st.integers(0, 2), min_size=len(trajectory), max_size=len(trajectory)))
    flat = compile_tree(tree, FEATURES).evaluator()
    ref = ReferenceEvaluator(tree, FEATURES)
    assert flat.paths == ref.paths
    assert flat.slots == ref.slots
    assert flat.safety_keys == ref.safety_keys
    assert flat.reset(trajectory[0]) == ref.reset(trajectory[0])
    for a, f in zip(actions, trajectory[1:]):
        r1, end1, goals1, terms1 = flat.step(a, f)
        r2, end2, goals2, terms2 = ref.step(a, f)
        assert type(r1) is float
        assert r1 == pytest.approx(r2, rel=1e-9, abs=1e-12)
        assert (end1, goals1) == (end2, goals2)
        assert list(terms1) == list(terms2)
        assert list(terms1.values()) == pytest.approx(list(terms2.values()), rel=1e-9, abs=1e-12)
        assert sum(terms1.values()) == pytest.approx(r1)
        assert flat.own_state == ref.own_state
        assert flat.safe == ref.safe
        if end1:
            break


@given(sgst.trees(FEATURES), st.lists(sgst.states(FEATURES), min_size=1, max_size=30))
def test_batch_membership_agrees_with_reference(tree, batch):
    compiled = compile_tree(tree, FEATURES)
    req = process(tree)
    members = compiled.members(np.asarray(batch))
    assert members.shape == (len(batch), len(compiled.paths))
    for row, f in zip(members, batch):
        s = State._make(f)
        x = ExtendedState(s, req.initial(s))
        assert row.tolist() == [req.goals[p](x) for p in compiled.paths]


@given(sgst.trees(FEATURES), st.data())
def test_batch_rewards_agree_with_reference(tree, data):
    n = data.draw(st.integers(1, 20))
    s = data.draw(st.lists(sgst.states(FEATURES), min_size=n, max_size=n))
    s2 = data.draw(st.lists(sgst.states(FEATURES), min_size=n, max_size=n))
    actions = data.draw(st.lists(st.integers(0, 2), min_size=n, max_size=n))
    compiled = compile_tree(tree, FEATURES)
    req = process(tree)
    terms = compiled.reward_terms(np.asarray(s), np.asarray(actions), np.asarray(s2))
    for i in range(n):
        first, second = State._make(s[i]), State._make(s2[i])
        ext = ExtendedState(first, req.initial(first))
        ext2 = ExtendedState(second, req.transition(ext, actions[i], second, False))
        expected = req.reward(ext, actions[i], ext2)
        assert list(expected) == list(compiled.term_keys)
        assert terms[i].tolist() == pytest.approx(list(expected.values()), rel=1e-9, abs=1e-12)
    assert compiled.rewards(np.asarray(s), np.asarray(actions), np.asarray(s2)) == pytest.approx(terms.sum(axis=1))


def test_batch_falls_back_to_rows_for_python_branching_functions():
    def crash(s, a):
        return abs(s.a) >= 0.2 and s.b <= 0.2  # `and` cannot take arrays

    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Constraint(crash, budget=2))
    compiled = compile_tree(tree, FEATURES)
    s = np.array([[0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert compiled.reward_terms(s, np.zeros(2), s)[:, 1].tolist() == [-1.0, 0.0]


def test_every_node_goal_is_the_intersection_box():
    tree = sg.All(sg.Goal("p", a=(0, 1)), sg.Goal("q", a=(0.5, None), b=2.0), name="r")
    compiled = compile_tree(tree, FEATURES)
    assert compiled.paths == ("r", "r/p", "r/q")
    assert compiled.lo[0].tolist() == [0.5, 2.0, -np.inf]
    assert compiled.hi[0].tolist() == [1.0, 2.0, np.inf]


def test_weights_are_folded_into_one_coefficient_per_leaf():
    d = sg.Distance(lambda s: abs(s.a), scale=4.0)
    tree = sg.All(sg.Goal("p", a=(0, 1)).annotate(d), sg.Goal("q", b=(0, 1)), name="r", weights=(0.8, 0.2))
    compiled = compile_tree(tree, FEATURES)
    coefs = {t.key: t.coef for t in compiled.terms}
    assert coefs == pytest.approx({"r/p": 0.4, "r/p:distance": 0.4 / 4.0, "r/q": 0.2})


def test_generated_source_is_readable():
    tree = sg.All(sg.Goal("p", a=(0, 1)), sg.Goal("q", b=(None, 2.0)), name="r")
    source = compile_tree(tree, FEATURES).source
    assert "0.0 <= f0 <= 1.0  # 'r/p'" in source
    assert "f1 <= 2.0  # 'r/q'" in source
    assert "m0 = m1 and m2  # 'r'" in source


def test_unknown_feature_names_the_path_and_lists_known_features():
    tree = sg.All(sg.Goal("p", z=(0, 1)), name="r")
    with pytest.raises(sg.error.UnknownFeature, match=r"r/p: goal names unknown feature 'z'; known features: a, b, c"):
        compile_tree(tree, FEATURES)


def test_user_function_errors_name_the_annotation():
    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Distance(lambda s: s.zz, scale=1.0))
    ev = compile_tree(tree, FEATURES).evaluator()
    with pytest.raises(sg.error.EvaluationError, match=r"g:distance: the distance function raised AttributeError"):
        ev.reset([0.0, 0.0, 0.0])


def test_negative_distance_is_rejected_mid_episode():
    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Distance(lambda s: s.b, scale=1.0))
    ev = compile_tree(tree, FEATURES).evaluator()
    ev.reset([5.0, 1.0, 0.0])
    with pytest.raises(sg.error.EvaluationError, match=r"g:distance: expected a finite distance >= 0, got -1.0"):
        ev.step(0, [5.0, -1.0, 0.0])


def test_failing_constraint_is_named():
    def boom(s, a):
        raise RuntimeError("no")

    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Constraint(boom, name="crash"))
    ev = compile_tree(tree, FEATURES).evaluator()
    ev.reset([5.0, 1.0, 0.0])
    with pytest.raises(sg.error.EvaluationError, match=r"g:crash: the constraint function raised RuntimeError: no"):
        ev.step(0, [5.0, -1.0, 0.0])


# -- non-finite distances ----------------------------------------------------------


def _distance_of_b(s):
    return s.b


@pytest.mark.parametrize("bad", [math.inf, math.nan])
def test_non_finite_distance_is_rejected_at_reset(bad):
    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Distance(_distance_of_b, scale=1.0))
    ev = compile_tree(tree, FEATURES).evaluator()
    with pytest.raises(
        sg.error.EvaluationError,
        match=rf"g:distance: expected a finite distance >= 0, got {bad!r} \(state State\(a=5.0, b={bad!r}, c=0.0\)\)",
    ):
        ev.reset([5.0, bad, 0.0])


@pytest.mark.parametrize("bad", [math.inf, math.nan])
def test_non_finite_distance_is_rejected_mid_episode_by_both_evaluators(bad):
    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Distance(_distance_of_b, scale=1.0))
    message = rf"g:distance: expected a finite distance >= 0, got {bad!r} \(state State\(a=5.0, b={bad!r}, c=0.0\)\)"
    for ev in (compile_tree(tree, FEATURES).evaluator(), ReferenceEvaluator(tree, FEATURES)):
        ev.reset([5.0, 1.0, 0.0])
        with pytest.raises(sg.error.EvaluationError, match=message):
            ev.step(0, [5.0, bad, 0.0])


@pytest.mark.parametrize("bad", [math.inf, math.nan, -1.0])
def test_batch_rewards_reject_bad_distances(bad):
    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Distance(_distance_of_b, scale=1.0))
    s = np.array([[0.0, 1.0, 0.0], [0.0, 2.0, 0.0]])
    s2 = np.array([[0.0, 1.0, 0.0], [0.0, bad, 0.0]])
    with pytest.raises(
        sg.error.EvaluationError, match=rf"g:distance: expected a finite distance >= 0, got {bad!r} \(state"
    ):
        compile_tree(tree, FEATURES).reward_terms(s, np.zeros(2), s2)


# -- generated code: exact numbers, names only as string literals ------------------


def test_an_overflowing_coefficient_is_rejected_when_compiling():
    tree = sg.Goal("g", a=(0, 1)).annotate(sg.Distance(_distance_of_b, scale=1e-320))
    with pytest.raises(sg.error.InvalidSpec, match=r"g:distance: the component's coefficient .* is inf"):
        compile_tree(tree, FEATURES)


_finite = st.floats(allow_nan=False, allow_infinity=False)


@given(_finite, _finite)
def test_generated_bounds_are_exact(x, y):
    lo, hi = min(x, y), max(x, y)
    compiled = compile_tree(sg.Goal("g", a=(lo, hi)), FEATURES)
    members = compiled.evaluator().members
    edges = [lo, hi, math.nextafter(lo, -math.inf), math.nextafter(hi, math.inf)]
    for v in edges:
        f = [v, 0.0, 0.0]
        assert members(f) == tuple(compiled.members(np.asarray([f]))[0].tolist()) == ((lo <= v <= hi),)


def test_a_name_holding_code_stays_a_name(capsys):
    name = 'g\n    print("X")'
    tree = sg.All(
        sg.Goal(name, a=(0, 1)).annotate(sg.Distance(_distance_of_b, scale=1.0, name="x\n    raise SystemExit")),
        name="r",
    )
    ev = compile_tree(tree, FEATURES).evaluator()
    ev.reset([0.5, 1.0, 0.0])
    _, _, _, terms = ev.step(0, [0.5, 0.5, 0.0])
    assert list(terms) == [f"r/{name}", f"r/{name}:x\n    raise SystemExit"]
    assert capsys.readouterr().out == ""


class _BlankStrings(ast.NodeTransformer):
    def visit_Constant(self, node: ast.Constant) -> ast.AST:
        return ast.copy_location(ast.Constant(""), node) if isinstance(node.value, str) else node


def _shape(source: str) -> str:
    """The AST of ``source`` with every string constant blanked."""
    return ast.dump(_BlankStrings().visit(ast.parse(source)))


def _named_tree(root: str, p: str, q: str, d: str, c: str) -> sg.Node:
    return sg.All(
        sg.Goal(p, a=(0, 1)).annotate(
            sg.Distance(_distance_of_b, scale=2.0, name=d), sg.Constraint(lambda s, a: s.c > 1, name=c)
        ),
        sg.Goal(q, b=(None, 2.0)),
        name=root,
    )


_any_name = st.text(min_size=1).filter(lambda s: bool(s.strip()) and "/" not in s and ":" not in s)


@given(st.lists(_any_name, min_size=5, max_size=5, unique=True))
def test_names_reach_generated_code_only_as_string_literals(names):
    compiled = compile_tree(_named_tree(*names), FEATURES)
    placeholder = compile_tree(_named_tree("n0", "n1", "n2", "n3", "n4"), FEATURES)
    assert _shape(compiled.source) == _shape(placeholder.source)
    ev = compiled.evaluator()
    ev.reset([0.5, 1.0, 2.0])  # violates the constraint s.c > 1: its counter drops to 0
    r, ended, goals, terms = ev.step(0, [0.5, 0.5, 0.0])
    assert goals == (True, True, True)
    root, p, q, d, c = names
    assert list(terms) == [f"{root}/{p}", f"{root}/{p}:{d}", f"{root}/{p}:{c}", f"{root}/{q}"]
    assert ev.paths == (root, f"{root}/{p}", f"{root}/{q}")
    assert ev.own_state == [0.0] and ended
    assert r == pytest.approx(0.5 * (0.5 * (1.0 - 0.5) / 2.0 - 1.0))  # root weight 1/2: distance, penalty


def test_adapted_weights_replace_an_auto_nodes_weights_only():
    up, still = sg.Goal("up", x=(0.5, None)), sg.Goal("still", v=(-0.1, 0.1))
    tree = sg.All(up, still, name="p", weights="auto")
    plain = compile_tree(tree, ("x", "v"))
    adapted = compile_tree(tree, ("x", "v"), weights={"p": (0.9, 0.1)})
    assert [t.coef for t in plain.terms] == [0.5, 0.5]
    assert [t.coef for t in adapted.terms] == [0.9, 0.1]
    with pytest.raises(sg.error.InvalidSpec, match=r"weights\['p/up'\].*weights='auto'.*such nodes: 'p'"):
        compile_tree(tree, ("x", "v"), weights={"p/up": (1.0,)})
    with pytest.raises(sg.error.InvalidSpec, match=r"expected 2 finite weights >= 0 \(one per child\), got \(1.0,\)"):
        compile_tree(tree, ("x", "v"), weights={"p": (1.0,)})
    with pytest.raises(sg.error.InvalidSpec, match=r"such nodes: none"):
        compile_tree(sg.All(up, still, name="p"), ("x", "v"), weights={"p": (0.9, 0.1)})


def test_adapted_weights_of_an_auto_node_include_its_default_weight_constraints():
    up, still = sg.Goal("up", x=(0.5, None)), sg.Goal("still", v=(-0.1, 0.1))
    fast, kept = sg.Constraint(lambda s, a: s.v > 1, name="fast"), sg.Constraint(lambda s, a: False, weight=2.0)
    tree = sg.All(up, still, name="p", weights="auto").annotate(fast, kept)
    plain = compile_tree(tree, ("x", "v"))
    adapted = compile_tree(tree, ("x", "v"), weights={"p": (0.6, 0.3, 0.1)})
    assert [(t.key, t.coef) for t in plain.terms] == [
        ("p/up", 0.5),
        ("p/still", 0.5),
        ("p:fast", 1.0),
        ("p:constraint", 2.0),
    ]
    assert [(t.key, t.coef) for t in adapted.terms] == [
        ("p/up", 0.6),
        ("p/still", 0.3),
        ("p:fast", 0.1),
        ("p:constraint", 2.0),  # a weight its author set is kept
    ]
    with pytest.raises(
        sg.error.InvalidSpec, match=r"expected 3 finite weights >= 0 \(one per child, then one per constraint"
    ):
        compile_tree(tree, ("x", "v"), weights={"p": (0.9, 0.1)})


def _distance_to_a(s):
    return abs(s.a)


def test_a_compiled_tree_shares_its_generated_code_and_pickles_without_it():
    import copy
    import pickle

    tree = sg.All(sg.Goal("g", a=(0.0, 1.0)).annotate(sg.Distance(_distance_to_a, scale=2.0)), name="root")
    compiled = compile_tree(tree, FEATURES)
    first, second = compiled.evaluator(), compiled.evaluator()
    assert first.step.__code__ is second.step.__code__ and first.step is not second.step
    for again in (pickle.loads(pickle.dumps(compiled)), copy.deepcopy(compiled)):
        assert "code" not in again.__dict__ and again.source == compiled.source
        ev = again.evaluator()
        first.reset([2.0, 0.0, 0.0])
        ev.reset([2.0, 0.0, 0.0])
        assert ev.step(0, [0.5, 0.0, 0.0]) == first.step(0, [0.5, 0.0, 0.0])


@pytest.mark.parametrize(
    "bad",
    [None, "no", math.nan, 0, 1, np.float64(1.0), np.float64(0.0)],
    ids=["None", "a string", "NaN", "0", "1", "np.float64 1", "np.float64 0"],
)
def test_a_constraint_result_is_checked_on_every_step_in_both_evaluators_with_one_error(bad):
    # True on the first steps (the old flat evaluator checked only the first call), then ``bad``.
    def evaluate(evaluator):
        results = iter([False, True, bad])
        tree = sg.Goal("far", a=(10.0, None)).annotate(sg.Constraint(lambda s, a: next(results), budget=5, name="hot"))
        ev = compile_tree(tree, FEATURES).evaluator() if evaluator == "flat" else ReferenceEvaluator(tree, FEATURES)
        ev.reset([0.0, 0.0, 0.0])
        ev.step(0, [1.0, 0.0, 0.0])
        ev.step(0, [2.0, 0.0, 0.0])
        own = list(ev.own_state)
        with pytest.raises(sg.error.EvaluationError) as caught:
            ev.step(0, [3.0, 0.0, 0.0])
        assert ev.own_state == own  # the failed step changed no episode state
        return caught.value

    flat, ref = evaluate("flat"), evaluate("reference")
    assert flat.message.startswith(f"far:hot: the constraint function returned {bad!r} ({type(bad).__name__})")
    assert (flat.message, flat.hint) == (ref.message, ref.hint)


def test_a_constraint_returning_bools_of_either_kind_counts_each_true_as_one_violation():
    results = iter([np.True_, False, True, np.bool_(False), np.bool_(True)])
    tree = sg.Goal("far", a=(10.0, None)).annotate(sg.Constraint(lambda s, a: next(results), budget=9, name="c"))
    ev = compile_tree(tree, FEATURES).evaluator()
    ev.reset([0.0, 0.0, 0.0])
    for x in range(1, 6):
        ev.step(0, [float(x), 0.0, 0.0])
    assert ev.own_state == [6.0]


@pytest.mark.parametrize("how", ["copy", "deepcopy"])
def test_a_copied_evaluator_steps_its_own_episode(how):
    # The generated step writes the episode state of the evaluator it was made for: a copy needs a step of its
    # own, or stepping the copy would move the original (and leave the copy where it was).
    import copy

    tree = sg.Goal("far", a=(10.0, None)).annotate(sg.Constraint(lambda s, a: s.a < 0, budget=3, name="neg"))
    original = compile_tree(tree, FEATURES).evaluator()
    original.reset([1.0, 0.0, 0.0])
    original.step(0, [-1.0, 0.0, 0.0])
    twin = getattr(copy, how)(original)
    assert twin.own_state == original.own_state == [3.0] and twin.goals == original.goals
    twin.step(0, [-2.0, 0.0, 0.0])
    assert original.own_state == [3.0] and twin.own_state == [2.0]  # a constraint judges (s, a)
    assert original.state.a == -1.0 and twin.state.a == -2.0
    original.step(0, [-2.0, 0.0, 0.0])
    twin.step(0, [-2.0, 0.0, 0.0])
    assert original.own_state == [2.0] and twin.own_state == [1.0]
