"""Tests of mope.preferences: simplex sampling, validation, relabeling neighbours and preference exploration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mope.errors import PreferenceError
from mope.preferences import (
    PreferencePartition,
    PreferenceSampler,
    equally_spaced,
    parse_preference,
    pe_cell_probs,
    sample_neighbours,
    sample_simplex,
    validate_preference,
)


def assert_on_simplex(x: np.ndarray, atol: float = 1e-9) -> None:
    x = np.asarray(x)
    assert np.all(np.isfinite(x))
    assert np.all(x >= 0.0)
    np.testing.assert_allclose(x.sum(axis=-1), 1.0, atol=atol)


# ------------------------------------------------------------------------------------------- sample_simplex
# Rows on the simplex for any n, m and seed: tests/test_properties.py::test_sample_simplex_on_simplex.


def test_sample_simplex_seeded_reproducible_and_seed_dependent() -> None:
    a = sample_simplex(50, 3, np.random.default_rng(7))
    b = sample_simplex(50, 3, np.random.default_rng(7))
    c = sample_simplex(50, 3, np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_sample_simplex_is_uniform_in_first_coordinate_for_m2() -> None:
    # Dirichlet(1, 1): the first coordinate is Uniform(0, 1), so each decile holds ~10%.
    x = sample_simplex(20_000, 2, np.random.default_rng(1))
    hist = np.histogram(x[:, 0], bins=10, range=(0.0, 1.0))[0] / 20_000
    np.testing.assert_allclose(hist, 0.1, atol=0.015)


def test_sample_simplex_marginal_mean_m3() -> None:
    # Dirichlet(1, 1, 1): each coordinate has mean 1/3.
    x = sample_simplex(20_000, 3, np.random.default_rng(2))
    np.testing.assert_allclose(x.mean(axis=0), 1.0 / 3.0, atol=0.01)


# ------------------------------------------------------------------------------------------- equally_spaced
def test_equally_spaced_m2_exact_endpoints_and_grid() -> None:
    x = equally_spaced(2, 5)
    expected = np.array([[0.0, 1.0], [0.25, 0.75], [0.5, 0.5], [0.75, 0.25], [1.0, 0.0]])
    np.testing.assert_array_equal(x, expected)


def test_equally_spaced_m2_hundred_points() -> None:
    x = equally_spaced(2, 100)
    assert x.shape == (100, 2)
    assert x[0].tolist() == [0.0, 1.0]
    assert x[-1].tolist() == [1.0, 0.0]
    np.testing.assert_allclose(np.diff(x[:, 0]), 1.0 / 99.0)


def test_equally_spaced_m3_lattice_on_simplex() -> None:
    x = equally_spaced(3, 10)
    # Das-Dennis with h partitions has C(h + 2, 2) points; the largest <= 10 is h = 3 -> 10 points.
    assert x.shape == (10, 3)
    assert_on_simplex(x)
    # every coordinate is a multiple of 1/3, and all three vertices are present
    np.testing.assert_allclose(x * 3.0, np.round(x * 3.0), atol=1e-9)
    rows = {tuple(np.round(r, 9)) for r in x}
    assert {(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)} <= rows
    assert len(rows) == 10


def test_equally_spaced_m3_never_exceeds_n() -> None:
    for n in (3, 6, 7, 15, 16, 100):
        x = equally_spaced(3, n)
        assert 1 <= len(x) <= n
        assert_on_simplex(x)


def test_equally_spaced_m4_lattice_sizes() -> None:
    # Das-Dennis sizes for m = 4: C(h + 3, 3) = 4, 10, 20, 35, 56, ...
    assert len(equally_spaced(4, 35)) == 35
    assert len(equally_spaced(4, 34)) == 20
    assert len(equally_spaced(4, 4)) == 4
    assert_on_simplex(equally_spaced(4, 35))


@pytest.mark.parametrize(("m", "n"), [(3, 1), (3, 2), (4, 3)])
def test_equally_spaced_below_m_returns_the_vertices(m: int, n: int) -> None:
    got = equally_spaced(m, n)
    np.testing.assert_allclose(got[np.lexsort(got.T)], np.eye(m)[np.lexsort(np.eye(m).T)])


def test_equally_spaced_m1_and_bad_arguments() -> None:
    np.testing.assert_array_equal(equally_spaced(1, 5), [[1.0]])
    with pytest.raises(PreferenceError, match="m=0"):
        equally_spaced(0, 5)
    with pytest.raises(PreferenceError, match="n=0"):
        equally_spaced(2, 0)


# ------------------------------------------------------------------------------------------- validation
def test_validate_preference_accepts_and_renormalises() -> None:
    out = validate_preference([0.3, 0.7], 2)
    assert out.dtype == np.float64
    np.testing.assert_allclose(out, [0.3, 0.7])
    # within the 1e-3 tolerance: renormalised exactly
    out = validate_preference([0.5, 0.5005], 2)
    assert out.sum() == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(out, [0.5 / 1.0005, 0.5005 / 1.0005])


def test_validate_preference_accepts_batches() -> None:
    out = validate_preference(np.array([[1.0, 0.0], [0.25, 0.75]]), 2)
    assert out.shape == (2, 2)
    np.testing.assert_allclose(out, [[1.0, 0.0], [0.25, 0.75]])


@pytest.mark.parametrize("text", ["0.3,0.7", "0.3 0.7", " 0.3, 0.7 "])
def test_validate_preference_accepts_strings(text: str) -> None:
    assert parse_preference(text) == [0.3, 0.7]
    np.testing.assert_allclose(validate_preference(text, 2), [0.3, 0.7])


@pytest.mark.parametrize(
    ("pref", "m", "needle"),
    [
        ([0.2, 0.3, 0.5], 2, "length 3"),
        ([1.0], 2, "length 1"),
        ([-0.2, 1.2], 2, "negative"),
        ([float("nan"), 1.0], 2, "NaN"),
        ([float("inf"), 0.0], 2, "inf"),
        ([0.3, 0.3], 2, "sums to 0.6"),
        ([0.7, 0.7], 2, "sums to 1.4"),
        ([], 2, "empty"),
        ("", 2, "empty"),
        ("0.3,abc", 2, "not a list of numbers"),
    ],
)
def test_validate_preference_rejects(pref: object, m: int, needle: str) -> None:
    with pytest.raises(PreferenceError, match=needle):
        validate_preference(pref, m)  # type: ignore[arg-type]


def test_validate_preference_error_names_the_value() -> None:
    with pytest.raises(PreferenceError) as info:
        validate_preference([-0.25, 1.25], 2)
    assert "-0.25" in str(info.value) and "1.25" in str(info.value)
    with pytest.raises(PreferenceError) as info:
        validate_preference([0.1, 0.2, 0.7], 2)
    assert "0.1" in str(info.value) and "0.7" in str(info.value) and "2 objectives" in str(info.value)
    with pytest.raises(PreferenceError) as info:
        validate_preference([0.5, 0.2], 2)
    assert "0.5" in str(info.value) and "0.2" in str(info.value) and "0.7" in str(info.value)


def test_validate_preference_rejects_bad_row_in_batch() -> None:
    with pytest.raises(PreferenceError, match="sums to 0.5"):
        validate_preference([[0.5, 0.5], [0.25, 0.25]], 2)


def test_preference_error_is_value_error() -> None:
    with pytest.raises(ValueError):
        validate_preference([2.0, -1.0], 2)


# ------------------------------------------------------------------------------------------- neighbours
SIGMA = 0.04


def check_neighbours(centers: np.ndarray, nb: np.ndarray, sigma: float) -> None:
    b, m = centers.shape
    assert nb.shape[0] == b and nb.shape[2] == m
    assert_on_simplex(nb)
    dist = np.linalg.norm(nb - centers[:, None, :], axis=-1)
    assert dist.max() <= sigma + 1e-9


@pytest.mark.parametrize(
    "center",
    [
        [1.0, 0.0],
        [0.0, 1.0],
        [0.5, 0.5],
        [0.99, 0.01],
        [1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.5, 0.5, 0.0],
        [0.0, 0.3, 0.7],
        [1 / 3, 1 / 3, 1 / 3],
        [0.98, 0.01, 0.01],
    ],
)
def test_sample_neighbours_within_sigma_on_simplex_and_spread(center: list[float]) -> None:
    c = np.array([center])
    nb = sample_neighbours(c, 200, SIGMA, np.random.default_rng(0))
    assert nb.shape == (1, 200, len(center))
    check_neighbours(c, nb, SIGMA)
    dist = np.linalg.norm(nb[0] - c[0], axis=-1)
    # spread: not all equal to the center, and the farthest one uses a good part of the radius
    assert np.sum(dist > 1e-6) >= 50
    assert dist.max() > 0.5 * SIGMA
    assert len(np.unique(np.round(nb[0], 12), axis=0)) >= 50


def test_sample_neighbours_interior_is_uniform_in_ball_m2() -> None:
    # Far from the boundary, m = 2: the offset along (1, -1)/sqrt(2) is uniform on [-sigma, sigma].
    c = np.array([[0.5, 0.5]])
    nb = sample_neighbours(c, 20_000, SIGMA, np.random.default_rng(3))[0]
    offset = (nb[:, 0] - 0.5) * math.sqrt(2.0)
    assert np.abs(offset).max() <= SIGMA + 1e-12
    hist = np.histogram(offset, bins=4, range=(-SIGMA, SIGMA))[0] / 20_000
    np.testing.assert_allclose(hist, 0.25, atol=0.02)


def test_sample_neighbours_interior_fills_the_disc_m3() -> None:
    # Uniform in a 2-d disc of radius sigma: P(r <= sigma / 2) = 1/4.
    c = np.array([[0.4, 0.3, 0.3]])
    nb = sample_neighbours(c, 20_000, SIGMA, np.random.default_rng(4))[0]
    r = np.linalg.norm(nb - c[0], axis=-1)
    assert np.mean(r <= SIGMA / 2) == pytest.approx(0.25, abs=0.02)
    # directions are isotropic in the plane: the mean offset is ~0
    np.testing.assert_allclose((nb - c[0]).mean(axis=0), 0.0, atol=1e-3)


def test_sample_neighbours_batched_centers_and_reproducible() -> None:
    centers = np.array([[1.0, 0.0, 0.0], [0.2, 0.3, 0.5], [0.5, 0.0, 0.5]])
    a = sample_neighbours(centers, 16, SIGMA, np.random.default_rng(11))
    b = sample_neighbours(centers, 16, SIGMA, np.random.default_rng(11))
    assert a.shape == (3, 16, 3)
    np.testing.assert_array_equal(a, b)
    check_neighbours(centers, a, SIGMA)


def test_sample_neighbours_m1() -> None:
    nb = sample_neighbours(np.ones((2, 1)), 5, SIGMA, np.random.default_rng(0))
    np.testing.assert_array_equal(nb, np.ones((2, 5, 1)))


# The property versions (any center, sigma and m = 2..5) live in tests/test_properties.py.


# ------------------------------------------------------------------------------------------- partition
@pytest.fixture(scope="module")
def partition3() -> PreferencePartition:
    return PreferencePartition(3, 10)


def test_partition_m2_equal_intervals() -> None:
    p = PreferencePartition(2, 10)
    assert p.n_cells == 10
    np.testing.assert_allclose(p.volumes, 0.1)
    prefs = np.array([[0.05, 0.95], [0.0, 1.0], [0.15, 0.85], [0.55, 0.45], [0.999, 0.001], [1.0, 0.0]])
    assert p.cell_of(prefs).tolist() == [0, 0, 1, 5, 9, 9]
    assert p.cell_of(np.array([0.999, 0.001])).tolist() == [9]


def test_partition_m2_sample_in_cell() -> None:
    p = PreferencePartition(2, 10)
    rng = np.random.default_rng(0)
    for cell in range(10):
        for _ in range(20):
            w = p.sample_in_cell(cell, rng)
            assert_on_simplex(w)
            assert cell / 10 <= w[0] < (cell + 1) / 10
            assert p.cell_of(w)[0] == cell


def test_partition_m3_cells_have_nearly_equal_volume(partition3: PreferencePartition) -> None:
    p = partition3
    assert p.anchors.shape == (10, 3)
    assert_on_simplex(p.anchors)
    assert p.volumes.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(p.volumes, 0.1, atol=0.02)
    # an independent uniform sample lands in the cells at about the same rates
    x = sample_simplex(20_000, 3, np.random.default_rng(123))
    freq = np.bincount(p.cell_of(x), minlength=10) / 20_000
    np.testing.assert_allclose(freq, 0.1, atol=0.025)


def test_partition_m3_anchor_is_in_its_own_cell_and_deterministic(partition3: PreferencePartition) -> None:
    p = partition3
    q = PreferencePartition(3, 10)
    np.testing.assert_array_equal(p.anchors, q.anchors)
    assert p.cell_of(p.anchors).tolist() == list(range(10))


def test_partition_m3_sample_in_cell_lands_in_cell(partition3: PreferencePartition) -> None:
    p = partition3
    rng = np.random.default_rng(5)
    for cell in range(10):
        pts = np.array([p.sample_in_cell(cell, rng) for _ in range(10)])
        assert_on_simplex(pts)
        assert (p.cell_of(pts) == cell).all()


def test_partition_m1_and_bad_arguments() -> None:
    p = PreferencePartition(1, 10)
    assert p.n_cells == 1
    assert p.cell_of(np.ones((3, 1))).tolist() == [0, 0, 0]
    np.testing.assert_array_equal(p.sample_in_cell(0, np.random.default_rng(0)), [1.0])
    with pytest.raises(PreferenceError, match="n_cells=0"):
        PreferencePartition(2, 0)


# ------------------------------------------------------------------------------------------- PE distribution
def test_pe_cell_probs_hand_example() -> None:
    p = pe_cell_probs(np.array([0, 3]), 0.01)
    w = np.array([0.01**-0.5, 3.01**-0.5])  # [10, 0.57639...]
    np.testing.assert_allclose(p, w / w.sum())
    np.testing.assert_allclose(p, [10 / (10 + 3.01**-0.5), 3.01**-0.5 / (10 + 3.01**-0.5)])
    assert p[0] == pytest.approx(0.945502, abs=1e-6)


def test_pe_cell_probs_uniform_when_counts_equal_and_decreasing_in_counts() -> None:
    np.testing.assert_allclose(pe_cell_probs(np.zeros(4)), 0.25)
    np.testing.assert_allclose(pe_cell_probs(np.full(4, 7)), 0.25)
    p = pe_cell_probs(np.array([0, 1, 10, 100]))
    assert p.sum() == pytest.approx(1.0)
    assert np.all(np.diff(p) < 0)
    # ratio of two cells = sqrt of the inverse ratio of (count + offset)
    assert p[2] / p[3] == pytest.approx(math.sqrt(100.01 / 10.01))


def test_sampler_cell_probs_modes() -> None:
    uni = PreferenceSampler(2, 10, exploration=False)
    np.testing.assert_allclose(uni.cell_probs(), 0.1)
    pe = PreferenceSampler(2, 10, exploration=True, count_offset=0.01)
    pe.counts[:] = [0, 3, 0, 0, 0, 0, 0, 0, 0, 0]
    np.testing.assert_allclose(pe.cell_probs(), pe_cell_probs(pe.counts, 0.01))
    np.testing.assert_allclose(pe.log_prob_cells(np.array([1, 0])), np.log(pe_cell_probs(pe.counts, 0.01))[[1, 0]])


def test_sampler_counts_every_draw() -> None:
    for exploration in (False, True):
        s = PreferenceSampler(2, 10, exploration=exploration)
        rng = np.random.default_rng(0)
        prefs = np.array([s.sample(rng) for _ in range(40)])
        assert_on_simplex(prefs)
        assert s.counts.sum() == 40
        np.testing.assert_array_equal(s.counts, np.bincount(s.partition.cell_of(prefs), minlength=10))


def test_sampler_exploration_goes_to_unvisited_cells() -> None:
    s = PreferenceSampler(2, 10, exploration=True)
    s.counts[:] = [100, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    rng = np.random.default_rng(0)
    cells = s.partition.cell_of(np.array([s.sample(rng) for _ in range(50)]))
    new = np.bincount(cells, minlength=10)
    # p(cell 0) starts at 0.1 / (0.1 + 9 * 10) ~ 0.001 and stays small: almost every draw goes elsewhere
    assert new[0] <= 2
    assert (new[1:] >= 3).all()
    # without exploration the same start changes nothing: cell 0 gets its 10% share
    u = PreferenceSampler(2, 10, exploration=False)
    u.counts[:] = [100, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    u_rng = np.random.default_rng(0)
    u_cells = u.partition.cell_of(np.array([u.sample(u_rng) for _ in range(2000)]))
    assert np.mean(u_cells == 0) == pytest.approx(0.1, abs=0.03)


def test_sampler_exploration_covers_cells_faster_than_uniform() -> None:
    # From zero counts an unvisited cell weighs 0.01^-1/2 = 10 against (1.01)^-1/2 ~ 1 for a visited one, so PE
    # visits ~9 of 10 cells in its first 10 draws; uniform sampling only ~6.5 (coupon collector: 10 * (1 - 0.9^10)).
    distinct: dict[bool, list[int]] = {True: [], False: []}
    for seed in range(20):
        for exploration in (True, False):
            s = PreferenceSampler(2, 10, exploration=exploration)
            rng = np.random.default_rng(seed)
            for _ in range(10):
                s.sample(rng)
            distinct[exploration].append(int((s.counts > 0).sum()))
    assert np.mean(distinct[True]) >= 8.5
    assert np.mean(distinct[False]) <= 7.5
    assert min(distinct[True]) >= 7


def test_sampler_exploration_m3_counts_and_visits_every_cell(partition3: PreferencePartition) -> None:
    s = PreferenceSampler(3, 10, exploration=True)
    rng = np.random.default_rng(0)
    prefs = np.array([s.sample(rng) for _ in range(30)])
    assert_on_simplex(prefs)
    assert s.counts.sum() == 30
    np.testing.assert_array_equal(s.counts, np.bincount(s.partition.cell_of(prefs), minlength=10))
    assert (s.counts >= 1).all()


def test_sampler_state_dict_round_trip() -> None:
    s = PreferenceSampler(2, 10, exploration=True)
    rng = np.random.default_rng(0)
    for _ in range(25):
        s.sample(rng)
    state = s.state_dict()
    assert state == {"counts": s.counts.tolist()}
    t = PreferenceSampler(2, 10, exploration=True)
    t.load_state_dict(state)
    np.testing.assert_array_equal(t.counts, s.counts)
    np.testing.assert_allclose(t.cell_probs(), s.cell_probs())
    # the restored sampler continues exactly like the original
    np.testing.assert_array_equal(s.sample(np.random.default_rng(9)), t.sample(np.random.default_rng(9)))


def test_sampler_load_state_dict_rejects_wrong_size() -> None:
    s = PreferenceSampler(2, 10, exploration=True)
    with pytest.raises(PreferenceError, match="3 cells, expected 10"):
        s.load_state_dict({"counts": [1, 2, 3]})
