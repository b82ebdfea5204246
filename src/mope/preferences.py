"""Preferences: sampling on the simplex, validation, relabeling neighbours and preference exploration.

A preference (weight) ``omega`` is a point of the probability simplex of dimension ``m`` (the number of
objectives): non-negative entries that sum to 1. The scalarised reward is ``omega^T r`` (paper, sec. 2).

This module is the one source of preferences in mope:

* :func:`sample_simplex` -- uniform sampling, Dirichlet(1, ..., 1).
* :func:`equally_spaced` -- a regular grid of preferences (for EUM and plots).
* :func:`validate_preference` -- user input checks.
* :func:`sample_neighbours` -- "similar preference exploration" (sec. 3): N_omega preferences within L2
  radius sigma_omega of a transition's own preference.
* :class:`PreferencePartition` and :class:`PreferenceSampler` -- the N_I intervals of preference
  exploration (PE) and the count-based sampling distribution p(omega) ~ (N_i + 0.01)^(-1/2).

All randomness comes from a ``numpy.random.Generator`` owned by the agent, so a seed reproduces a run.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mope.errors import PreferenceError

PREF_SUM_ATOL = 1e-3


def sample_simplex(n: int, m: int, rng: np.random.Generator) -> np.ndarray:
    """Draw ``n`` preferences uniformly from the ``m``-simplex (Dirichlet(1, ..., 1)).

    Args:
        n: Number of preferences.
        m: Number of objectives.
        rng: The caller's generator.

    Returns:
        Array of shape ``(n, m)``, rows on the simplex.
    """
    e = rng.exponential(size=(n, m))
    return e / e.sum(axis=1, keepdims=True)


def equally_spaced(m: int, n: int) -> np.ndarray:
    """Equally spaced preferences on the simplex.

    For ``m == 2`` this is ``n`` points ``(w, 1 - w)`` with ``w`` on ``linspace(0, 1, n)``. For ``m > 2`` it is
    the Das-Dennis simplex lattice (via pymoo) with the most divisions whose size does not exceed ``n``; the
    coarsest lattice is the ``m`` vertices, returned even when ``n < m``.

    Args:
        m: Number of objectives.
        n: Number of preferences wanted (an upper bound for ``m > 2``).

    Returns:
        Array of shape ``(k, m)``.
    """
    if m < 1 or n < 1:
        raise PreferenceError(f"equally_spaced needs m >= 1 and n >= 1, got m={m}, n={n}")
    if m == 1:
        return np.ones((1, 1))
    if m == 2:
        w = np.linspace(0.0, 1.0, n)
        return np.stack([w, 1.0 - w], axis=1)
    from math import comb

    from pymoo.util.ref_dirs import get_reference_directions

    h = 1
    while comb(h + 1 + m - 1, m - 1) <= n:
        h += 1
    return np.asarray(get_reference_directions("das-dennis", m, n_partitions=h), dtype=np.float64)


def parse_preference(text: str, m: int | None = None) -> list[float]:
    """Parse ``"0.3,0.7"`` (commas or spaces) into floats; raise a clear error on junk.

    Args:
        text: The preference as typed.
        m: Number of objectives, used only in the error message.
    """
    parts = [p for p in text.replace(",", " ").split() if p]
    if not parts:
        count = f"{m} " if m is not None else ""
        raise PreferenceError(f"preference '{text}' is empty; give {count}comma-separated weights, e.g. 0.3,0.7")
    try:
        return [float(p) for p in parts]
    except ValueError:
        raise PreferenceError(f"preference '{text}' is not a list of numbers, e.g. 0.3,0.7") from None


def validate_preference(pref: Sequence[float] | np.ndarray, m: int) -> np.ndarray:
    """Check a user-given preference (or a batch of them) and return it as float64.

    Accepts shape ``(m,)`` or ``(n, m)``. Rows must be finite, non-negative and sum to 1 within
    ``1e-3`` (they are then renormalised exactly).

    Raises:
        PreferenceError: naming the bad value.
    """
    if isinstance(pref, str):
        arr = np.asarray(parse_preference(pref, m))
    else:
        try:
            arr = np.asarray(pref, dtype=np.float64)
        except (TypeError, ValueError):
            raise PreferenceError(
                f"preference {pref!r} is not a list of numbers; give {m} weights that sum to 1") from None
    if arr.size == 0:
        raise PreferenceError(f"preference is empty; expected {m} weights that sum to 1")
    if arr.ndim == 0:
        raise PreferenceError(f"preference {pref!r} is not a list of weights; give {m} weights that sum to 1")
    if arr.ndim > 2:
        raise PreferenceError(f"preference has shape {arr.shape}; expected ({m},) or (n, {m})")
    if arr.shape[-1] != m:
        raise PreferenceError(
            f"preference {np.array2string(arr, precision=4)} has length {arr.shape[-1]}; this environment has "
            f"{m} objectives, so give {m} weights that sum to 1"
        )
    if not np.all(np.isfinite(arr)):
        raise PreferenceError(
            f"preference {np.array2string(arr, precision=4)} contains NaN or inf; weights must be finite numbers")
    if np.any(arr < 0):
        raise PreferenceError(
            f"preference {np.array2string(arr, precision=4)} has a negative weight; weights must be >= 0")
    sums = arr.sum(axis=-1)
    if np.any(np.abs(sums - 1.0) > PREF_SUM_ATOL):
        bad = float(np.atleast_1d(sums)[np.argmax(np.abs(np.atleast_1d(sums) - 1.0))])
        raise PreferenceError(
            f"preference {np.array2string(arr, precision=4)} sums to {bad:.6g}; weights must sum to 1"
        )
    return arr / sums[..., None]


def sample_neighbours(centers: np.ndarray, n: int, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Similar preference exploration (paper sec. 3): ``n`` preferences within L2 radius ``sigma`` of each center.

    Each neighbour is ``center + r * u`` with ``u`` a uniform unit direction in the simplex's plane
    (entries summing to 0) and ``r = sigma * U^(1/(m-1))``, i.e. uniform in the (m-1)-ball around the
    center. A candidate that leaves the simplex is redrawn (up to 4 tries in all; only the rejected ones are
    drawn again); if all tries leave it (only near the boundary), the last candidate is reflected back across
    the facets it crossed. Reflection
    across a facet never moves a point farther from a center inside the simplex, so every result lies on the
    simplex and within ``sigma`` of its center. The result is exactly uniform on the ball-simplex intersection
    away from the boundary and close to uniform near it (nothing piles up on the center).

    Args:
        centers: ``(B, m)`` preferences on the simplex.
        n: Neighbours per center (N_omega).
        sigma: L2 radius (sigma_omega).
        rng: The caller's generator.

    Returns:
        ``(B, n, m)`` array.
    """
    centers = np.asarray(centers, dtype=np.float64)
    b, m = centers.shape
    if m == 1:
        return np.ones((b, n, 1))
    # Neighbour-major layout (m, b * n): the sums over the m objectives are then m-row sums, much faster in numpy
    # than reductions over a short last axis.
    flat = np.repeat(centers, n, axis=0).T.copy()  # (m, b * n): one column per neighbour
    pick = flat + _ball_offsets(m, flat.shape[1], sigma, rng)
    todo = np.flatnonzero(pick.min(axis=0) < 0.0)
    for _ in range(3):  # redraw the candidates that left the simplex (3 more tries; rare away from the boundary)
        if not len(todo):
            break
        pick[:, todo] = flat[:, todo] + _ball_offsets(m, len(todo), sigma, rng)
        todo = todo[pick[:, todo].min(axis=0) < 0.0]
    if len(todo):
        pick[:, todo] = _reflect_inside(pick[:, todo].T).T
    pick = np.clip(pick, 0.0, None)
    return (pick / pick.sum(axis=0)).T.reshape(b, n, m)


def _ball_offsets(m: int, k: int, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """``(m, k)``: ``k`` offsets uniform in the (m-1)-ball of radius ``sigma`` within the plane ``sum(x) = 0``."""
    g = rng.standard_normal(size=(m, k))
    g -= g.mean(axis=0)  # project onto the plane sum(x) = 0
    u = g / np.maximum(np.sqrt((g * g).sum(axis=0)), 1e-12)
    return u * (sigma * rng.random(size=k) ** (1.0 / (m - 1)))


def _reflect_inside(pick: np.ndarray) -> np.ndarray:
    """Reflect points of the plane ``sum(x) = 1`` across the most violated facet ``x_k = 0`` until inside."""
    m = pick.shape[-1]
    for _ in range(2 * m):  # a few rounds at most
        k = np.argmin(pick, axis=-1)
        low = np.take_along_axis(pick, k[..., None], axis=-1)  # (k, 1)
        if np.all(low >= 0):
            break
        normal = np.eye(m)[k] - 1.0 / m  # facet normal within the simplex plane
        pick = np.where(low < 0, pick - 2.0 * low / (1.0 - 1.0 / m) * normal, pick)
    return pick


class PreferencePartition:
    """The N_I preference intervals of preference exploration (paper sec. 3).

    For two objectives the cells are the paper's equal intervals of ``omega_0`` on [0, 1]. For ``m > 2`` the
    simplex is cut into the Voronoi cells of ``N_I`` anchors placed by Lloyd's algorithm (k-means on a fixed
    sample of 20,000 uniform preferences, seed 0): a centroidal Voronoi tessellation, so cells have nearly equal
    volume and are compact. The anchors depend only on ``(m, N_I)``.
    """

    def __init__(self, m: int, n_cells: int) -> None:
        if m < 1 or n_cells < 1:
            raise PreferenceError(f"a partition needs m >= 1 and n_cells >= 1, got m={m}, n_cells={n_cells}")
        self.m = m
        self.n_cells = n_cells if m > 1 else 1
        if m > 2:
            ref_rng = np.random.default_rng(0)
            self._reference = sample_simplex(20_000, m, ref_rng)
            anchors = self._reference[: self.n_cells].copy()
            for _ in range(50):
                lab = self._nearest(self._reference, anchors)
                for k in range(self.n_cells):  # loop over cells (N_I), not samples
                    pts = self._reference[lab == k]
                    if len(pts):
                        anchors[k] = pts.mean(axis=0)
            self.anchors = anchors
            self.volumes = np.bincount(self._nearest(self._reference, anchors), minlength=self.n_cells) / 20_000
        else:
            self.anchors = None
            self.volumes = np.full(self.n_cells, 1.0 / self.n_cells)

    @staticmethod
    def _nearest(x: np.ndarray, anchors: np.ndarray) -> np.ndarray:
        d = ((x[:, None, :] - anchors[None, :, :]) ** 2).sum(-1)
        return d.argmin(axis=1)

    def cell_of(self, prefs: np.ndarray) -> np.ndarray:
        """Cell index of each preference; ``prefs`` is ``(n, m)`` (or ``(m,)``)."""
        prefs = np.atleast_2d(np.asarray(prefs, dtype=np.float64))
        if self.m == 1:
            return np.zeros(len(prefs), dtype=np.int64)
        if self.m == 2:
            return np.minimum((prefs[:, 0] * self.n_cells).astype(np.int64), self.n_cells - 1)
        return self._nearest(prefs, self.anchors)

    def sample_in_cell(self, cell: int, rng: np.random.Generator) -> np.ndarray:
        """One preference uniform inside ``cell``."""
        if not 0 <= cell < self.n_cells:
            raise PreferenceError(f"cell {cell} is out of range: this partition has cells 0..{self.n_cells - 1}")
        if self.m == 1:
            return np.ones(1)
        if self.m == 2:
            w = (cell + rng.random()) / self.n_cells
            return np.array([w, 1.0 - w])
        while True:  # rejection sampling in batches: the acceptance rate is the cell's volume (~1/N_I)
            cand = sample_simplex(8 * self.n_cells, self.m, rng)
            hit = np.flatnonzero(self.cell_of(cand) == cell)
            if len(hit):
                return cand[hit[0]]


class PreferenceSampler:
    """Draws each episode's preference and keeps the visit counts N_i of the partition.

    With ``exploration=False`` preferences are uniform on the simplex (EQL). With ``exploration=True``
    (PE) a cell is drawn with probability proportional to ``(N_i + c)^(-1/2)`` (paper sec. 3, ``c = 0.01``)
    and the preference uniformly inside it. Counts are kept in both modes so the discriminator and the logs
    can use them.
    """

    def __init__(self, m: int, n_cells: int, exploration: bool, count_offset: float = 0.01) -> None:
        self.partition = PreferencePartition(m, n_cells)
        self.exploration = exploration
        self.count_offset = count_offset
        self.counts = np.zeros(self.partition.n_cells, dtype=np.int64)

    def cell_probs(self) -> np.ndarray:
        """Probability of each cell under the current sampling distribution p."""
        if not self.exploration:
            return self.partition.volumes.copy()
        return pe_cell_probs(self.counts, self.count_offset)

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        """Draw one episode preference and count it."""
        if self.exploration:
            cell = int(rng.choice(self.partition.n_cells, p=self.cell_probs()))
            pref = self.partition.sample_in_cell(cell, rng)
        else:
            pref = sample_simplex(1, self.partition.m, rng)[0]
            cell = int(self.partition.cell_of(pref)[0])
        self.counts[cell] += 1
        return pref

    def log_prob_cells(self, cells: np.ndarray) -> np.ndarray:
        """``log p(cell)`` under the current sampling distribution, for the MI term of eq. 6-7."""
        return np.log(self.cell_probs())[cells]

    def state_dict(self) -> dict:
        """Counts, for checkpoints."""
        return {"counts": self.counts.tolist()}

    def load_state_dict(self, state: dict) -> None:
        """Restore counts from :meth:`state_dict`."""
        counts = np.asarray(state["counts"], dtype=np.int64)
        if counts.shape != self.counts.shape:
            raise PreferenceError(f"preference counts have {counts.shape[0]} cells, expected {self.counts.shape[0]}")
        self.counts = counts


def pe_cell_probs(counts: np.ndarray, offset: float = 0.01) -> np.ndarray:
    """Preference exploration's cell distribution: p_i proportional to ``(N_i + offset)^(-1/2)`` (paper sec. 3)."""
    w = (np.asarray(counts, dtype=np.float64) + offset) ** -0.5
    return w / w.sum()
