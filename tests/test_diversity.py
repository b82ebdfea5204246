"""Diversity measures on hand-made rollouts with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from mope.evaluation.diversity import distinct_paths, state_preference_mi


def paths_to_array(paths: list[list[tuple[int, int]]]) -> tuple[np.ndarray, np.ndarray]:
    t = max(len(p) for p in paths)
    obs = np.zeros((len(paths), t, 2), dtype=np.int64)
    for i, p in enumerate(paths):
        obs[i, : len(p)] = p
        obs[i, len(p):] = p[-1]
    return obs, np.array([len(p) - 1 for p in paths])


def test_distinct_paths_counts_routes_per_solution():
    # three episodes reach solution A by two different routes, one reaches B, one reaches nothing on the front
    paths = [[(0, 0), (0, 1), (1, 1)], [(0, 0), (1, 0), (1, 1)], [(0, 0), (0, 1), (1, 1)], [(0, 0), (1, 0)],
             [(0, 0), (0, 0)]]
    obs, lengths = paths_to_array(paths)
    returns = np.array([[5.0, -2.0], [5.0, -2.0], [5.0, -2.0], [1.0, -1.0], [0.0, -9.0]])
    front = np.array([[5.0, -2.0], [1.0, -1.0], [9.0, -5.0]])
    out = distinct_paths(obs, lengths, returns, front)
    assert out == {"paths_per_solution": 1.5, "max_paths": 2.0, "solutions_reached": 2.0}


def test_mi_is_zero_when_states_ignore_the_preference():
    paths = [[(0, 0), (0, 1), (1, 1)]] * 4
    obs, lengths = paths_to_array(paths)
    assert state_preference_mi(obs, lengths, np.array([0, 0, 1, 1])) == pytest.approx(0.0, abs=1e-12)


def test_mi_is_the_cell_entropy_when_states_reveal_the_preference():
    # cell 0 goes right, cell 1 goes down; the shared start state (0, 0) carries no information
    paths = [[(0, 0), (0, 1), (0, 2)], [(0, 0), (1, 0), (2, 0)]]
    obs, lengths = paths_to_array(paths)
    # states acted in: (0,0),(0,1) for cell 0; (0,0),(1,0) for cell 1 -> I = H(C) - H(C|S) = log 2 - 0.5 log 2
    assert state_preference_mi(obs, lengths, np.array([0, 1])) == pytest.approx(0.5 * np.log(2))


def test_mi_is_never_negative_when_states_and_cells_are_exactly_independent():
    """Counts that factorise (state i with cell j a_i * b_j times) make I = 0; the plug-in sum rounds to -6e-17
    there, and a mutual information is never negative."""
    a, b = [3, 3, 4, 3], [3, 3, 3, 4]
    pairs = [(i, j) for i, ai in enumerate(a) for j, bj in enumerate(b) for _ in range(ai * bj)]
    obs = np.array([[[i], [99]] for i, _ in pairs])  # one acted-in state per episode
    mi = state_preference_mi(obs, np.ones(len(pairs), dtype=int), np.array([j for _, j in pairs]))
    assert mi == 0.0
