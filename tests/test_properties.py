"""Property-based tests (hypothesis) of the preference utilities, the metrics and the sum tree.

This file is the one home of every property below; the example-based tests of the same modules stay in
test_preferences.py, test_metrics.py and test_replay.py.

=====================================================  ====================================================
property                                               test
=====================================================  ====================================================
simplex samples lie on the simplex (m = 1..5)          test_sample_simplex_on_simplex
relabeled neighbours lie within sigma_omega            test_neighbours_within_sigma_on_simplex
CR, precision and recall lie in [0, 1]                 test_cr_in_unit_interval
CR = 1 when the found set is the CCS                   test_cr_one_when_found_is_ccs
CR = 1 exactly when the found set equals the CCS       test_cr_one_iff_found_set_equals_ccs
HV never falls when a point is added                   test_hv_never_falls_when_a_point_is_added
CCS is a subset of the Pareto front (of the input)     test_ccs_subset_of_front_subset_of_input
the CCS keeps every linear optimum                     test_ccs_keeps_every_linear_optimum
sum tree: sampling frequency proportional to priority  test_sumtree_sampling_frequency_proportional_to_priority
sum tree: updates keep the total (and every node)      test_sumtree_updates_keep_the_total
sum tree: find agrees with a cumulative sum            test_sumtree_find_matches_cumsum
=====================================================  ====================================================
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chisquare

from mope.agent.replay import SumTree
from mope.metrics import (
    DEFAULT_ATOL,
    convex_coverage_set,
    coverage_ratio,
    hypervolume,
    match_matrix,
    pareto_front,
)
from mope.preferences import sample_neighbours, sample_simplex

PROPS = settings(max_examples=60, deadline=None)
SEEDS = st.integers(0, 2**32 - 1)


def assert_on_simplex(x: np.ndarray, atol: float = 1e-9) -> None:
    assert np.all(np.isfinite(x))
    assert np.all(x >= 0.0)
    np.testing.assert_allclose(x.sum(axis=-1), 1.0, atol=atol)


def rows(a: np.ndarray) -> set[tuple[float, ...]]:
    return {tuple(float(v) for v in r) for r in np.asarray(a)}


# ------------------------------------------------------------------------------------------- preferences
@PROPS
@given(n=st.integers(1, 300), m=st.integers(1, 5), seed=SEEDS)
def test_sample_simplex_on_simplex(n: int, m: int, seed: int) -> None:
    x = sample_simplex(n, m, np.random.default_rng(seed))
    assert x.shape == (n, m)
    assert_on_simplex(x)


@st.composite
def simplex_points(draw: st.DrawFn, m: int) -> np.ndarray:
    # Integer weights make vertices, edges and faces (zeros) common, where neighbours must be reflected back.
    w = draw(st.lists(st.integers(0, 100), min_size=m, max_size=m).filter(lambda v: sum(v) > 0))
    w = np.asarray(w, dtype=np.float64)
    return w / w.sum()


@PROPS
@given(
    data=st.data(),
    m=st.integers(2, 5),
    sigma=st.floats(0.005, 0.3),
    n=st.integers(1, 64),
    seed=SEEDS,
)
def test_neighbours_within_sigma_on_simplex(data: st.DataObject, m: int, sigma: float, n: int, seed: int) -> None:
    centers = np.stack([data.draw(simplex_points(m)) for _ in range(data.draw(st.integers(1, 3)))])
    nb = sample_neighbours(centers, n, sigma, np.random.default_rng(seed))
    assert nb.shape == (len(centers), n, m)
    assert_on_simplex(nb)
    dist = np.linalg.norm(nb - centers[:, None, :], axis=-1)
    assert dist.max() <= sigma + 1e-9


# ------------------------------------------------------------------------------------------- metrics
# Integer coordinates keep distinct points >= 1 apart, far beyond the matching tolerance.
int_points = (
    st.integers(min_value=2, max_value=3)
    .flatmap(lambda m: st.lists(st.tuples(*[st.integers(0, 10)] * m), min_size=1, max_size=12))
    .map(lambda p: np.array(p, dtype=float))
)

float_points = (
    st.integers(min_value=2, max_value=3)
    .flatmap(
        lambda m: st.lists(
            st.tuples(*[st.floats(0.0, 10.0, allow_nan=False, allow_infinity=False)] * m),
            min_size=1,
            max_size=12,
        )
    )
    .map(lambda p: np.array(p, dtype=float))
)


@PROPS
@given(pts=int_points, found=float_points)
def test_cr_in_unit_interval(pts: np.ndarray, found: np.ndarray) -> None:
    m = min(pts.shape[1], found.shape[1])
    res = coverage_ratio(found[:, :m], convex_coverage_set(pts[:, :m]))
    for v in (res.cr, res.precision, res.recall):
        assert 0.0 <= v <= 1.0


@PROPS
@given(pts=int_points, seed=SEEDS)
def test_cr_one_when_found_is_ccs(pts: np.ndarray, seed: int) -> None:
    ccs = convex_coverage_set(pts)
    rng = np.random.default_rng(seed)
    found = ccs[rng.integers(0, len(ccs), size=3 * len(ccs))]
    found = np.vstack([found, ccs])[rng.permutation(4 * len(ccs))]  # every CCS point, shuffled, duplicated
    found = found + rng.uniform(-0.5, 0.5, size=found.shape) * DEFAULT_ATOL  # float noise within the tolerance
    res = coverage_ratio(found, ccs)
    assert (res.cr, res.precision, res.recall) == (1.0, 1.0, 1.0)


@PROPS
@given(pts=int_points, data=st.data())
def test_cr_one_iff_found_set_equals_ccs(pts: np.ndarray, data: st.DataObject) -> None:
    ccs = convex_coverage_set(pts)
    m = ccs.shape[1]
    keep = np.array(data.draw(st.lists(st.booleans(), min_size=len(ccs), max_size=len(ccs))))
    extra = np.array(data.draw(st.lists(st.tuples(*[st.integers(0, 12)] * m), max_size=3)), dtype=float)
    found = np.vstack([ccs[keep], extra.reshape(-1, m)])
    res = coverage_ratio(found, ccs)
    if len(found) == 0:
        assert res.cr == 0.0
        return
    hits = match_matrix(found, ccs)
    same_set = bool(hits.any(axis=1).all() and hits.any(axis=0).all())
    assert (res.cr == 1.0) == same_set
    assert res.cr < 1.0 or (res.precision, res.recall) == (1.0, 1.0)


@PROPS
@given(
    pts=st.integers(2, 4).flatmap(
        lambda m: st.lists(st.tuples(*[st.floats(-1.0, 10.0, allow_nan=False)] * m), min_size=0, max_size=10)
        .map(lambda p, m=m: np.array(p, dtype=float).reshape(-1, m))
    ),
    data=st.data(),
)
def test_hv_never_falls_when_a_point_is_added(pts: np.ndarray, data: st.DataObject) -> None:
    m = pts.shape[1]
    extra = np.array(data.draw(st.tuples(*[st.floats(-1.0, 10.0, allow_nan=False)] * m)))
    ref = np.zeros(m)
    before = hypervolume(pts, ref)
    after = hypervolume(np.vstack([pts, extra]), ref)
    assert before >= 0.0
    assert after >= before - 1e-9 * max(1.0, before)


@PROPS
@given(pts=st.one_of(int_points, float_points))
def test_ccs_subset_of_front_subset_of_input(pts: np.ndarray) -> None:
    front = pareto_front(pts)
    ccs = convex_coverage_set(pts)
    assert rows(ccs) <= rows(front) <= rows(pts)
    assert len(front) >= 1 and len(ccs) >= 1


@PROPS
@given(pts=st.one_of(int_points, float_points), w_raw=st.lists(st.floats(0.01, 1.0), min_size=3, max_size=3))
def test_ccs_keeps_every_linear_optimum(pts: np.ndarray, w_raw: list[float]) -> None:
    # for any preference, the best utility over the CCS equals the best over all points
    w = np.array(w_raw[: pts.shape[1]])
    w = w / w.sum()
    ccs = convex_coverage_set(pts)
    assert (ccs @ w).max() == pytest.approx((pts @ w).max(), abs=1e-9)


# ------------------------------------------------------------------------------------------- sum tree
priorities = st.integers(1, 16).flatmap(
    lambda c: st.lists(st.integers(0, 9), min_size=c, max_size=c).filter(lambda p: sum(p) > 0)
).map(lambda p: np.array(p, dtype=np.float64))


@settings(max_examples=40, deadline=None)
@given(pr=priorities, seed=SEEDS)
def test_sumtree_sampling_frequency_proportional_to_priority(pr: np.ndarray, seed: int) -> None:
    t = SumTree(len(pr))
    t.update(np.arange(len(pr)), pr)
    n = 20_000
    idx = t.find(np.random.default_rng(seed).random(n) * t.total)
    counts = np.bincount(idx, minlength=len(pr))
    assert counts[pr == 0].sum() == 0  # a zero priority is never drawn
    live = pr > 0
    if live.sum() >= 2:
        # chi-square goodness of fit to p_i = priority_i / total; with 40 examples a false alarm is ~4e-5
        assert chisquare(counts[live], n * pr[live] / pr.sum()).pvalue > 1e-6


@PROPS
@given(
    capacity=st.integers(1, 40),
    data=st.data(),
)
def test_sumtree_updates_keep_the_total(capacity: int, data: st.DataObject) -> None:
    t = SumTree(capacity)
    ref = np.zeros(capacity)
    for _ in range(data.draw(st.integers(1, 6))):
        k = data.draw(st.integers(1, 2 * capacity))
        idx = np.array(data.draw(st.lists(st.integers(0, capacity - 1), min_size=k, max_size=k)))
        val = np.array(data.draw(st.lists(st.floats(0.0, 100.0), min_size=k, max_size=k)))
        t.update(idx, val)
        ref[idx] = val  # numpy keeps the last value given for a repeated index, as the tree does
        assert t.total == pytest.approx(ref.sum(), rel=1e-12, abs=1e-9)
        np.testing.assert_array_equal(t.get(np.arange(capacity)), ref)
        internal = np.arange(1, t.size)
        np.testing.assert_allclose(t.tree[internal], t.tree[2 * internal] + t.tree[2 * internal + 1], rtol=1e-12)


@PROPS
@given(
    capacity=st.integers(1, 40),
    data=st.data(),
)
def test_sumtree_find_matches_cumsum(capacity: int, data: st.DataObject) -> None:
    pr = np.array(data.draw(st.lists(st.integers(0, 9), min_size=capacity, max_size=capacity)), dtype=np.float64)
    if pr.sum() == 0:
        pr[0] = 1.0
    t = SumTree(capacity)
    t.update(np.arange(capacity), pr)
    assert t.total == pytest.approx(pr.sum())
    values = np.linspace(0.0, pr.sum(), 57, endpoint=False)
    expected = np.searchsorted(np.cumsum(pr), values, side="right")
    assert t.find(values).tolist() == expected.tolist()
