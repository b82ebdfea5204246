"""Strategy diversity: how differently the agent acts under different preferences.

The paper (sec. 4, Fig. 3b) claims MoPE picks more diverse routes than EQL for the same outcome. Two measures,
both computed from greedy rollouts recorded with ``solutions(..., record_obs=True)``:

* :func:`distinct_paths` -- for each optimal solution (treasure) reached, the number of distinct state
  sequences that reach it across preferences. On Deep-Sea-Treasure every optimal path is a shortest path,
  and most treasures have several, so a value above 1 is genuine route diversity at no cost in return.
* :func:`state_preference_mi` -- the plug-in estimate of the mutual information I(S; C) in nats between the
  states visited and the preference cell C (the N_I cells of preference exploration) under which they were
  visited, from the empirical joint distribution of (state, cell) over all steps. Exact counting, so it
  needs discrete (or discretised) observations; 0 means the states say nothing about the preference, and it
  is at most H(C) <= log N_I.
"""

from __future__ import annotations

import numpy as np

from mope.metrics import match_matrix


def _paths(observations: np.ndarray, lengths: np.ndarray) -> list[bytes]:
    """One hashable key per episode: its visited observations up to its length."""
    flat = observations.reshape(observations.shape[0], observations.shape[1], -1)
    return [np.ascontiguousarray(flat[i, : lengths[i] + 1]).tobytes() for i in range(len(flat))]


def distinct_paths(observations: np.ndarray, lengths: np.ndarray, returns: np.ndarray, front: np.ndarray
                   ) -> dict[str, float]:
    """Distinct routes per solution of ``front`` reached.

    Args:
        observations: ``(n, T + 1, ...)`` visited observations per preference.
        lengths: ``(n,)`` episode lengths.
        returns: ``(n, m)`` returns, on the same scale as ``front`` (e.g. both discounted).
        front: ``(k, m)`` solutions to group by (e.g. the CCS).

    Returns:
        ``paths_per_solution`` (mean over reached solutions of the number of distinct routes),
        ``max_paths`` and ``solutions_reached``.
    """
    match = match_matrix(returns, front)  # (n, k)
    keys = _paths(observations, lengths)
    counts = []
    for j in range(len(front)):  # loop over the few front points, not over preferences
        rows = np.flatnonzero(match[:, j])
        if rows.size:
            counts.append(len({keys[i] for i in rows}))
    if not counts:
        return {"paths_per_solution": 0.0, "max_paths": 0.0, "solutions_reached": 0.0}
    return {"paths_per_solution": float(np.mean(counts)), "max_paths": float(max(counts)),
            "solutions_reached": float(len(counts))}


def state_preference_mi(observations: np.ndarray, lengths: np.ndarray, cells: np.ndarray) -> float:
    """Plug-in estimate of I(S; C) in nats over every visited step (see the module docstring).

    Args:
        observations: ``(n, T + 1, ...)`` discrete observations.
        lengths: ``(n,)`` episode lengths (steps ``0 .. length - 1`` count: the states acted in).
        cells: ``(n,)`` preference cell of each episode.
    """
    n, t = observations.shape[:2]
    flat = observations.reshape(n, t, -1)
    steps = np.arange(t)[None, :] < np.asarray(lengths)[:, None]  # (n, T+1) mask of acted-in states
    states = flat[steps]
    c = np.broadcast_to(np.asarray(cells)[:, None], (n, t))[steps]
    _, s_idx = np.unique(states, axis=0, return_inverse=True)
    s_idx = s_idx.reshape(-1)
    _, c_idx = np.unique(c, return_inverse=True)
    joint = np.zeros((s_idx.max() + 1, c_idx.max() + 1))
    np.add.at(joint, (s_idx, c_idx), 1.0)
    joint /= joint.sum()
    ps = joint.sum(1, keepdims=True)
    pc = joint.sum(0, keepdims=True)
    nz = joint > 0
    # I >= 0; the plug-in sum can land a rounding error below 0 (-1e-16) when S and C are independent
    return max(0.0, float(np.sum(joint[nz] * np.log(joint[nz] / (ps @ pc)[nz]))))
