"""N Robot Confrontation games stepped as arrays, blue's one-step look-ahead included (issue 14).

:class:`ConfrontationBatch` implements mope's batched-environment protocol (:mod:`mope.envs.batched`): the
evaluation rolls out hundreds of preferences x episodes with one array step per time step instead of one Python
``env.step`` per game. Initial states come from the environment's own ``reset(seed=...)``, so game ``i`` starts
exactly where a copy of the environment reset with that seed starts; every step then applies eq. 9-12 and blue's
rule to all running games at once, with the same functions the single environment uses
(``tests/test_confrontation_batch.py`` checks them against each other step for step).
"""

from __future__ import annotations

import copy
import math

import gymnasium as gym
import numpy as np

import mope.envs.confrontation as conf
from mope.envs.batched import BENIGN_WRAPPERS


def blue_actions(red: np.ndarray, blue: np.ndarray, env: conf.RobotConfrontationEnv) -> np.ndarray:
    """Blue's ``(a, w)`` in each of N games (:func:`mope.envs.confrontation.blue_rule`, vectorised).

    Args:
        red, blue: ``(N, 4)`` states.
        env: The game (its candidates, look-ahead, threat weights and safety check).

    Returns:
        ``(N, 2)`` actions.
    """
    cand = env.blue_candidates
    n, c = len(red), len(cand)
    nb = conf.unicycle_step(np.broadcast_to(blue[:, None, :], (n, c, 4)), cand[None, :, 0], cand[None, :, 1],
                            env.blue_lookahead, env.v_max)
    nr = conf.unicycle_step(red, 0.0, 0.0, env.blue_lookahead, env.v_max)[:, None, :]
    q_r, q_b, _, d = conf.engagement_angles(np.broadcast_to(nr, (n, c, 4)), nb)
    threat = conf.threat_index(conf.angle_threat(q_b, q_r), conf.distance_threat(d, env.d_min, env.d_max),
                               *env.threat_weights)
    if env.blue_safety_time > 0:
        times = env.blue_safety_time * np.arange(1, 5) / 4
        ahead = conf.unicycle_step(np.broadcast_to(blue[:, None, None, :], (n, c, 4, 4)), cand[None, :, 0:1],
                                   cand[None, :, 1:2], times[None, None, :], env.v_max)
        margin = env.half - np.max(np.abs(ahead[..., :2]), axis=(2, 3))  # (N, C)
        safe = margin >= 0
        threat = np.where(safe, threat, -np.inf)
        none_safe = ~safe.any(axis=1)
        best = np.where(none_safe, np.argmax(margin, axis=1), np.argmax(threat, axis=1))
    else:
        best = np.argmax(threat, axis=1)
    return cand[best]


def observations(red: np.ndarray, blue: np.ndarray, env: conf.RobotConfrontationEnv) -> np.ndarray:
    """``(N, 17)`` observations (:func:`mope.envs.confrontation.observation`, vectorised)."""
    dx, dy = blue[:, 0] - red[:, 0], blue[:, 1] - red[:, 1]
    d = np.hypot(dx, dy)
    los = np.where(d > 0, np.arctan2(dy, dx), red[:, 2])
    phi_r, phi_b, rel = los - red[:, 2], los + math.pi - blue[:, 2], blue[:, 2] - red[:, 2]
    half, size = env.half, 2 * env.half
    obs = np.stack([d / env.d_max, np.cos(phi_r), np.sin(phi_r), np.cos(phi_b), np.sin(phi_b), np.cos(rel),
                    np.sin(rel), red[:, 3] / env.v_max, blue[:, 3] / env.v_max, (red[:, 0] + half) / size,
                    (half - red[:, 0]) / size, (red[:, 1] + half) / size, (half - red[:, 1]) / size,
                    np.cos(red[:, 2]), np.sin(red[:, 2]), blue[:, 0] / half, blue[:, 1] / half], axis=1)
    return np.clip(obs, -1.0, 1.0).astype(np.float32)


def outcomes_and_rewards(red: np.ndarray, blue: np.ndarray, env: conf.RobotConfrontationEnv
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Outcome codes (indices into :data:`mope.envs.confrontation.OUTCOMES`) and ``(N, 2)`` rewards (eq. 10, 12)."""
    q_r, q_b, beta, d = conf.engagement_angles(red, blue)
    qm, qo, bm, dm = env.win_thresholds
    red_won = conf.wins(q_r, q_b, beta, d, qm, qo, bm, dm)
    blue_won = conf.wins(q_b, q_r, beta, d, qm, qo, bm, dm)
    red_out = conf.out_of_arena(red, env.half)
    blue_out = conf.out_of_arena(blue, env.half)
    t_a = conf.angle_threat(q_r, q_b)
    t_d = conf.distance_threat(d, env.d_min, env.d_max)
    r_catch = np.where(red_won, 10.0, np.where(blue_won, -10.0, (t_a - 1.0) / 10.0 + (t_d - 1.0) / 10.0))
    r_move = np.where(red_out, -10.0, red[:, 3] * env.dt)
    outcome = np.select([red_won, blue_won, red_out, blue_out], [1, 2, 3, 4], default=0)
    return outcome, np.stack([r_catch, r_move], axis=1).astype(np.float32).astype(np.float64)


class ConfrontationBatch:
    """N games of a Robot Confrontation environment (continuous, discrete, or wrapped in ``DiscreteActions``).

    Args:
        env: An instance of the game (copied; it is never stepped).
        n: Number of games.
        seed: Game ``i`` starts as ``env.reset(seed=seed + i)`` does.
        seeds: Reset seed of each game instead (length ``n``).
        record: Keep every game's ``(2, 4)`` [red, blue] state at every step (:meth:`histories`).
    """

    def __init__(self, env: gym.Env, n: int, seed: int = 0, seeds: list[int] | None = None,
                 record: bool = False) -> None:
        self.n, self.seed = n, seed
        self.seeds = list(seeds) if seeds is not None else [seed + i for i in range(n)]
        self.record = record
        self._history: list[list[np.ndarray]] = [[] for _ in range(n)]
        self.base: conf.RobotConfrontationEnv = copy.deepcopy(env.unwrapped)
        self.table = self._action_table(env)
        self.red = np.zeros((n, 4))
        self.blue = np.zeros((n, 4))
        self.outcome = np.zeros(n, dtype=np.int64)

    @staticmethod
    def supports(env: gym.Env) -> bool:
        """True for the Robot Confrontation Game, bare or behind ``DiscreteActions`` / benign wrappers."""
        if not isinstance(env.unwrapped, conf.RobotConfrontationEnv):
            return False
        layer = env
        while isinstance(layer, gym.Wrapper):
            if type(layer).__name__ not in (*BENIGN_WRAPPERS, "DiscreteActions", "DiscreteConfrontation"):
                return False
            layer = layer.env
        return True

    @staticmethod
    def _action_table(env: gym.Env) -> np.ndarray | None:
        """``(K, 2)`` the ``(a, w)`` of each discrete action, or None for continuous actions."""
        layer = env
        while isinstance(layer, gym.Wrapper):
            table = getattr(layer, "_table", None) if type(layer).__name__ == "DiscreteActions" else \
                getattr(layer, "grid", None)
            if table is not None:
                return np.asarray(table, dtype=np.float64).reshape(len(table), 2)
            layer = layer.env
        grid = getattr(env.unwrapped, "grid", None)
        return None if grid is None else np.asarray(grid, dtype=np.float64)

    def reset(self) -> np.ndarray:
        """Every game's initial state, drawn by the environment's own reset with seed ``seed + i``."""
        probe = copy.deepcopy(self.base)
        for i, s in enumerate(self.seeds):
            probe.reset(seed=int(s))
            self.red[i], self.blue[i] = probe.red, probe.blue
        self.outcome[:] = 0
        if self.record:
            self._history = [[np.stack([self.red[i], self.blue[i]])] for i in range(self.n)]
        return observations(self.red, self.blue, self.base)

    def step(self, idx: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Step games ``idx`` with ``actions``; their observations, ``(len(idx), 2)`` rewards and terminations."""
        env = self.base
        act = np.asarray(actions)
        pairs = self.table[act.astype(np.int64)] if self.table is not None else act.reshape(len(idx), 2)
        a = np.clip(pairs[:, 0].astype(np.float64), -env.a_max, env.a_max)
        w = np.clip(pairs[:, 1].astype(np.float64), -env.w_max, env.w_max)
        red, blue = self.red[idx], self.blue[idx]
        b_act = blue_actions(red, blue, env)
        red = conf.unicycle_step(red, a, w, env.dt, env.v_max)
        blue = conf.unicycle_step(blue, b_act[:, 0], b_act[:, 1], env.dt, env.v_max)
        self.red[idx], self.blue[idx] = red, blue
        if self.record:
            for k, i in enumerate(idx):
                self._history[i].append(np.stack([red[k], blue[k]]))
        outcome, reward = outcomes_and_rewards(red, blue, env)
        self.outcome[idx] = outcome
        return observations(red, blue, env), reward, outcome != 0

    def histories(self) -> list[np.ndarray]:
        """Every game's ``(T + 1, 2, 4)`` states (``record=True``)."""
        return [np.asarray(h) for h in self._history]

    def outcomes(self) -> list[str]:
        """The latest outcome of every game (``running`` for one cut by the time limit)."""
        return [conf.OUTCOMES[i] for i in self.outcome]


# ------------------------------------------------------------------------------------------------------------
# reference policies for red (the points a learner must reach or pass)
# ------------------------------------------------------------------------------------------------------------
def _scripted(batch: ConfrontationBatch, idx: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    env = batch.base
    return np.stack([conf.scripted_pursuer(batch.red[i], batch.blue[i], env.half, env.a_max, env.w_max, env.v_max,
                                           env.dt) for i in idx])


def _leave(batch: ConfrontationBatch, idx: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Full speed to the nearest wall and out of the arena."""
    env = batch.base
    red = batch.red[idx]
    gaps = np.stack([env.half - red[:, 0], env.half + red[:, 0], env.half - red[:, 1], env.half + red[:, 1]], 1)
    desired = np.array([0.0, np.pi, np.pi / 2, -np.pi / 2])[np.argmin(gaps, axis=1)]
    w = np.clip(2.0 * conf.wrap_angle(desired - red[:, 2]), -env.w_max, env.w_max)
    return np.stack([np.full(len(idx), env.a_max), w], axis=1)


def _pursuit(batch: ConfrontationBatch, idx: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    env = batch.base
    red, blue = batch.red[idx], batch.blue[idx]
    bearing = np.arctan2(blue[:, 1] - red[:, 1], blue[:, 0] - red[:, 0])
    w = np.clip(2.0 * conf.wrap_angle(bearing - red[:, 2]), -env.w_max, env.w_max)
    return np.stack([np.full(len(idx), env.a_max), w], axis=1)  # steer at blue, always at full speed


def _random(batch: ConfrontationBatch, idx: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    env = batch.base
    return rng.uniform([-env.a_max, -env.w_max], [env.a_max, env.w_max], size=(len(idx), 2))


#: Red's reference policies: name -> (batch, running games, rng) -> ``(k, 2)`` continuous actions.
REFERENCE_POLICIES = {"scripted pursuer": _scripted, "leave the arena": _leave, "pure pursuit": _pursuit,
                      "random": _random}


def play_reference(name: str, seeds: list[int], max_steps: int = conf.DEFAULT_HORIZON, gamma: float = 0.99,
                   rng_seed: int = 0, **env_kwargs: object) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Play a reference policy for red on the continuous game, one episode per reset seed.

    Returns:
        ``(returns, discounted, outcomes)``: ``(n, 2)`` undiscounted and discounted returns, each episode's outcome.
    """
    if name not in REFERENCE_POLICIES:
        raise KeyError(f"unknown reference policy '{name}'; choose one of {', '.join(REFERENCE_POLICIES)}")
    policy = REFERENCE_POLICIES[name]
    batch = ConfrontationBatch(conf.RobotConfrontationEnv(**env_kwargs), len(seeds), seeds=list(seeds))
    rng = np.random.default_rng(rng_seed)
    batch.reset()
    ret, disc = np.zeros((batch.n, 2)), np.zeros((batch.n, 2))
    running, g = np.arange(batch.n), 1.0
    for _ in range(max_steps):
        _, r, term = batch.step(running, policy(batch, running, rng))
        ret[running] += r
        disc[running] += g * r
        running, g = running[~term], g * gamma
        if not running.size:
            break
    return ret, disc, batch.outcomes()
