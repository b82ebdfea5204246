"""Four-room's exact optimum: a dynamic programme over its tours (MO-Gymnasium publishes no front for it).

``four-room-v0`` is deterministic: a 13x13 maze, 12 shapes of 3 kinds (+1 in the kind's objective the first time a
shape's cell is entered), the goal ends the episode with (1, 1, 1), and a move into a wall or off the grid stays.
Every reward is >= 0 and comes on entering a shape or the goal, so an optimal policy is a *tour*: shortest paths
from the start to some shapes in some order, then to the goal. Between two visits a path may cross collected
shapes' cells but not uncollected ones (crossing one is visiting it), nor the goal. The optimum is therefore a
dynamic programme over (collected set, shape the agent stands on), 4,096 x 12 states, each move a breadth-first
shortest path discounted by its length: :func:`optimal_tours`. It is exact for the infinite horizon, and for the
evaluation's 200-step limit when the optimal tour is shorter (:func:`exact_front` checks it).

``scripts/four_room_exact.py`` checks the programme against the real environment and against plain value iteration
over the ~690k (cell, flags) states (:func:`mope.evaluation.diagnose.four_room_model`), and writes the convex
coverage set that :func:`stored_front` reads (``fronts/four-room-v0.json``):
:func:`mope.evaluation.diagnose.reference_front` evaluates against it.
"""

from __future__ import annotations

import json
from collections import deque
from functools import cache
from pathlib import Path

import gymnasium as gym
import numpy as np

from mope.metrics import convex_coverage_set
from mope.preferences import equally_spaced

#: The env's actions LEFT, UP, RIGHT, DOWN as (row, col) moves.
MOVES = ((0, -1), (-1, 0), (0, 1), (1, 0))
#: The stored front: computed by ``scripts/four_room_exact.py`` for MO-Gymnasium's map.
STORED_FRONT = Path(__file__).with_name("fronts") / "four-room-v0.json"


def _shortest_paths(base: gym.Env, source: tuple[int, int], blocked: set) -> dict[tuple[int, int], list[int]]:
    """Breadth-first from ``source``, entering ``blocked`` cells but never leaving them: ``{blocked cell: the
    actions of the first shortest path to it}`` for the blocked cells it reaches."""
    rows, cols = base.maze.shape
    prev: dict = {source: None}
    queue = deque([source])
    while queue:
        here = queue.popleft()
        for a, (dr, dc) in enumerate(MOVES):
            cell = (here[0] + dr, here[1] + dc)
            if not (0 <= cell[0] < rows and 0 <= cell[1] < cols) or cell in base.occupied or cell in prev:
                continue
            prev[cell] = (here, a)
            if cell not in blocked:
                queue.append(cell)
    paths = {}
    for target in blocked & prev.keys():
        actions, cell = [], target
        while prev[cell] is not None:
            cell, a = prev[cell]
            actions.append(a)
        paths[target] = actions[::-1]
    return paths


def optimal_tours(env: gym.Env, prefs: np.ndarray, gamma: float) -> tuple[np.ndarray, list[list[int]]]:
    """The dynamic programme of the module docstring for each preference.

    Args:
        env: A four-room environment (any maze in MO-Gymnasium's format).
        prefs: ``(n, 3)`` preferences.
        gamma: Discount factor.

    Returns:
        ``(returns, tours)``: ``(n, 3)`` the discounted vector return of each preference's optimal tour from the
        start, and its actions.
    """
    base = env.unwrapped
    prefs = np.atleast_2d(np.asarray(prefs, dtype=np.float64))
    shapes = sorted(base.shape_ids, key=base.shape_ids.get)  # the cell of shape k
    kinds = [base.all_shapes[base.maze[r, c]] for r, c in shapes]
    n_shapes, n = len(shapes), len(prefs)
    start, goal = base.initial[0], base.goal
    unit = np.eye(len(base.all_shapes))
    value: dict = {}  # (collected mask, shape stood on) -> (n, m) vector return of the best rest of the tour
    plan: dict = {}  # the same key -> per preference (next shape or None for the goal, the path's actions)

    def solve(mask: int, here: tuple[int, int], key: tuple) -> None:
        todo = [k for k in range(n_shapes) if not mask >> k & 1]
        paths = _shortest_paths(base, here, {shapes[k] for k in todo} | {goal})
        options, steps = [], []
        if goal in paths:
            d = len(paths[goal])
            options.append(np.broadcast_to(gamma ** (d - 1) * np.ones(len(unit)), (n, len(unit))))
            steps.append((None, paths[goal]))
        for k in todo:
            if shapes[k] in paths:
                d = len(paths[shapes[k]])
                options.append(gamma ** (d - 1) * unit[kinds[k]] + gamma ** d * value[(mask | 1 << k, k)])
                steps.append((k, paths[shapes[k]]))
        opts = np.stack(options)  # (O, n, m)
        best = np.einsum("onm,nm->on", opts, prefs).argmax(axis=0)
        value[key] = opts[best, np.arange(n)]
        plan[key] = [steps[b] for b in best]

    for mask in sorted(range(1, 1 << n_shapes), key=lambda x: -bin(x).count("1")):  # fuller sets first
        for k in range(n_shapes):
            if mask >> k & 1:
                solve(mask, shapes[k], (mask, k))
    solve(0, start, ("start",))
    tours = []
    for i in range(n):
        key, mask, actions = ("start",), 0, []
        while True:
            k, path = plan[key][i]
            actions += path
            if k is None:
                break
            mask |= 1 << k
            key = (mask, k)
        tours.append(actions)
    return value[("start",)], tours


def exact_front(env: gym.Env, gamma: float, n_prefs: int = 400, horizon: int | None = 200
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """The convex coverage set of the optimal tours' returns at ``n_prefs`` equally spaced preferences.

    Returns:
        ``(ccs, returns, longest tour)``, ``returns`` ``(n, 3)`` per preference of ``equally_spaced(3, n_prefs)``.

    Raises:
        ValueError: if an optimal tour is not shorter than ``horizon`` (the time limit would cut it).
    """
    prefs = equally_spaced(3, n_prefs)
    returns, tours = optimal_tours(env, prefs, gamma)
    longest = max(len(t) for t in tours)
    if horizon is not None and longest >= horizon:
        raise ValueError(f"an optimal tour takes {longest} steps, not fewer than the time limit {horizon}")
    return convex_coverage_set(np.unique(returns.round(12), axis=0)), returns, longest


@cache
def _stored() -> dict:
    return json.loads(STORED_FRONT.read_text())


def stored_front(env: gym.Env, gamma: float) -> np.ndarray | None:
    """The stored exact front of MO-Gymnasium's four-room map at the stored discount, else ``None`` (another map
    or discount: compute it with :func:`exact_front`)."""
    from mo_gymnasium.envs.four_room.four_room import MAZE

    stored = _stored()
    base = env.unwrapped
    if not np.array_equal(np.asarray(base.maze), MAZE) or abs(gamma - stored["gamma"]) > 1e-12:
        return None
    return np.asarray(stored["ccs"], dtype=np.float64)
