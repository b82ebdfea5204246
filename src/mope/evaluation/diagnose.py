"""Ground truth for environments with known dynamics, and a diagnostic of a learned agent against it.

On a small deterministic environment whose dynamics are known (Deep-Sea-Treasure and its concave, mirrored
and seabed maps), the optimal action values are exact: :func:`value_iteration` computes, for every
preference ``w`` at once, the scalar ``Q*(s, a, w)``, ``V*(s, w)`` and the vector return ``Q*_vec(s, a, w)`` of
acting optimally after ``a``. :func:`diagnose` then measures a learned agent against them:

* ``path_error``: share of (w, s) pairs, s on one of w's optimal paths from the start, where the greedy action
  ``argmax_a w^T Q(s, a, w)`` is not optimal;
* ``state_error``: the same over every reachable non-terminal state;
* ``first_error_step``: along w's optimal path (first optimal action at each state), the mean index of the
  first wrong greedy action, over the preferences whose path has one (``path_failed_share`` says how many);
* ``overestimation_mean`` / ``_max``: ``max_a w^T Q(s0, a, w) - V*(s0, w)`` at the start state;
* ``abs_error_mean``: mean ``|w^T Q(s, a, w) - Q*(s, a, w)|`` over reachable states and all actions.

A wrong greedy action is one whose exact value is below ``V*(s, w)`` by more than :data:`ACTION_TOL`: ties
(several shortest routes to one treasure) all count as right.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Protocol

import gymnasium as gym
import numpy as np

from mope.errors import EnvironmentError_, MopeError
from mope.preferences import equally_spaced, validate_preference

#: An action is optimal when its exact value is within this of V*(s, w).
ACTION_TOL = 1e-6


class QFunction(Protocol):
    """Anything with ``q_values(obs, prefs) -> (n, A, m)`` vector Q-values (a :class:`~mope.agent.agent.MoPE`)."""

    def q_values(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray: ...


@dataclass
class TabularModel:
    """A deterministic finite MOMDP.

    Attributes:
        obs: ``(S, *obs_shape)`` the observation of each state.
        next_state: ``(S, A)`` successor of each state-action.
        reward: ``(S, A, m)`` vector reward of each state-action.
        terminal: ``(S, A)`` True where the transition ends the episode.
        start: The start state.
        reachable: ``(S,)`` True for non-terminal states reachable from the start.
    """

    obs: np.ndarray
    next_state: np.ndarray
    reward: np.ndarray
    terminal: np.ndarray
    start: int
    reachable: np.ndarray

    @property
    def n_states(self) -> int:
        return int(self.next_state.shape[0])

    @property
    def n_actions(self) -> int:
        return int(self.next_state.shape[1])


def _reachable(next_state: np.ndarray, terminal: np.ndarray, start: int) -> np.ndarray:
    """Non-terminal states reachable from ``start`` (breadth-first; a terminal transition's target is not entered)."""
    seen = np.zeros(next_state.shape[0], dtype=bool)
    seen[start] = True
    frontier = [start]
    while frontier:
        nxt = next_state[frontier][~terminal[frontier]]
        new = np.unique(nxt[~seen[nxt]])
        seen[new] = True
        frontier = new.tolist()
    return seen


def tabular_model(env: gym.Env) -> TabularModel:
    """The exact model of a Deep-Sea-Treasure environment (any of its maps, and the seabed-terminal variant).

    Raises:
        EnvironmentError_: for an environment whose dynamics mope does not know.
    """
    base = env.unwrapped
    if not hasattr(base, "sea_map") or type(base).__name__ not in ("DeepSeaTreasure", "SeabedDeepSeaTreasure"):
        name = env.spec.id if env.spec is not None else type(base).__name__
        raise EnvironmentError_(
            f"no ground truth for environment '{name}': mope knows the exact dynamics of Deep-Sea-Treasure "
            "(deep-sea-treasure-v0, -concave-v0, -mirrored-v0, mope/deep-sea-treasure-seabed-v0) only")
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
    """Scalarised value iteration, every preference at once, then the vector returns of the optimal policy.

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
    cont = gamma * (~model.terminal)  # (S, A)
    r_scal = np.einsum("nm,sam->nsa", prefs, model.reward)  # (n, S, A)
    # start below every value (the worst reward forever): the iterates then rise monotonically and reach V*
    # exactly once they span the longest optimal path
    v = np.broadcast_to(r_scal.min(axis=(1, 2))[:, None] / (1.0 - gamma), (len(prefs), model.n_states)).copy()
    for _ in range(max_iter):
        q = r_scal + cont[None] * v[:, model.next_state]
        v_new = q.max(axis=2)
        done = np.max(np.abs(v_new - v)[:, model.reachable]) <= tol
        v = v_new
        if done:
            break
    q = r_scal + cont[None] * v[:, model.next_state]
    # vector returns of the greedy (optimal) policy: iterate its vector Bellman equation to the same precision
    pi = q.argmax(axis=2)  # (n, S)
    n_idx = np.arange(len(prefs))[:, None]
    s_idx = np.arange(model.n_states)[None, :]
    r_pi = model.reward[s_idx, pi]  # (n, S, m)
    next_pi = model.next_state[s_idx, pi]  # (n, S)
    cont_pi = cont[s_idx, pi]  # (n, S)
    v_vec = np.zeros((len(prefs), model.n_states, model.reward.shape[2]))
    for _ in range(max_iter):
        v_vec_new = r_pi + cont_pi[..., None] * v_vec[n_idx, next_pi]
        done = np.max(np.abs(v_vec_new - v_vec)[:, model.reachable]) <= tol
        v_vec = v_vec_new
        if done:
            break
    q_vec = model.reward[None] + cont[None, ..., None] * v_vec[n_idx[..., None], model.next_state[None]]
    return GroundTruth(prefs, q, q.max(axis=2), q_vec)


def optimal_path_states(model: TabularModel, truth: GroundTruth) -> np.ndarray:
    """``(n, S)`` True for states on some optimal path of each preference (every optimal action followed)."""
    opt = truth.optimal_actions()
    n = len(truth.prefs)
    on = np.zeros((n, model.n_states), dtype=bool)
    on[:, model.start] = True
    frontier = on.copy()
    for _ in range(model.n_states):
        # successors of frontier states through optimal, non-terminal transitions
        step = frontier[..., None] & opt & ~model.terminal[None]  # (n, S, A)
        nxt = np.zeros_like(on)
        idx_n, idx_s, idx_a = np.nonzero(step)
        nxt[idx_n, model.next_state[idx_s, idx_a]] = True
        frontier = nxt & ~on
        on |= nxt
        if not frontier.any():
            break
    return on


def canonical_paths(model: TabularModel, truth: GroundTruth, horizon: int = 1000) -> np.ndarray:
    """``(n, T)`` states of each preference's optimal path (first optimal action), -1 after the end."""
    n = len(truth.prefs)
    pi = truth.q.argmax(axis=2)
    state = np.full(n, model.start)
    alive = np.ones(n, dtype=bool)
    out = []
    for _ in range(horizon):
        out.append(np.where(alive, state, -1))
        a = pi[np.arange(n), state]
        ends = model.terminal[state, a]
        state = np.where(alive, model.next_state[state, a], state)
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
    m = model.reward.shape[2]
    w = equally_spaced(m, prefs) if isinstance(prefs, int) else validate_preference(prefs, m)
    w = np.atleast_2d(w)
    truth = value_iteration(model, w, gamma)
    out = diagnose_q(agent_q(agent, model, w), model, truth)
    out["n_prefs"] = float(len(w))
    return out
