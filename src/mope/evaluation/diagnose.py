"""Ground truth for environments with known dynamics, and a diagnostic of a learned agent against it.

On a small environment whose dynamics are known (Deep-Sea-Treasure and its concave, mirrored and seabed maps;
resource-gathering, whose enemies kill at random), the optimal action values are exact: :func:`value_iteration`
computes, for every preference ``w`` at once, the scalar ``Q*(s, a, w)``, ``V*(s, w)`` and the expected vector
return ``Q*_vec(s, a, w)`` of acting optimally after ``a``. :func:`diagnose` then measures a learned agent
against them:

* ``path_error``: share of (w, s) pairs, s on one of w's optimal paths from the start, where the greedy action
  ``argmax_a w^T Q(s, a, w)`` is not optimal;
* ``state_error``: the same over every reachable non-terminal state;
* ``first_error_step``: along w's optimal path (first optimal action at each state), the mean index of the
  first wrong greedy action, over the preferences whose path has one (``path_failed_share`` says how many);
* ``overestimation_mean`` / ``_max``: ``max_a w^T Q(s0, a, w) - V*(s0, w)`` at the start state;
* ``abs_error_mean``: mean ``|w^T Q(s, a, w) - Q*(s, a, w)|`` over reachable states and all actions;
* ``greedy_regret_mean`` (:func:`diagnose` only, not the training evaluations): ``V*(s0, w) - w^T V^pi(s0)``,
  the exact expected utility the greedy policy pi gives up at the start (:func:`policy_returns`), and
  ``greedy_utility_share``, ``sum_w w^T V^pi(s0) / sum_w V*(s0, w)`` (where no optimal value is negative:
  resource-gathering; NaN on Deep-Sea-Treasure, whose time cost makes them negative);
* ``belief_gap_mean``: ``max_a w^T Q(s0, a, w) - w^T V^pi(s0)``, what the agent expects of its own greedy
  policy beyond what it gets (its optimism about itself; on a stochastic environment, about luck).

On a stochastic model an "optimal path" is any state an optimal policy reaches with positive probability, and
the canonical path (``first_error_step``) follows each transition's most likely outcome. The ground truth is of
the infinite-horizon discounted problem: the environment's time limit is not modelled (it only matters to a
policy that never ends its episode).

A wrong greedy action is one whose exact value is below ``V*(s, w)`` by more than :data:`ACTION_TOL`: ties
(several shortest routes to one treasure) all count as right.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Protocol

import gymnasium as gym
import numpy as np

from mope.envs import known_front
from mope.errors import EnvironmentError_, MopeError
from mope.evaluation.four_room import MOVES as FOUR_ROOM_MOVES
from mope.evaluation.four_room import stored_front
from mope.metrics import convex_coverage_set
from mope.preferences import equally_spaced, validate_preference

#: An action is optimal when its exact value is within this of V*(s, w).
ACTION_TOL = 1e-6


class QFunction(Protocol):
    """Anything with ``q_values(obs, prefs) -> (n, A, m)`` vector Q-values (a :class:`~mope.agent.agent.MoPE`)."""

    def q_values(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray: ...


@dataclass
class TabularModel:
    """A finite MOMDP: deterministic, or with ``prob`` a random outcome per state-action.

    Attributes:
        obs: ``(S, *obs_shape)`` the observation of each state.
        next_state: ``(S, A)`` successor of each state-action (``(S, A, K)`` with ``prob``: one per outcome).
        reward: ``(S, A, m)`` vector reward of each state-action (``(S, A, K, m)`` with ``prob``).
        terminal: ``(S, A)`` True where the transition ends the episode (``(S, A, K)`` with ``prob``).
        start: The start state.
        reachable: ``(S,)`` True for non-terminal states reachable from the start.
        prob: ``None`` for a deterministic model, else ``(S, A, K)`` the probability of each outcome.
    """

    obs: np.ndarray
    next_state: np.ndarray
    reward: np.ndarray
    terminal: np.ndarray
    start: int
    reachable: np.ndarray
    prob: np.ndarray | None = None

    @property
    def n_states(self) -> int:
        return int(self.next_state.shape[0])

    @property
    def n_actions(self) -> int:
        return int(self.next_state.shape[1])

    @property
    def n_objectives(self) -> int:
        return int(self.reward.shape[-1])

    def outcomes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(next_state, prob, reward, terminal)`` with an outcome axis K (``(S, A, K)``, ``(S, A, K, m)``): a
        deterministic model's one outcome has probability 1."""
        if self.prob is None:
            return (self.next_state[..., None], np.ones(self.next_state.shape + (1,)), self.reward[:, :, None],
                    self.terminal[..., None])
        return self.next_state, self.prob, self.reward, self.terminal


def _reachable(next_state: np.ndarray, terminal: np.ndarray, start: int, prob: np.ndarray | None = None
               ) -> np.ndarray:
    """Non-terminal states reachable from ``start`` (breadth-first; a terminal transition's target is not entered,
    nor an outcome of probability 0). ``next_state``/``terminal`` ``(S, A)`` or, with ``prob``, ``(S, A, K)``."""
    live = ~terminal if prob is None else ~terminal & (prob > 0)
    seen = np.zeros(next_state.shape[0], dtype=bool)
    seen[start] = True
    frontier = [start]
    while frontier:
        nxt = next_state[frontier][live[frontier]]
        new = np.unique(nxt[~seen[nxt]])
        seen[new] = True
        frontier = new.tolist()
    return seen


def tabular_model(env: gym.Env) -> TabularModel:
    """The exact model of a Deep-Sea-Treasure environment (any of its maps, and the seabed-terminal variant) or of
    resource-gathering.

    Raises:
        EnvironmentError_: for an environment whose dynamics mope does not know.
    """
    base = env.unwrapped
    kind = type(base).__name__
    if kind == "ResourceGathering" and hasattr(base, "map"):
        return _resource_gathering_model(base)
    if not hasattr(base, "sea_map") or kind not in ("DeepSeaTreasure", "SeabedDeepSeaTreasure"):
        name = env.spec.id if env.spec is not None else kind
        raise EnvironmentError_(
            f"no ground truth for environment '{name}': mope knows the exact dynamics of Deep-Sea-Treasure "
            "(deep-sea-treasure-v0, -concave-v0, -mirrored-v0, mope/deep-sea-treasure-seabed-v0) and of "
            "resource-gathering-v0 only")
    return _deep_sea_treasure_model(base)


def _deep_sea_treasure_model(base: gym.Env) -> TabularModel:
    """:func:`tabular_model` of a Deep-Sea-Treasure map (deterministic)."""
    sea = np.asarray(base.sea_map, dtype=np.float64)
    rows, cols = sea.shape
    seabed_ends = bool(getattr(base, "seabed_terminates", False))
    seabed_reward = float(getattr(base, "seabed_reward", 0.0))
    moves = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]])
    n_states, n_actions = rows * cols, len(moves)
    next_state = np.zeros((n_states, n_actions), dtype=np.int64)
    reward = np.zeros((n_states, n_actions, 2))
    terminal = np.zeros((n_states, n_actions), dtype=bool)
    for r in range(rows):
        for c in range(cols):
            s = r * cols + c
            for a, (dr, dc) in enumerate(moves):
                nr, nc = r + dr, c + dc
                inside = 0 <= nr < rows and 0 <= nc < cols
                if inside and sea[nr, nc] == -10 and seabed_ends:
                    next_state[s, a], terminal[s, a] = s, True
                    reward[s, a] = (seabed_reward, -1.0)
                    continue
                if not inside or sea[nr, nc] == -10:
                    nr, nc = r, c
                next_state[s, a] = nr * cols + nc
                value = sea[nr, nc]
                terminal[s, a] = value not in (0.0, -10.0)
                reward[s, a] = (value if terminal[s, a] else 0.0, -1.0)
    probe = copy.deepcopy(base)  # never touch the caller's episode
    probe.reset()
    start_pos = np.asarray(probe.current_state, dtype=np.int64)
    start = int(start_pos[0] * cols + start_pos[1])
    obs = np.array([[r, c] for r in range(rows) for c in range(cols)])
    obs = obs.astype(np.float32) * 0.1 if getattr(base, "float_state", False) else obs.astype(np.int32)
    return TabularModel(obs, next_state, reward, terminal, start, _reachable(next_state, terminal, start))


#: Resource-gathering's chance that an enemy cell kills (mo_gymnasium's ``ResourceGathering.step``).
ENEMY_KILL_PROB = 0.1


def _resource_gathering_model(base: gym.Env) -> TabularModel:
    """:func:`tabular_model` of resource-gathering (Barrett and Narayanan 2008, MO-Gymnasium's map).

    States are (row, col, gold carried, gem carried): 100. A move off the grid stays. Entering the gold (R1) or
    gem (R2) cell picks it up; an enemy cell (E1, E2) ends the episode with (-1, 0, 0) with probability
    :data:`ENEMY_KILL_PROB` (outcome 1), else nothing happens (outcome 0); home (H) ends it with (0, gold, gem).
    Two outcomes per state-action; where nothing is random the second has probability 0.
    """
    cells = np.asarray(base.map)
    rows, cols = cells.shape
    moves = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]])  # the env's actions: up, down, left, right
    grid = [(r, c, g, d) for r in range(rows) for c in range(cols) for g in (0, 1) for d in (0, 1)]
    index = {state: i for i, state in enumerate(grid)}
    n_states, n_actions = len(grid), len(moves)
    next_state = np.zeros((n_states, n_actions, 2), dtype=np.int64)
    prob = np.zeros((n_states, n_actions, 2))
    reward = np.zeros((n_states, n_actions, 2, 3))
    terminal = np.zeros((n_states, n_actions, 2), dtype=bool)
    for s, (r, c, g, d) in enumerate(grid):
        for a, (dr, dc) in enumerate(moves):
            nr, nc = (r + dr, c + dc) if 0 <= r + dr < rows and 0 <= c + dc < cols else (r, c)
            cell = str(cells[nr, nc])
            g2, d2 = max(g, int(cell == "R1")), max(d, int(cell == "R2"))
            next_state[s, a] = index[(nr, nc, g2, d2)]
            prob[s, a] = (1.0, 0.0)
            if cell == "H":
                terminal[s, a] = True
                reward[s, a, :] = (0.0, g2, d2)
            elif cell in ("E1", "E2"):
                prob[s, a] = (1.0 - ENEMY_KILL_PROB, ENEMY_KILL_PROB)
                terminal[s, a, 1] = True
                reward[s, a, 1] = (-1.0, 0.0, 0.0)
    start_pos = np.asarray(base.initial_pos, dtype=np.int64)
    start = index[(int(start_pos[0]), int(start_pos[1]), 0, 0)]
    obs = np.array(grid, dtype=np.int32)
    return TabularModel(obs, next_state, reward, terminal, start,
                        _reachable(next_state, terminal, start, prob), prob)


def four_room_model(env: gym.Env) -> TabularModel:
    """The cell-level model of a four-room maze, for :func:`value_iteration` on small mazes and as a check of
    :func:`mope.evaluation.four_room.optimal_tours`: a state is (cell, collected flags), ``cell * 2^K + flags`` for
    ``K`` shapes (MO-Gymnasium's map: 169 x 4,096 states, walls included). Not used by :func:`tabular_model`: value
    iteration over MO-Gymnasium's map at 101 preferences would need gigabytes."""
    base = env.unwrapped
    rows, cols = base.maze.shape
    n_masks = 1 << len(base.shape_ids)
    mask = np.arange(n_masks)
    m = len(base.all_shapes)
    next_state = np.zeros((rows * cols * n_masks, len(FOUR_ROOM_MOVES)), dtype=np.int64)
    reward = np.zeros((rows * cols * n_masks, len(FOUR_ROOM_MOVES), m))
    terminal = np.zeros((rows * cols * n_masks, len(FOUR_ROOM_MOVES)), dtype=bool)
    for r in range(rows):
        for c in range(cols):
            here = r * cols + c
            block = slice(here * n_masks, (here + 1) * n_masks)
            for a, (dr, dc) in enumerate(FOUR_ROOM_MOVES):
                nr, nc = r + dr, c + dc
                if not (0 <= nr < rows and 0 <= nc < cols) or (nr, nc) in base.occupied:
                    next_state[block, a] = here * n_masks + mask  # stays, no reward
                    continue
                cell = nr * cols + nc
                next_state[block, a] = cell * n_masks + mask
                if (nr, nc) == base.goal:
                    reward[block, a], terminal[block, a] = 1.0, True
                elif (nr, nc) in base.shape_ids:
                    bit = 1 << base.shape_ids[(nr, nc)]
                    next_state[block, a] = cell * n_masks + (mask | bit)
                    reward[block, a, base.all_shapes[base.maze[nr, nc]]] = (mask & bit) == 0
    sr, sc = base.initial[0]
    start = (sr * cols + sc) * n_masks
    k = len(base.shape_ids)
    obs = np.concatenate([np.repeat(np.arange(rows), cols * n_masks)[:, None],
                          np.tile(np.repeat(np.arange(cols), n_masks), rows)[:, None],
                          np.tile((mask[:, None] >> np.arange(k)) & 1, (rows * cols, 1))], axis=1).astype(np.int32)
    return TabularModel(obs, next_state, reward, terminal, start, _reachable(next_state, terminal, start))


@dataclass
class GroundTruth:
    """Exact values for a set of preferences (``n`` preferences, ``S`` states, ``A`` actions, ``m`` objectives)."""

    prefs: np.ndarray  #: ``(n, m)``
    q: np.ndarray  #: ``(n, S, A)`` scalar Q*
    v: np.ndarray  #: ``(n, S)`` scalar V*
    q_vec: np.ndarray  #: ``(n, S, A, m)`` vector return of ``a`` then optimal behaviour

    def optimal_actions(self, tol: float = ACTION_TOL) -> np.ndarray:
        """``(n, S, A)`` True for every optimal action."""
        return self.q >= self.v[..., None] - tol


def value_iteration(model: TabularModel, prefs: np.ndarray, gamma: float, tol: float = 1e-12,
                    max_iter: int = 100_000) -> GroundTruth:
    """Scalarised value iteration, every preference at once, then the expected vector returns of the optimal policy.

    Args:
        model: The environment's exact model.
        prefs: ``(n, m)`` preferences.
        gamma: Discount factor (< 1).
        tol: Stop when no value moves by more than this.
        max_iter: Safety cap on sweeps.

    Returns:
        A :class:`GroundTruth`.
    """
    prefs = np.atleast_2d(np.asarray(prefs, dtype=np.float64))
    nxt, p, rew, term = model.outcomes()
    cont = gamma * p * ~term  # (S, A, K): the discounted probability of going on to each outcome's state
    r_exp = (p[..., None] * rew).sum(axis=2)  # (S, A, m) expected reward
    r_scal = np.einsum("nm,sam->nsa", prefs, r_exp)  # (n, S, A)
    # start below every value (the worst reward forever): the iterates then rise monotonically and reach V*
    # exactly once they span the longest optimal path
    v = np.broadcast_to(r_scal.min(axis=(1, 2))[:, None] / (1.0 - gamma), (len(prefs), model.n_states)).copy()
    for _ in range(max_iter):
        q = r_scal + (cont[None] * v[:, nxt]).sum(axis=3)
        v_new = q.max(axis=2)
        done = np.max(np.abs(v_new - v)[:, model.reachable]) <= tol
        v = v_new
        if done:
            break
    q = r_scal + (cont[None] * v[:, nxt]).sum(axis=3)
    v_vec = policy_returns(model, q.argmax(axis=2), gamma, tol, max_iter)  # (n, S, m) of the optimal policy
    q_vec = r_exp[None] + (cont[None, ..., None] * v_vec[:, nxt]).sum(axis=3)
    return GroundTruth(prefs, q, q.max(axis=2), q_vec)


#: Environments whose published ``pareto_front`` mope does not evaluate against, and why: their front is computed
#: exactly from the model instead (:func:`reference_front`).
WRONG_PUBLISHED_FRONTS = {
    "ResourceGathering": "MO-Gymnasium's resource-gathering front misses the safe route to both resources "
                         "(0, g^17, g^17), which dominates its risky (-0.09, 0.78, 0.78) at gamma 0.99, and "
                         "discounts every return once more than the episode's steps (g^10 for the 10-step trip to "
                         "the gem, whose reward comes at step 9 counting from 0)",
}


def exact_front(env: gym.Env, gamma: float, n_prefs: int = 1000) -> np.ndarray:
    """The discounted convex coverage set of an environment :func:`tabular_model` knows: the expected vector returns
    at the start of the optimal policies of ``n_prefs`` equally spaced preferences, those on the convex hull.

    Raises:
        EnvironmentError_: for an environment whose dynamics mope does not know.
    """
    model = tabular_model(env)
    w = equally_spaced(model.n_objectives, n_prefs)
    truth = value_iteration(model, w, gamma)
    starts = truth.q_vec[np.arange(len(w)), model.start, truth.q[:, model.start].argmax(axis=1)]
    return convex_coverage_set(np.unique(starts.round(12), axis=0))


#: :func:`reference_front`'s exact fronts, by (environment class, its map, gamma): each is computed once per process.
_EXACT_FRONTS: dict[tuple[str, str, float], np.ndarray] = {}


def reference_front(env: gym.Env, gamma: float) -> np.ndarray | None:
    """The front mope evaluates against: the environment's published one (:func:`mope.envs.known_front`); for an
    environment of :data:`WRONG_PUBLISHED_FRONTS` the exact one (:func:`exact_front`); for four-room, which
    publishes none, the exact one stored for its map and discount (:func:`mope.evaluation.four_room.stored_front`);
    ``None`` without any."""
    kind = type(env.unwrapped).__name__
    if kind == "FourRoom":  # publishes none: the exact one mope stores (mope.evaluation.four_room)
        return stored_front(env, gamma)
    if kind in WRONG_PUBLISHED_FRONTS and 0 < gamma < 1:
        key = (kind, repr(getattr(env.unwrapped, "map", None)), float(gamma))
        if key not in _EXACT_FRONTS:
            _EXACT_FRONTS[key] = exact_front(env, gamma)
        return _EXACT_FRONTS[key].copy()
    return known_front(env, gamma)


def policy_returns(model: TabularModel, pi: np.ndarray, gamma: float, tol: float = 1e-12,
                   max_iter: int = 100_000) -> np.ndarray:
    """``(n, S, m)`` the expected discounted vector return of each of ``n`` deterministic policies ``pi (n, S)``
    (an action per state), by iterating their vector Bellman equations until nothing moves by more than ``tol``."""
    nxt, p, rew, term = model.outcomes()
    cont = gamma * p * ~term
    r_exp = (p[..., None] * rew).sum(axis=2)
    s_idx = np.arange(model.n_states)[None, :]
    n_idx = np.arange(len(pi))[:, None, None]
    r_pi = r_exp[s_idx, pi]  # (n, S, m)
    next_pi = nxt[s_idx, pi]  # (n, S, K)
    cont_pi = cont[s_idx, pi]  # (n, S, K)
    v_vec = np.zeros((len(pi), model.n_states, model.n_objectives))
    for _ in range(max_iter):
        v_vec_new = r_pi + (cont_pi[..., None] * v_vec[n_idx, next_pi]).sum(axis=2)
        done = np.max(np.abs(v_vec_new - v_vec)[:, model.reachable]) <= tol
        v_vec = v_vec_new
        if done:
            break
    return v_vec


def optimal_path_states(model: TabularModel, truth: GroundTruth) -> np.ndarray:
    """``(n, S)`` True for states on some optimal path of each preference (every optimal action followed, every
    outcome of positive probability)."""
    opt = truth.optimal_actions()
    nxt, p, _, term = model.outcomes()
    live = ~term & (p > 0)  # (S, A, K)
    n = len(truth.prefs)
    on = np.zeros((n, model.n_states), dtype=bool)
    on[:, model.start] = True
    frontier = on.copy()
    for _ in range(model.n_states):
        # successors of frontier states through optimal, non-terminal transitions
        step = (frontier[..., None] & opt)[..., None] & live[None]  # (n, S, A, K)
        nxt_on = np.zeros_like(on)
        idx_n, idx_s, idx_a, idx_k = np.nonzero(step)
        nxt_on[idx_n, nxt[idx_s, idx_a, idx_k]] = True
        frontier = nxt_on & ~on
        on |= nxt_on
        if not frontier.any():
            break
    return on


def canonical_paths(model: TabularModel, truth: GroundTruth, horizon: int = 1000) -> np.ndarray:
    """``(n, T)`` states of each preference's optimal path (first optimal action, most likely outcome), -1 after
    the end."""
    nxt, p, _, term = model.outcomes()
    likely = p.argmax(axis=2)[..., None]  # (S, A, 1)
    nxt, term = np.take_along_axis(nxt, likely, 2)[..., 0], np.take_along_axis(term, likely, 2)[..., 0]
    n = len(truth.prefs)
    pi = truth.q.argmax(axis=2)
    state = np.full(n, model.start)
    alive = np.ones(n, dtype=bool)
    out = []
    for _ in range(horizon):
        out.append(np.where(alive, state, -1))
        a = pi[np.arange(n), state]
        ends = term[state, a]
        state = np.where(alive, nxt[state, a], state)
        alive &= ~ends
        if not alive.any():
            break
    return np.stack(out, axis=1)


def agent_q(agent: QFunction, model: TabularModel, prefs: np.ndarray) -> np.ndarray:
    """``(n, S, A, m)`` the agent's vector Q-values at every state, for every preference (one batched call)."""
    n, s = len(prefs), model.n_states
    obs = np.broadcast_to(model.obs[None], (n, *model.obs.shape)).reshape(n * s, *model.obs.shape[1:])
    w = np.repeat(prefs, s, axis=0)
    q = np.asarray(agent.q_values(obs, w), dtype=np.float64)
    return q.reshape(n, s, model.n_actions, prefs.shape[1])


def diagnose_q(q: np.ndarray, model: TabularModel, truth: GroundTruth) -> dict[str, float]:
    """The diagnostic of the module docstring for learned vector Q-values ``q`` of shape ``(n, S, A, m)``."""
    prefs = truth.prefs
    scal = np.einsum("nm,nsam->nsa", prefs, q)
    greedy = scal.argmax(axis=2)  # (n, S)
    n_idx = np.arange(len(prefs))[:, None]
    s_idx = np.arange(model.n_states)[None, :]
    wrong = ~truth.optimal_actions()[n_idx, s_idx, greedy]  # (n, S)
    on_path = optimal_path_states(model, truth) & model.reachable[None]
    reach = np.broadcast_to(model.reachable[None], wrong.shape)
    paths = canonical_paths(model, truth)
    valid = paths >= 0
    path_wrong = np.where(valid, wrong[np.arange(len(prefs))[:, None], np.maximum(paths, 0)], False)
    failed = path_wrong.any(axis=1)
    first = np.argmax(path_wrong, axis=1)
    over = scal[:, model.start].max(axis=1) - truth.v[:, model.start]
    err = np.abs(scal - truth.q)[:, model.reachable]
    return {
        "path_error": float(wrong[on_path].mean()),
        "state_error": float(wrong[reach].mean()),
        "path_failed_share": float(failed.mean()),
        "first_error_step": float(first[failed].mean()) if failed.any() else float("nan"),
        "overestimation_mean": float(over.mean()),
        "overestimation_max": float(over.max()),
        "abs_error_mean": float(err.mean()),
        "vector_error_mean": float(np.abs(q - truth.q_vec)[:, model.reachable].mean()),
    }


def greedy_policy_metrics(q: np.ndarray, model: TabularModel, truth: GroundTruth, gamma: float
                          ) -> dict[str, float]:
    """What the greedy policy of learned vector Q-values ``q (n, S, A, m)`` is worth at the start, exactly (the
    model's expectation, no sampled episodes): ``greedy_regret_mean``, ``greedy_utility_share`` and
    ``belief_gap_mean`` of the module docstring."""
    prefs = truth.prefs
    scal = np.einsum("nm,nsam->nsa", prefs, q)
    got = np.einsum("nm,nm->n", prefs, policy_returns(model, scal.argmax(axis=2), gamma)[:, model.start])
    best = truth.v[:, model.start]
    return {
        "greedy_regret_mean": float(np.mean(best - got)),
        "greedy_utility_share": (float(got.sum() / best.sum()) if np.all(best >= 0) and best.sum() > 0
                                 else float("nan")),
        "belief_gap_mean": float(np.mean(scal[:, model.start].max(axis=1) - got)),
    }


def diagnose(agent: QFunction, env: gym.Env, gamma: float = 0.99, prefs: np.ndarray | int = 101
             ) -> dict[str, float]:
    """Measure an agent against the exact Q* of ``env`` (see the module docstring).

    Args:
        agent: Anything with ``q_values(obs, prefs)``.
        env: An environment :func:`tabular_model` knows.
        gamma: Discount factor of the ground truth (the agent's).
        prefs: Preferences, or a number of equally spaced ones (default 101).

    Returns:
        The metrics, plus ``n_prefs``.
    """
    if not 0 < gamma < 1:
        raise MopeError(f"gamma={gamma} is out of range for the ground truth: value iteration needs 0 < gamma < 1")
    model = tabular_model(env)
    m = model.n_objectives
    w = equally_spaced(m, prefs) if isinstance(prefs, int) else validate_preference(prefs, m)
    w = np.atleast_2d(w)
    truth = value_iteration(model, w, gamma)
    q = agent_q(agent, model, w)
    out = {**diagnose_q(q, model, truth), **greedy_policy_metrics(q, model, truth, gamma)}
    out["n_prefs"] = float(len(w))
    return out
