"""Evaluation metrics for multi-objective RL agents (all objectives are MAXIMISED).

Preferences ``ω`` are rows on the probability simplex (non-negative, summing to 1), returns and fronts are
arrays of shape ``(n, m)`` with one column per objective.

Coverage ratio (CR) protocol
----------------------------
Following the paper (eq. 8) and Yang et al. (2019, "A Generalized Algorithm for Multi-Objective
Reinforcement Learning and Policy Adaptation"), an agent is evaluated on 2,000 preferences drawn uniformly
from the simplex; for each preference it is rolled out and its vector return is discounted with
``gamma = 0.99``. The multiset of returns is reduced to the set ``P`` of *distinct* solutions
(:func:`unique_solutions`) and compared against the convex coverage set (CCS, paper eq. 3) of the
**discounted** true Pareto front (:func:`convex_coverage_set`), never the undiscounted one::

    precision = |P ∩ CCS| / |P|        recall = |P ∩ CCS| / |CCS|        CR = F1(precision, recall)

Two points "match" when every coordinate satisfies ``|a - b| <= atol + rtol * |b|`` (:func:`match_matrix`).

Why the default tolerance (``DEFAULT_ATOL = 1e-2``, ``DEFAULT_RTOL = 1e-3``)
------------------------------------------------------------------------------
Discounted Deep-Sea-Treasure returns accumulated from float32 rewards differ from the float64 reference front
by about ``1e-6``, so an exact comparison would reject a perfect agent. On the other hand, the nearest two
distinct points of the discounted DST CCS differ by ~0.88 (always >= ~0.5) in some coordinate, and with
returns of magnitude <= ~25 the effective tolerance ``atol + rtol * |b|`` stays below ~0.04, so a tolerance of
this size can never confuse two treasures while being four orders of magnitude above float32 noise.

Errors
------
Bad input raises :class:`mope.errors.MopeError` (a ``ValueError``; :class:`~mope.errors.PreferenceError` for
preferences off the simplex) with a message naming the bad value or shape.

CR is not enough on its own
---------------------------
CR only asks *whether* each CCS point was produced by *some* preference; an agent that emits every CCS point
but for the wrong preferences scores CR = 1. :func:`evaluate_front` therefore reports, beside CR, the
expected-utility gap ``eum_gap = eum_optimal - eum`` (0 for a perfect agent) and ``optimal_share``, the
fraction of preferences whose return *is* one of their own utility-maximising front points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from pymoo.indicators.hv import HV
from pymoo.indicators.igd import IGD
from scipy.optimize import linprog

from mope.errors import MopeError, PreferenceError

__all__ = [
    "DEFAULT_ATOL",
    "DEFAULT_RTOL",
    "EVALUATE_KEYS",
    "CoverageResult",
    "cardinality",
    "convex_coverage_set",
    "coverage_ratio",
    "evaluate_front",
    "expected_utility",
    "hypervolume",
    "inverted_generational_distance",
    "match_matrix",
    "optimal_share",
    "optimal_utility",
    "pareto_front",
    "unique_solutions",
]

DEFAULT_ATOL = 1e-2
DEFAULT_RTOL = 1e-3

#: Keys of the dictionary returned by :func:`evaluate_front`, in order (always all present).
EVALUATE_KEYS: tuple[str, ...] = (
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
)

# Tolerance on the row sums of preference vectors (same as mope.preferences.PREF_SUM_ATOL).
_SIMPLEX_ATOL = 1e-3
# Relative tolerance used to decide that two utilities tie (float round-off only).
_TIE_RTOL = 1e-9
# Upper bound on the number of booleans materialised at once by the dominance check.
_CHUNK_ELEMS = 4_000_000


# --------------------------------------------------------------------------------------------------------
# validation helpers
# --------------------------------------------------------------------------------------------------------
def _as_points(x: ArrayLike, name: str, n_cols: int | None = None, allow_empty: bool = True) -> np.ndarray:
    """Convert ``x`` to a finite float64 array of shape ``(n, m)`` and validate it."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.size == 0 and arr.ndim <= 1:
        arr = arr.reshape(0, 0 if n_cols is None else n_cols)
    if arr.ndim != 2:
        raise MopeError(f"{name} must be a 2-D array of shape (n, m), got shape {arr.shape}")
    if n_cols is not None and arr.shape[1] != n_cols:
        raise MopeError(f"{name} has {arr.shape[1]} columns but {n_cols} objectives were expected")
    if not allow_empty and arr.shape[0] == 0:
        raise MopeError(f"{name} must contain at least one row, got shape {arr.shape}")
    if arr.shape[0] > 0 and arr.shape[1] == 0:
        raise MopeError(f"{name} must have at least one objective column, got shape {arr.shape}")
    if np.isnan(arr).any():
        rows = np.flatnonzero(np.isnan(arr).any(axis=1))
        raise MopeError(f"{name} contain NaN (rows {rows[:10].tolist()})")
    if np.isinf(arr).any():
        rows = np.flatnonzero(np.isinf(arr).any(axis=1))
        raise MopeError(f"{name} contain inf (rows {rows[:10].tolist()})")
    return arr


def _check_tolerances(atol: float, rtol: float) -> None:
    if not (atol >= 0 and rtol >= 0):
        raise MopeError(f"tolerances must be non-negative, got atol={atol}, rtol={rtol}")


def _check_prefs(prefs: np.ndarray) -> None:
    """Raise if any row of ``prefs`` is not on the probability simplex."""
    if prefs.size == 0:
        return
    if (prefs < 0).any():
        i = int(np.argmin(prefs.min(axis=1)))
        raise PreferenceError(f"prefs must be non-negative; row {i} is {prefs[i].tolist()}")
    dev = np.abs(prefs.sum(axis=1) - 1.0)
    if (dev > _SIMPLEX_ATOL).any():
        i = int(np.argmax(dev))
        raise PreferenceError(f"prefs rows must sum to 1; row {i} sums to {prefs[i].sum():.6g}")


def _returns_and_prefs(returns: ArrayLike, prefs: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Validate a (returns, prefs) pair: same non-zero row count and the same number of objectives."""
    r = _as_points(returns, "returns", allow_empty=False)
    p = _as_points(prefs, "prefs", allow_empty=False)
    if r.shape[0] != p.shape[0]:
        raise MopeError(f"returns has {r.shape[0]} rows but prefs has {p.shape[0]} rows; they must match")
    if r.shape[1] != p.shape[1]:
        raise MopeError(
            f"returns has {r.shape[1]} columns but prefs has {p.shape[1]}; "
            "the number of objectives must match"
        )
    _check_prefs(p)
    return r, p


def _greedy_unique(x: np.ndarray, atol: float, rtol: float) -> np.ndarray:
    """Indices (ascending) of greedy representatives: each kept row absorbs later rows matching it."""
    covered = np.zeros(x.shape[0], dtype=bool)
    keep: list[int] = []
    while not covered.all():  # one iteration per distinct solution
        i = int(np.argmax(~covered))
        keep.append(i)
        covered |= np.all(np.abs(x - x[i]) <= atol + rtol * np.abs(x[i]), axis=1)
    return np.asarray(keep, dtype=np.intp)


# --------------------------------------------------------------------------------------------------------
# fronts
# --------------------------------------------------------------------------------------------------------
def pareto_front(points: ArrayLike, tol: float = 1e-9) -> np.ndarray:
    """Non-dominated rows of ``points`` under maximisation.

    A row is dominated if another row is ``>=`` in every objective and ``>`` in at least one (exact
    comparison). Among the survivors, rows within ``tol`` (max-abs) of an earlier row are dropped.

    Args:
        points: Array of shape ``(n, m)``.
        tol: Absolute tolerance used to remove duplicates.

    Returns:
        The Pareto-optimal rows in their original (first-occurrence) order, shape ``(k, m)``.
    """
    x = _as_points(points, "points")
    n, m = x.shape
    if n == 0:
        return x.copy()
    dominated = np.empty(n, dtype=bool)
    chunk = max(1, _CHUNK_ELEMS // max(1, n * m))
    for s in range(0, n, chunk):
        c = x[s : s + chunk, None, :]  # (c, 1, m) candidates vs (1, n, m) all rows
        geq = np.all(x[None, :, :] >= c, axis=2)
        gt = np.any(x[None, :, :] > c, axis=2)
        dominated[s : s + chunk] = np.any(geq & gt, axis=1)
    front = x[~dominated]
    return front[_greedy_unique(front, atol=tol, rtol=0.0)]


def convex_coverage_set(points: ArrayLike, tol: float = 1e-9) -> np.ndarray:
    """Convex coverage set (paper eq. 3) of ``points`` under maximisation.

    A Pareto-optimal point ``p`` is kept iff some ``w`` on the simplex has ``w·p >= w·q`` for every other
    Pareto point ``q``. This is decided for any number of objectives by the LP
    ``max t  s.t.  w·(p - q) >= t  for all q != p,  sum(w) = 1,  w >= 0``; ``p`` is kept if ``t >= -tol``.
    Points on a face of the hull (weak ties) are therefore kept.

    Args:
        points: Array of shape ``(n, m)``.
        tol: Absolute slack on the LP value ``t``.

    Returns:
        The CCS rows, a subset of :func:`pareto_front` in the same order.
    """
    front = pareto_front(points)
    k, m = front.shape
    if k <= 1 or m == 1:
        return front
    keep = np.zeros(k, dtype=bool)
    c = np.zeros(m + 1)
    c[-1] = -1.0  # minimise -t
    a_eq = np.append(np.ones(m), 0.0)[None, :]
    bounds = [(0.0, 1.0)] * m + [(None, None)]
    for i in range(k):  # one small LP per CCS candidate
        diff = front[i] - np.delete(front, i, axis=0)  # rows p - q
        a_ub = np.hstack([-diff, np.ones((k - 1, 1))])  # t - w·(p - q) <= 0
        res = linprog(
            c, A_ub=a_ub, b_ub=np.zeros(k - 1), A_eq=a_eq, b_eq=[1.0], bounds=bounds, method="highs"
        )
        if res.status != 0:
            raise RuntimeError(f"CCS linear program failed for point {front[i].tolist()}: {res.message}")
        keep[i] = -res.fun >= -tol
    return front[keep]


# --------------------------------------------------------------------------------------------------------
# matching / coverage
# --------------------------------------------------------------------------------------------------------
def match_matrix(
    a: ArrayLike, b: ArrayLike, atol: float = DEFAULT_ATOL, rtol: float = DEFAULT_RTOL
) -> np.ndarray:
    """Pairwise tolerance matching.

    Args:
        a: Array of shape ``(n, m)``.
        b: Array of shape ``(k, m)``.
        atol: Absolute tolerance.
        rtol: Relative tolerance (relative to ``|b_j|``).

    Returns:
        Boolean array ``M`` of shape ``(n, k)`` with ``M[i, j]`` true iff ``|a_i - b_j| <= atol + rtol*|b_j|``
        holds in every coordinate.
    """
    _check_tolerances(atol, rtol)
    b_arr = _as_points(b, "b")
    a_arr = _as_points(a, "a", n_cols=b_arr.shape[1] if b_arr.shape[0] else None)
    if b_arr.shape == (0, 0):
        b_arr = b_arr.reshape(0, a_arr.shape[1])
    if a_arr.shape[1] != b_arr.shape[1]:
        raise MopeError(f"a has {a_arr.shape[1]} columns but b has {b_arr.shape[1]}")
    diff = np.abs(a_arr[:, None, :] - b_arr[None, :, :])
    return np.all(diff <= atol + rtol * np.abs(b_arr)[None, :, :], axis=2)


def unique_solutions(points: ArrayLike, atol: float = DEFAULT_ATOL, rtol: float = DEFAULT_RTOL) -> np.ndarray:
    """Distinct solutions of ``points`` (the set ``P`` of paper eq. 8), by greedy de-duplication.

    Rows are scanned in order; a row is kept unless it matches (:func:`match_matrix`) an already kept row.

    Args:
        points: Array of shape ``(n, m)``.
        atol: Absolute matching tolerance.
        rtol: Relative matching tolerance.

    Returns:
        The kept rows, in first-occurrence order.
    """
    _check_tolerances(atol, rtol)
    x = _as_points(points, "points")
    return x[_greedy_unique(x, atol, rtol)]


def cardinality(points: ArrayLike, atol: float = DEFAULT_ATOL, rtol: float = DEFAULT_RTOL) -> int:
    """Number of distinct solutions in ``points`` (see :func:`unique_solutions`).

    Args:
        points: Array of shape ``(n, m)``.
        atol: Absolute matching tolerance.
        rtol: Relative matching tolerance.

    Returns:
        The number of distinct rows.
    """
    return int(unique_solutions(points, atol, rtol).shape[0])


@dataclass(frozen=True)
class CoverageResult:
    """Result of :func:`coverage_ratio`.

    Attributes:
        precision: Share of distinct found solutions that match some CCS point.
        recall: Share of (distinct) CCS points matched by some found solution.
        cr: Coverage ratio, the F1 score of precision and recall (0 when both are 0).
        n_found: Number of distinct found solutions ``|P|``.
        n_ccs: Number of distinct CCS points.
        n_matched: Number of CCS points matched by some found solution (the recall numerator).
    """

    precision: float
    recall: float
    cr: float
    n_found: int
    n_ccs: int
    n_matched: int


def coverage_ratio(
    found: ArrayLike, ccs: ArrayLike, atol: float = DEFAULT_ATOL, rtol: float = DEFAULT_RTOL
) -> CoverageResult:
    """Coverage ratio of paper eq. 8 (F1 of precision and recall against the CCS).

    Args:
        found: Returns obtained by the agent, shape ``(n, m)``; may contain duplicates or be empty.
        ccs: The reference convex coverage set, shape ``(k, m)`` with ``k >= 1``.
        atol: Absolute matching tolerance.
        rtol: Relative matching tolerance.

    Returns:
        A :class:`CoverageResult`; empty ``found`` gives precision, recall and CR of 0.
    """
    _check_tolerances(atol, rtol)
    ref = unique_solutions(_as_points(ccs, "ccs", allow_empty=False), atol, rtol)
    p = unique_solutions(_as_points(found, "found", n_cols=ref.shape[1]), atol, rtol)
    n_found, n_ccs = p.shape[0], ref.shape[0]
    if n_found == 0:
        return CoverageResult(0.0, 0.0, 0.0, 0, n_ccs, 0)
    m = match_matrix(p, ref, atol, rtol)
    n_prec = int(m.any(axis=1).sum())
    n_rec = int(m.any(axis=0).sum())
    precision = n_prec / n_found
    recall = n_rec / n_ccs
    cr = 0.0 if precision + recall == 0 else 2.0 * precision * recall / (precision + recall)
    return CoverageResult(float(precision), float(recall), float(cr), n_found, n_ccs, n_rec)


# --------------------------------------------------------------------------------------------------------
# hypervolume / utility
# --------------------------------------------------------------------------------------------------------
def hypervolume(points: ArrayLike, ref_point: ArrayLike) -> float:
    """Hypervolume dominated by ``points`` and bounded below by ``ref_point`` (maximisation).

    Points that are not strictly better than ``ref_point`` in every objective contribute nothing.

    Args:
        points: Array of shape ``(n, m)``; may be empty.
        ref_point: Array of shape ``(m,)``.

    Returns:
        The hypervolume (0.0 for an empty or fully non-improving set).
    """
    ref = np.asarray(ref_point, dtype=np.float64)
    if ref.ndim != 1 or ref.size == 0:
        raise MopeError(f"ref_point must be a 1-D array of length m, got shape {ref.shape}")
    if not np.isfinite(ref).all():
        raise MopeError(f"ref_point must be finite, got {ref.tolist()}")
    x = np.asarray(points, dtype=np.float64)
    if x.ndim == 2 and x.shape[1] != ref.size:
        raise MopeError(f"ref_point has length {ref.size} but points have {x.shape[1]} objectives")
    x = _as_points(x, "points", n_cols=ref.size)
    if x.shape[0] == 0:
        return 0.0
    x = x[np.all(x > ref, axis=1)]
    if x.shape[0] == 0:
        return 0.0
    # pymoo minimises: negate both the points and the reference point.
    return float(HV(ref_point=-ref)(-x))


def inverted_generational_distance(points: ArrayLike, front: ArrayLike) -> float:
    """IGD: the mean, over the points of ``front``, of the Euclidean distance to the nearest of ``points``.

    The distance of a found set to a known front (0 when every front point is found; pymoo's ``IGD``).

    Args:
        points: Found returns, shape ``(n, m)``, ``n >= 1``.
        front: The true (Pareto) front, shape ``(k, m)``, ``k >= 1``.
    """
    f = _as_points(front, "front", allow_empty=False)
    x = _as_points(points, "points", n_cols=f.shape[1], allow_empty=False)
    return float(IGD(f)(x))


def expected_utility(returns: ArrayLike, prefs: ArrayLike) -> float:
    """Expected utility metric (EUM): mean of ``prefs[i] · returns[i]``.

    Args:
        returns: Array of shape ``(n, m)``; ``returns[i]`` is the return obtained under ``prefs[i]``.
        prefs: Preferences on the simplex, shape ``(n, m)``.

    Returns:
        The mean linear utility.
    """
    r, p = _returns_and_prefs(returns, prefs)
    return float(np.mean(np.einsum("ij,ij->i", r, p)))


def _front_for(front: ArrayLike, m: int) -> np.ndarray:
    return _as_points(front, "front", n_cols=m, allow_empty=False)


def optimal_utility(prefs: ArrayLike, front: ArrayLike) -> np.ndarray:
    """Best achievable utility per preference, ``max_v w·v`` over ``front``.

    Args:
        prefs: Preferences on the simplex, shape ``(n, m)``.
        front: Candidate returns (e.g. the true Pareto front), shape ``(k, m)``.

    Returns:
        Array of shape ``(n,)``.
    """
    p = _as_points(prefs, "prefs")
    _check_prefs(p)
    f = _front_for(front, p.shape[1])
    if p.shape[0] == 0:
        return np.zeros(0)
    return (p @ f.T).max(axis=1)


def optimal_share(
    returns: ArrayLike,
    prefs: ArrayLike,
    front: ArrayLike,
    atol: float = DEFAULT_ATOL,
    rtol: float = DEFAULT_RTOL,
) -> float:
    """Share of preferences whose return is one of their own utility-maximising front points.

    ``returns[i]`` counts if it matches (:func:`match_matrix`) some ``v`` in ``front`` attaining
    ``max_v prefs[i]·v``; with ties every maximiser counts.

    Args:
        returns: Array of shape ``(n, m)``.
        prefs: Preferences on the simplex, shape ``(n, m)``.
        front: The reference front, shape ``(k, m)``.
        atol: Absolute matching tolerance.
        rtol: Relative matching tolerance.

    Returns:
        A fraction in ``[0, 1]``.
    """
    _check_tolerances(atol, rtol)
    r, p = _returns_and_prefs(returns, prefs)
    f = _front_for(front, r.shape[1])
    util = p @ f.T  # (n, k)
    best = util.max(axis=1, keepdims=True)
    is_max = util >= best - _TIE_RTOL * (1.0 + np.abs(best))
    ok = np.any(match_matrix(r, f, atol, rtol) & is_max, axis=1)
    return float(ok.mean())


# --------------------------------------------------------------------------------------------------------
# summary
# --------------------------------------------------------------------------------------------------------
def evaluate_front(
    returns: ArrayLike,
    prefs: ArrayLike,
    true_front: ArrayLike | None = None,
    ref_point: ArrayLike | None = None,
    atol: float = DEFAULT_ATOL,
    rtol: float = DEFAULT_RTOL,
) -> dict[str, float]:
    """The one metric summary of an evaluation run.

    Args:
        returns: Returns of the agent, shape ``(n, m)``; ``returns[i]`` obtained under ``prefs[i]``.
        prefs: Preferences on the simplex, shape ``(n, m)``.
        true_front: The known (discounted) Pareto front, shape ``(k, m)``, or ``None``.
        ref_point: Hypervolume reference point of length ``m``, or ``None``.
        atol: Absolute matching tolerance.
        rtol: Relative matching tolerance.

    Returns:
        A dict with exactly the keys of :data:`EVALUATE_KEYS`: ``eum``, ``cardinality``, ``hv`` (nan without
        ``ref_point``) and ``cr``, ``precision``, ``recall`` (against ``convex_coverage_set(true_front)``),
        ``eum_optimal``, ``eum_gap`` (``eum_optimal - eum``), ``optimal_share`` and ``igd`` (all nan without
        ``true_front``).
    """
    _check_tolerances(atol, rtol)
    r, p = _returns_and_prefs(returns, prefs)
    m = r.shape[1]
    out = dict.fromkeys(EVALUATE_KEYS, math.nan)
    out["eum"] = expected_utility(r, p)
    out["cardinality"] = float(cardinality(r, atol, rtol))
    if ref_point is not None:
        ref = np.asarray(ref_point, dtype=np.float64)
        if ref.shape != (m,):
            raise MopeError(f"ref_point has shape {ref.shape} but returns have {m} objectives")
        out["hv"] = hypervolume(r, ref)
    if true_front is not None:
        f = _as_points(true_front, "true_front", n_cols=m, allow_empty=False)
        cov = coverage_ratio(r, convex_coverage_set(f), atol, rtol)
        out["cr"], out["precision"], out["recall"] = cov.cr, cov.precision, cov.recall
        out["eum_optimal"] = float(np.mean(optimal_utility(p, f)))
        out["eum_gap"] = out["eum_optimal"] - out["eum"]
        out["optimal_share"] = optimal_share(r, p, f, atol, rtol)
        out["igd"] = inverted_generational_distance(unique_solutions(r, atol, rtol), pareto_front(f))
    return out
