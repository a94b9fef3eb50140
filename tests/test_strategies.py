"""The public Hypothesis strategies produce what they promise."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

import specguard as sg
from specguard import strategies as sgst
from specguard.construction.compiled import compile_tree

FEATURES = ("a", "b", "c")


@given(sgst.feature_names())
def test_feature_names_make_valid_initial_envs(features):
    sg.InitialEnv(lambda: None, features=features)


@given(sgst.feature_names().flatmap(lambda fs: st.tuples(st.just(fs), sgst.trees(fs))))
def test_trees_compile_over_their_features(args):
    features, tree = args
    compiled = compile_tree(tree, features)
    assert compiled.paths[0] == tree.name
    assert len(compiled.paths) == sum(1 for _ in tree.walk())


@given(st.data())
def test_refinements_intersect_to_the_leaf(data):
    leaf = data.draw(sgst.goals(FEATURES, name="root"))
    refined = data.draw(sgst.refinements(leaf))
    a, b = compile_tree(leaf, FEATURES), compile_tree(refined, FEATURES)
    assert np.array_equal(a.lo[0], b.lo[0]) and np.array_equal(a.hi[0], b.hi[0])


@given(sgst.trajectories(FEATURES, min_size=3, max_size=5))
def test_trajectories_have_the_requested_shape(trajectory):
    arr = np.asarray(trajectory, dtype=np.float64)
    assert arr.shape[1] == 3 and 3 <= arr.shape[0] <= 5
    assert np.all(np.isfinite(arr))


@given(sgst.bounds())
def test_bounds_are_ordered(bound):
    lo, hi = bound
    if lo is not None and hi is not None:
        assert lo <= hi
