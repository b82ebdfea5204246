"""Tests of mope.metrics on hand-made fronts whose answers are known by hand (objectives are maximised)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mope.metrics import (
    DEFAULT_ATOL,
    DEFAULT_RTOL,
    EVALUATE_KEYS,
    CoverageResult,
    cardinality,
    convex_coverage_set,
    coverage_ratio,
    evaluate_front,
    expected_utility,
    hypervolume,
    inverted_generational_distance,
    match_matrix,
    optimal_share,
    optimal_utility,
    pareto_front,
    unique_solutions,
)

# Deep-Sea-Treasure convex front (treasure, time), undiscounted.
DST = np.array(
    [
        [0.7, -1.0],
        [8.2, -3.0],
        [11.5, -5.0],
        [14.0, -7.0],
        [15.1, -8.0],
        [16.1, -9.0],
        [19.6, -13.0],
        [20.3, -14.0],
        [22.4, -17.0],
        [23.7, -19.0],
    ]
)
# For each DST point, a ratio r = w_time / w_treasure at which it is optimal, worked out by hand from the
# slopes between neighbours (3.75, 1.65, 1.25, 1.1, 1.0, 0.875, 0.7, 0.7, 0.65). (20.3, -14) lies on the
# segment from (19.6, -13) to (22.4, -17), so it is optimal only at r = 0.7, where all three tie.
DST_RATIOS = np.array([5.0, 2.0, 1.5, 1.2, 1.05, 0.9, 0.8, 0.7, 0.67, 0.5])
DST_PREFS = np.stack([1.0 / (1.0 + DST_RATIOS), DST_RATIOS / (1.0 + DST_RATIOS)], axis=1)


def rows(a: np.ndarray) -> set[tuple[float, ...]]:
    return {tuple(float(v) for v in r) for r in np.asarray(a)}


# ------------------------------------------------------------------------------------------- constants
def test_default_tolerances() -> None:
    assert DEFAULT_ATOL == 1e-2
    assert DEFAULT_RTOL == 1e-3


# ---------------------------------------------------------------------------------------- pareto_front
def test_pareto_front_removes_dominated_and_duplicates_in_order() -> None:
    pts = [[1, 2], [0.5, 0.5], [2, 1], [1, 1], [1, 2], [0, 3], [2, 1], [0, 2.5]]
    np.testing.assert_array_equal(pareto_front(pts), [[1, 2], [2, 1], [0, 3]])


def test_pareto_front_weak_domination() -> None:
    # (1, 2) is weakly dominated by (1, 3): equal in one objective, worse in the other.
    np.testing.assert_array_equal(pareto_front([[1, 2], [1, 3], [3, 0]]), [[1, 3], [3, 0]])


def test_pareto_front_near_duplicates_within_tol() -> None:
    out = pareto_front([[1.0, 2.0], [2.0, 1.0], [1.0, 2.0 + 1e-12]])
    np.testing.assert_array_equal(out, [[2.0, 1.0], [1.0, 2.0 + 1e-12]])


def test_pareto_front_empty_and_single() -> None:
    assert pareto_front(np.empty((0, 3))).shape == (0, 3)
    np.testing.assert_array_equal(pareto_front([[4.0, -1.0]]), [[4.0, -1.0]])


# ------------------------------------------------------------------------------------------------- CCS
def test_ccs_2d_point_below_the_line_is_excluded() -> None:
    pts = [[0, 1], [0.4, 0.4], [1, 0]]
    np.testing.assert_array_equal(pareto_front(pts), pts)  # Pareto-optimal ...
    np.testing.assert_array_equal(convex_coverage_set(pts), [[0, 1], [1, 0]])  # ... but not in the CCS


def test_ccs_2d_point_above_the_line_is_kept() -> None:
    pts = [[0, 1], [0.6, 0.6], [1, 0]]
    np.testing.assert_array_equal(convex_coverage_set(pts), pts)


def test_ccs_2d_point_on_the_line_is_kept_and_just_below_is_not() -> None:
    on_line = [[0, 1], [0.5, 0.5], [1, 0]]
    np.testing.assert_array_equal(convex_coverage_set(on_line), on_line)
    below = 0.5 - 1e-6
    np.testing.assert_array_equal(convex_coverage_set([[0, 1], [below, below], [1, 0]]), [[0, 1], [1, 0]])


def test_ccs_3d() -> None:
    eye = np.eye(3)
    # w·(0.2, 0.2, 0.2) = 0.2 < max_i w_i (>= 1/3) for every w: excluded.
    np.testing.assert_array_equal(convex_coverage_set(np.vstack([eye, [0.2, 0.2, 0.2]])), eye)
    # (0.3, 0.3, 0.3): still below 1/3, excluded.
    np.testing.assert_array_equal(convex_coverage_set(np.vstack([eye, [0.3, 0.3, 0.3]])), eye)
    # at w = (1/3, 1/3, 1/3): 0.5 > 1/3, kept.
    pts = np.vstack([eye, [0.5, 0.5, 0.5]])
    np.testing.assert_array_equal(convex_coverage_set(pts), pts)
    # (0.6, 0.6, 0) beats e1, e2 at w = (1/2, 1/2, 0); (0.4, 0.4, 0.1) is Pareto but never optimal.
    pts = np.vstack([eye, [0.6, 0.6, 0.0], [0.4, 0.4, 0.1]])
    np.testing.assert_array_equal(convex_coverage_set(pts), np.vstack([eye, [0.6, 0.6, 0.0]]))


def test_ccs_deep_sea_treasure_all_ten_points() -> None:
    # includes (20.3, -14), which lies exactly on the hull segment (tie, LP value 0).
    np.testing.assert_array_equal(convex_coverage_set(DST), DST)
    shuffled = DST[[3, 9, 0, 7, 5, 1, 8, 2, 6, 4]]
    assert rows(convex_coverage_set(shuffled)) == rows(DST)


def test_ccs_original_deep_sea_treasure_is_concave() -> None:
    # Original DST treasures: only the two extreme points are on the convex hull.
    original = np.array(
        [[1, -1], [2, -3], [3, -5], [5, -7], [8, -8], [16, -9], [24, -13], [50, -14], [74, -17], [124, -19]],
        dtype=float,
    )
    np.testing.assert_array_equal(convex_coverage_set(original), [[1, -1], [124, -19]])


def test_ccs_edge_cases() -> None:
    np.testing.assert_array_equal(convex_coverage_set([[3.0, 1.0]]), [[3.0, 1.0]])
    np.testing.assert_array_equal(convex_coverage_set([[3.0], [1.0], [3.0], [2.0]]), [[3.0]])
    np.testing.assert_array_equal(convex_coverage_set([[1.0, 1.0], [1.0, 1.0]]), [[1.0, 1.0]])
    assert convex_coverage_set(np.empty((0, 2))).shape == (0, 2)
    # dominated points never enter the CCS
    np.testing.assert_array_equal(convex_coverage_set([[0, 1], [1, 0], [0.1, 0.1]]), [[0, 1], [1, 0]])


# -------------------------------------------------------------------------------------------- matching
def test_match_matrix_shape_and_tolerances() -> None:
    a = [[0.0, 0.0], [0.005, -0.005], [0.1, 0.0], [100.05, 0.0]]
    b = [[0.0, 0.0], [100.0, 0.0]]
    expected = [[True, False], [True, False], [False, False], [False, True]]  # 0.05 <= 0.01 + 0.001*100
    np.testing.assert_array_equal(match_matrix(a, b), expected)
    np.testing.assert_array_equal(match_matrix(a, b, atol=0.2, rtol=0.0)[2], [True, False])
    assert match_matrix(np.empty((0, 2)), b).shape == (0, 2)


def test_match_matrix_relative_to_b() -> None:
    # tolerance is atol + rtol*|b|, so the relation is not symmetric
    assert match_matrix([[0.0]], [[10.0]], atol=0.0, rtol=1.0)[0, 0]
    assert not match_matrix([[10.0]], [[0.0]], atol=0.0, rtol=1.0)[0, 0]


def test_unique_solutions_and_cardinality() -> None:
    pts = [[1.0, 2.0], [1.004, 2.0], [3.0, 0.0], [1.0, 2.0], [3.0, 0.05], [1.0, 2.0]]
    np.testing.assert_array_equal(unique_solutions(pts), [[1.0, 2.0], [3.0, 0.0], [3.0, 0.05]])
    assert cardinality(pts) == 3
    assert cardinality(pts, atol=0.1) == 2
    assert cardinality(np.empty((0, 2))) == 0


# -------------------------------------------------------------------------------------------- coverage
CCS4 = np.array([[0.0, 4.0], [1.0, 3.5], [3.0, 2.0], [4.0, 0.0]])


def test_cr_found_equals_ccs() -> None:
    res = coverage_ratio(CCS4, CCS4)
    assert res == CoverageResult(precision=1.0, recall=1.0, cr=1.0, n_found=4, n_ccs=4, n_matched=4)


def test_cr_half_found_half_wrong() -> None:
    found = [[0.0, 4.0], [3.0, 2.0], [2.0, 2.0], [0.5, 0.5]]
    res = coverage_ratio(found, CCS4)
    assert (res.precision, res.recall, res.cr) == (0.5, 0.5, 0.5)
    assert (res.n_found, res.n_ccs, res.n_matched) == (4, 4, 2)


def test_cr_one_of_four() -> None:
    res = coverage_ratio([[4.0, 0.0]], CCS4)
    assert res.precision == 1.0
    assert res.recall == 0.25
    assert res.cr == pytest.approx(0.4, abs=1e-15)


def test_cr_duplicates_do_not_change_precision() -> None:
    found = [[0.0, 4.0], [0.0, 4.0], [0.0, 4.0], [2.0, 2.0]]
    res = coverage_ratio(found, CCS4)
    assert (res.precision, res.recall, res.n_found) == (0.5, 0.25, 2)
    assert res.cr == pytest.approx(1 / 3, abs=1e-15)  # 2 * 0.5 * 0.25 / 0.75


def test_cr_tolerance() -> None:
    near = CCS4 + np.array([[0.005, -0.005]])
    assert coverage_ratio(near, CCS4).cr == 1.0
    far = CCS4 + np.array([[0.1, 0.0]])
    res = coverage_ratio(far, CCS4)
    assert (res.precision, res.recall, res.cr) == (0.0, 0.0, 0.0)


def test_cr_precision_and_recall_count_different_sides() -> None:
    # two distinct found points (0.016 apart > atol) both match the one CCS point (0, 0):
    # precision counts found points (2 of 2), recall counts CCS points (1 of 2).
    res = coverage_ratio([[-0.008, 0.0], [0.008, 0.0]], [[0.0, 0.0], [5.0, 5.0]])
    assert (res.precision, res.recall, res.n_found, res.n_matched) == (1.0, 0.5, 2, 1)
    # one found point matches two distinct CCS points: recall 2 of 2, precision 1 of 1.
    res = coverage_ratio([[0.008, 0.0]], [[0.0, 0.0], [0.016, 0.0]])
    assert (res.precision, res.recall, res.n_found, res.n_ccs, res.n_matched) == (1.0, 1.0, 1, 2, 2)


def test_cr_empty_found() -> None:
    for empty in ([], np.empty((0, 2))):
        res = coverage_ratio(empty, CCS4)
        assert res == CoverageResult(precision=0.0, recall=0.0, cr=0.0, n_found=0, n_ccs=4, n_matched=0)


def test_coverage_result_is_frozen() -> None:
    res = coverage_ratio(CCS4, CCS4)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.cr = 0.0  # type: ignore[misc]


# ----------------------------------------------------------------------------------------- hypervolume
def test_hypervolume_2d_by_hand() -> None:
    pts = [[1.0, 3.0], [2.0, 2.0], [3.0, 1.0]]
    assert hypervolume(pts, [0.0, 0.0]) == pytest.approx(6.0)
    assert hypervolume(pts + [[1.5, 1.5]], [0.0, 0.0]) == pytest.approx(6.0)  # dominated point
    assert hypervolume(pts + [[-1.0, 5.0], [5.0, 0.0]], [0.0, 0.0]) == pytest.approx(6.0)  # not > ref
    assert hypervolume([[2.0, 2.0]], [1.0, -1.0]) == pytest.approx(3.0)


def test_hypervolume_3d_and_degenerate() -> None:
    assert hypervolume([[1.0, 2.0, 3.0]], [0.0, 0.0, 0.0]) == pytest.approx(6.0)
    assert hypervolume(np.empty((0, 2)), [0.0, 0.0]) == 0.0
    assert hypervolume([], [0.0, 0.0]) == 0.0
    assert hypervolume([[-1.0, -1.0]], [0.0, 0.0]) == 0.0


def test_hypervolume_dst() -> None:
    # sum over points sorted by treasure of (T_i - T_{i-1}) * (time_i + 25) = 401.8
    assert hypervolume(DST, [0.0, -25.0]) == pytest.approx(401.8)


# ------------------------------------------------------------------------------------------- utilities
FRONT2 = np.array([[1.0, 0.0], [0.0, 2.0]])


def test_expected_utility_by_hand() -> None:
    returns = [[1.0, 0.0], [0.0, 1.0]]
    prefs = [[0.5, 0.5], [1.0, 0.0]]
    assert expected_utility(returns, prefs) == pytest.approx(0.25)  # (0.5 + 0) / 2


def test_optimal_utility_by_hand() -> None:
    prefs = [[0.5, 0.5], [1.0, 0.0], [0.25, 0.75], [2 / 3, 1 / 3]]
    np.testing.assert_allclose(optimal_utility(prefs, FRONT2), [1.0, 1.0, 1.5, 2 / 3])


def test_optimal_share_by_hand_with_ties() -> None:
    prefs = [[1.0, 0.0], [0.0, 1.0], [2 / 3, 1 / 3], [0.5, 0.5]]
    returns = [[1.0, 0.0]] * 4
    # pref 0: (1,0) optimal; pref 1: (0,2) optimal; pref 2: tie 2/3 vs 2/3, so (1,0) counts;
    # pref 3: (0,2) optimal (1.0 > 0.5).
    assert optimal_share(returns, prefs, FRONT2) == 0.5
    assert optimal_share([[1.0 + 1e-6, 0.0], [0.0, 2.0], [0.0, 2.0], [0.0, 2.0]], prefs, FRONT2) == 1.0
    # a return off the front never counts, even if its utility is high
    assert optimal_share([[5.0, 5.0]] * 4, prefs, FRONT2) == 0.0


def test_optimal_share_exact_tie() -> None:
    front = [[1.0, 0.0], [0.0, 1.0]]
    assert optimal_share([[0.0, 1.0], [1.0, 0.0]], [[0.5, 0.5], [0.5, 0.5]], front) == 1.0


# -------------------------------------------------------------------------------------- evaluate_front
def test_evaluate_front_schema_without_true_front() -> None:
    out = evaluate_front([[1.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [0.0, 1.0]])
    assert tuple(out) == EVALUATE_KEYS
    assert set(out) == {
        "eum",
        "cardinality",
        "hv",
        "cr",
        "precision",
        "recall",
        "eum_optimal",
        "eum_gap",
        "optimal_share",
        "igd",
    }
    assert out["eum"] == 1.0
    assert out["cardinality"] == 2.0
    for key in ("hv", "cr", "precision", "recall", "eum_optimal", "eum_gap", "optimal_share"):
        assert math.isnan(out[key]), key
    assert all(isinstance(v, float) for v in out.values())


def test_evaluate_front_schema_with_true_front() -> None:
    returns = [[1.0, 0.0], [1.0, 0.0]]
    out = evaluate_front(returns, [[1.0, 0.0], [0.5, 0.5]], true_front=FRONT2, ref_point=[0, -1])
    assert tuple(out) == EVALUATE_KEYS
    assert all(isinstance(v, float) and not math.isnan(v) for v in out.values())
    assert out["eum"] == pytest.approx(0.75)  # (1 + 0.5) / 2
    assert out["eum_optimal"] == pytest.approx(1.0)  # (1 + 1) / 2
    assert out["eum_gap"] == pytest.approx(0.25)
    assert out["optimal_share"] == 0.5
    assert (out["precision"], out["recall"], out["cardinality"]) == (1.0, 0.5, 1.0)
    assert out["cr"] == pytest.approx(2 / 3)
    assert out["hv"] == pytest.approx(1.0)  # box [0,1] x [-1,0]


def test_evaluate_front_perfect_agent_on_dst() -> None:
    out = evaluate_front(DST, DST_PREFS, true_front=DST, ref_point=[0.0, -25.0])
    assert out["cr"] == 1.0 and out["precision"] == 1.0 and out["recall"] == 1.0
    assert out["optimal_share"] == 1.0
    assert out["cardinality"] == 10.0
    assert abs(out["eum_gap"]) < 1e-12
    assert out["hv"] == pytest.approx(401.8)


def test_evaluate_front_float32_noise_is_tolerated() -> None:
    noisy = DST.astype(np.float32).astype(np.float64) + 1e-6
    out = evaluate_front(noisy, DST_PREFS, true_front=DST)
    assert (out["cr"], out["optimal_share"], out["cardinality"]) == (1.0, 1.0, 10.0)
    assert abs(out["eum_gap"]) < 1e-5


def test_evaluate_front_cr_can_flatter() -> None:
    # every CCS point is produced, but each for the wrong preference: CR 1, optimal_share 0, gap > 0
    wrong = DST[::-1]
    out = evaluate_front(wrong, DST_PREFS, true_front=DST)
    assert out["cr"] == 1.0
    assert out["optimal_share"] == 0.0
    assert out["eum_gap"] > 1.0


# ---------------------------------------------------------------------------------------------- errors
def test_errors_row_mismatch() -> None:
    with pytest.raises(ValueError, match="returns has 2 rows but prefs has 3 rows"):
        expected_utility([[1.0, 0.0]] * 2, [[1.0, 0.0]] * 3)
    with pytest.raises(ValueError, match="rows"):
        evaluate_front([[1.0, 0.0]] * 2, [[1.0, 0.0]] * 3)


def test_errors_column_mismatch() -> None:
    with pytest.raises(ValueError, match="returns has 3 columns but prefs has 2"):
        expected_utility([[1.0, 0.0, 0.0]], [[1.0, 0.0]])
    with pytest.raises(ValueError, match="true_front has 3 columns"):
        evaluate_front([[1.0, 0.0]], [[1.0, 0.0]], true_front=[[1.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="found has 3 columns"):
        coverage_ratio([[1.0, 0.0, 0.0]], CCS4)


def test_errors_nan_and_inf() -> None:
    with pytest.raises(ValueError, match="returns contain NaN"):
        evaluate_front([[1.0, float("nan")]], [[1.0, 0.0]])
    with pytest.raises(ValueError, match="points contain inf"):
        pareto_front([[1.0, float("inf")]])


def test_errors_ref_point() -> None:
    with pytest.raises(ValueError, match="ref_point has length 3 but points have 2 objectives"):
        hypervolume([[1.0, 1.0]], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="ref_point has shape"):
        evaluate_front([[1.0, 0.0]], [[1.0, 0.0]], ref_point=[0.0])


def test_errors_bad_prefs_and_shapes() -> None:
    with pytest.raises(ValueError, match="sum to 1; row 1 sums to 0.8"):
        expected_utility([[1.0, 0.0]] * 2, [[1.0, 0.0], [0.4, 0.4]])
    with pytest.raises(ValueError, match="non-negative"):
        optimal_utility([[1.5, -0.5]], FRONT2)
    with pytest.raises(ValueError, match="2-D"):
        pareto_front([1.0, 2.0])
    with pytest.raises(ValueError, match="at least one row"):
        expected_utility(np.empty((0, 2)), np.empty((0, 2)))
    with pytest.raises(ValueError, match="ccs must contain at least one row"):
        coverage_ratio(CCS4, np.empty((0, 2)))
    with pytest.raises(ValueError, match="tolerances"):
        match_matrix(CCS4, CCS4, atol=-1.0)


# Property-based tests of these metrics (CR range, CR = 1 iff found = CCS, HV monotone, CCS subset of the
# front) live in tests/test_properties.py.


def test_igd_hand_values():
    front = np.array([[0.0, 4.0], [3.0, 0.0]])
    # every front point found: 0
    assert inverted_generational_distance(front, front) == pytest.approx(0.0)
    # one found point at (0, 0): distances 4 and 3 -> mean 3.5
    assert inverted_generational_distance([[0.0, 0.0]], front) == pytest.approx(3.5)
    # (0, 4) found, (3, 0) missing: nearest to (3, 0) is (0, 4) at distance 5 -> mean 2.5
    assert inverted_generational_distance([[0.0, 4.0]], front) == pytest.approx(2.5)
    with pytest.raises(ValueError):
        inverted_generational_distance(np.zeros((0, 2)), front)


def test_evaluate_front_reports_igd_against_the_pareto_front():
    front = np.array([[0.0, 4.0], [3.0, 0.0], [1.0, 1.0]])  # (1, 1) is Pareto optimal but not in the CCS
    prefs = np.array([[1.0, 0.0], [0.0, 1.0]])
    res = evaluate_front([[3.0, 0.0], [0.0, 4.0]], prefs, true_front=front)
    assert res["cr"] == pytest.approx(1.0)
    # (1, 1) is missed: its nearest found point is (3, 0) at sqrt(5), so IGD = sqrt(5) / 3
    assert res["igd"] == pytest.approx(np.sqrt(5) / 3)
    assert np.isnan(evaluate_front([[3.0, 0.0]], prefs[:1])["igd"])
