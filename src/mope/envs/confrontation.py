"""Robot Confrontation Game (paper sec. 4, eq. 9-12): two unicycle robots, red learns, blue follows a rule.

Ids (registered on import, idempotently):

* ``mope/RobotConfrontation-v0`` -- continuous actions ``[a, w]`` (the paper's setting), for PPO and friends;
* ``mope/RobotConfrontationDiscrete-v0`` -- the same game with a grid of ``n_accel x n_turn`` actions, for
  EQL and MoPE.

Geometry (``docs/confrontation.md`` has a figure). For robots at ``p_r``, ``p_b`` with headings ``theta_r``,
``theta_b`` (the direction of their velocity):

* ``d = |p_b - p_r|``;
* ``q_r`` in [0, pi]: angle between red's heading and the line from red to blue (0: red points at blue);
* ``q_b`` in [0, pi]: angle between blue's heading and the line from blue to red (0: blue points at red);
* ``beta`` in [0, pi]: angle between the two headings (0: both move the same way).

Red wins when ``q_r < 30 deg, q_b > 30 deg, beta < 40 deg, d < 0.3 m`` (eq. 10): red is close behind blue,
pointing at it, while blue is not pointing back. Blue wins under the mirror (``q_r`` and ``q_b`` swapped).

Every number the paper leaves open is a constructor argument; the defaults and their reasons are in
``docs/confrontation.md``. The episode length is the registered time limit (150 steps of 0.2 s = 30 s),
changed with ``mo_gymnasium.make(id, max_episode_steps=N)``, as Gymnasium does for every environment.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from mope.errors import EnvironmentError_

CONTINUOUS_ID = "mope/RobotConfrontation-v0"
DISCRETE_ID = "mope/RobotConfrontationDiscrete-v0"
#: Registered episode length (steps) and the default step length (s).
DEFAULT_HORIZON = 150
DEFAULT_DT = 0.2

#: Outcome codes of an episode step (``info["outcome"]``).
OUTCOMES = ("running", "red_win", "blue_win", "red_out", "blue_out")


# ------------------------------------------------------------------------------------------------------------
# dynamics (eq. 9)
# ------------------------------------------------------------------------------------------------------------
def wrap_angle(x: np.ndarray | float) -> np.ndarray:
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(x, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


def unicycle_step(state: np.ndarray, accel: np.ndarray | float, turn: np.ndarray | float, dt: float,
                  v_max: float) -> np.ndarray:
    """Integrate eq. 9 (x' = v cos th, y' = v sin th, th' = w, v' = a) over ``dt`` with constant ``a, w``.

    The speed is clipped to ``[0, v_max]``. Position uses the exact arc for the step's mean speed
    ``v_m = (v_0 + v_1) / 2``: exact when the speed is constant (a straight line, or a circle of radius
    ``v / w``), second-order accurate while accelerating.

    Args:
        state: ``(..., 4)`` rows ``(x, y, theta, v)``.
        accel: Acceleration ``a`` (m/s^2), broadcast against ``state[..., 0]``.
        turn: Turn rate ``w`` (rad/s), broadcast likewise.
        dt: Step length (s); an array broadcasts like ``accel``.
        v_max: Speed limit (m/s).

    Returns:
        The next states, same shape as ``state``; headings wrapped to [-pi, pi).
    """
    s = np.asarray(state, dtype=np.float64)
    a = np.asarray(accel, dtype=np.float64)
    w = np.asarray(turn, dtype=np.float64)
    v = s[..., 3]
    v1 = np.minimum(np.maximum(v + a * dt, 0.0), v_max)
    dth = w * dt
    # the exact arc's chord: length (v_m dt) sin(dth/2) / (dth/2) along the mean heading th + dth/2
    chord = 0.5 * (v + v1) * dt * np.sinc(dth / (2 * np.pi))
    mid = s[..., 2] + 0.5 * dth
    out = np.empty(np.broadcast_shapes(v.shape, a.shape, w.shape, np.shape(dt)) + (4,))
    out[..., 0] = s[..., 0] + chord * np.cos(mid)
    out[..., 1] = s[..., 1] + chord * np.sin(mid)
    out[..., 2] = wrap_angle(s[..., 2] + dth)
    out[..., 3] = v1
    return out


# ------------------------------------------------------------------------------------------------------------
# geometry, threat (eq. 11) and outcome (eq. 10)
# ------------------------------------------------------------------------------------------------------------
def engagement_angles(red: np.ndarray, blue: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The angles of eq. 10 (paper Fig. 4) between two robots, from red's point of view.

    Args:
        red: ``(..., 4)`` red states ``(x, y, theta, v)``.
        blue: ``(..., 4)`` blue states.

    Returns:
        ``(q_r, q_b, beta, d)``: ``q_r`` = angle between red's heading and the line red -> blue; ``q_b`` = angle
        between blue's heading and the line blue -> red; ``beta`` = angle between the headings; all in [0, pi];
        ``d`` = distance (m). At ``d = 0`` the line is undefined and taken along red's heading.
    """
    r = np.asarray(red, dtype=np.float64)
    b = np.asarray(blue, dtype=np.float64)
    dx = b[..., 0] - r[..., 0]
    dy = b[..., 1] - r[..., 1]
    d = np.hypot(dx, dy)
    los = np.where(d > 0, np.arctan2(dy, dx), r[..., 2])  # bearing of blue seen from red
    q_r = np.abs(wrap_angle(r[..., 2] - los))
    q_b = np.abs(wrap_angle(b[..., 2] - (los + np.pi)))
    beta = np.abs(wrap_angle(b[..., 2] - r[..., 2]))
    return q_r, q_b, beta, d


def angle_threat(q_r: np.ndarray | float, q_b: np.ndarray | float) -> np.ndarray:
    """Angle threat of red on blue, ``T_a = (q_b - q_r) / pi`` (eq. 11); in [-1, 1].

    1 when red points at blue (``q_r = 0``) and blue points straight away from red (``q_b = pi``); -1 in the
    mirror position. Blue's own angle threat is ``-T_a`` (swap ``q_r`` and ``q_b``).
    """
    return (np.asarray(q_b, dtype=np.float64) - np.asarray(q_r, dtype=np.float64)) / np.pi


def distance_threat(d: np.ndarray | float, d_min: float, d_max: float) -> np.ndarray:
    """Distance threat ``T_d = (d_max + d_min - 2 d) / (d_max - d_min)`` (eq. 11); in [-1, 1].

    1 at ``d_min``, -1 at ``d_max``; ``d`` is clipped to ``[d_min, d_max]`` so the bound holds everywhere.
    The same for both robots (distance is symmetric).
    """
    dc = np.clip(np.asarray(d, dtype=np.float64), d_min, d_max)
    return (d_max + d_min - 2.0 * dc) / (d_max - d_min)


def threat_index(t_a: np.ndarray | float, t_d: np.ndarray | float, a: float = 0.1, b: float = 0.9) -> np.ndarray:
    """Threat index ``T = a T_a + b T_d`` (eq. 11; the paper uses a = 0.1, b = 0.9)."""
    return a * np.asarray(t_a, dtype=np.float64) + b * np.asarray(t_d, dtype=np.float64)


def wins(q_own: np.ndarray | float, q_other: np.ndarray | float, beta: np.ndarray | float, d: np.ndarray | float,
         q_own_max: float = math.radians(30), q_other_min: float = math.radians(30),
         beta_max: float = math.radians(40), d_max: float = 0.3) -> np.ndarray:
    """Win test of eq. 10: ``q_own < 30 deg, q_other > 30 deg, beta < 40 deg, d < 0.3 m``.

    Red wins with ``wins(q_r, q_b, beta, d)``; blue wins under the mirror, ``wins(q_b, q_r, beta, d)``.
    """
    return ((np.asarray(q_own) < q_own_max) & (np.asarray(q_other) > q_other_min)
            & (np.asarray(beta) < beta_max) & (np.asarray(d) < d_max))


def out_of_arena(state: np.ndarray, half_size: float) -> np.ndarray:
    """True where a robot's position lies outside the square ``[-half_size, half_size]^2``."""
    s = np.asarray(state, dtype=np.float64)
    return (np.abs(s[..., 0]) > half_size) | (np.abs(s[..., 1]) > half_size)


def action_grid(a_max: float, w_max: float, n_accel: int, n_turn: int) -> np.ndarray:
    """The ``(n_accel * n_turn, 2)`` grid of ``(a, w)`` pairs, accelerations major (``n >= 2`` includes both ends).

    ``n = 1`` gives the single value 0 for that axis. Odd ``n`` includes 0 (coast / go straight).
    """
    if n_accel < 1 or n_turn < 1:
        raise EnvironmentError_(f"action grid {n_accel} x {n_turn} is out of range: both sizes must be >= 1")
    acc = np.linspace(-a_max, a_max, n_accel) if n_accel > 1 else np.zeros(1)
    turn = np.linspace(-w_max, w_max, n_turn) if n_turn > 1 else np.zeros(1)
    return np.stack(np.meshgrid(acc, turn, indexing="ij"), axis=-1).reshape(-1, 2)


def blue_rule(red: np.ndarray, blue: np.ndarray, candidates: np.ndarray, dt: float, v_max: float,
              d_min: float, d_max: float, weights: tuple[float, float] = (0.1, 0.9), half_size: float | None = None,
              safety_time: float = 0.0) -> int:
    """Blue's rule: the candidate action with the highest predicted threat of blue on red (eq. 11).

    Single-step forward prediction: blue's next state under each candidate ``(a, w)`` and red's next state
    under constant velocity (``a = w = 0``; blue does not know red's control) are predicted over ``dt``; the
    threat from blue's point of view is ``a (q_r - q_b) / pi + b T_d`` (the mirror of red's ``T_a``). When
    ``half_size`` is given, candidates that would take blue out of the arena within ``safety_time`` seconds
    (holding the action) are dropped, unless all would, then the one ending farthest inside is kept. Ties go
    to the first candidate (the grid's order).

    Returns:
        The index of the chosen row of ``candidates``.
    """
    cand = np.asarray(candidates, dtype=np.float64)
    nb = unicycle_step(np.broadcast_to(blue, (len(cand), 4)), cand[:, 0], cand[:, 1], dt, v_max)
    nr = unicycle_step(red, 0.0, 0.0, dt, v_max)
    q_r, q_b, _, d = engagement_angles(nr, nb)
    threat = threat_index(angle_threat(q_b, q_r), distance_threat(d, d_min, d_max), *weights)
    if half_size is not None and safety_time > 0:
        ahead = _arc_points(blue, cand, safety_time, v_max)
        margin = half_size - np.max(np.abs(ahead[..., :2]), axis=(1, 2))
        safe = margin >= 0
        if not safe.any():
            return int(np.argmax(margin))
        threat = np.where(safe, threat, -np.inf)
    return int(np.argmax(threat))


def _arc_points(state: np.ndarray, cand: np.ndarray, horizon: float, v_max: float, n: int = 4) -> np.ndarray:
    """``(len(cand), n, 4)`` states at ``horizon * k / n``, ``k = 1..n``, holding each candidate action.

    Each point is one :func:`unicycle_step` of length ``horizon * k / n`` (exact for constant speed; a close
    approximation when the speed limit cuts in, which is all a safety check needs).
    """
    times = horizon * np.arange(1, n + 1) / n
    return unicycle_step(np.asarray(state, dtype=np.float64), cand[:, 0:1], cand[:, 1:2], times[None, :], v_max)


def scripted_pursuer(red: np.ndarray, blue: np.ndarray, half: float, a_max: float = 0.2, w_max: float = 0.8,
                     v_max: float = 0.5, dt: float = DEFAULT_DT, gain: float = 2.0, max_lead: float = 1.5,
                     wall_time: float = 1.5, turn_slow: float = math.radians(60)) -> np.ndarray:
    """A simple rule for red (a baseline, and the balance check): lead pursuit of blue, away from the walls.

    Red steers (proportional turn rate, gain ``gain``) at blue's position extrapolated ``min(d / v_r, max_lead)``
    seconds ahead. It brakes while blue is more than ``turn_slow`` off its nose (a slower robot turns tighter),
    else goes at full speed while far, and within 0.6 m matches blue's speed so as to settle behind it. If
    going straight for ``wall_time`` seconds would leave the arena, it steers to the arena's centre instead.

    Returns:
        ``[a, w]``.
    """
    q_r, _, _, d = engagement_angles(red, blue)
    lead = min(float(d) / max(red[3], 0.1), max_lead)
    tx = blue[0] + blue[3] * math.cos(blue[2]) * lead
    ty = blue[1] + blue[3] * math.sin(blue[2]) * lead
    desired = math.atan2(ty - red[1], tx - red[0])
    ahead = red[:2] + red[3] * wall_time * np.array([math.cos(red[2]), math.sin(red[2])])
    if np.any(np.abs(ahead) > half):
        desired = math.atan2(-red[1], -red[0])
    w = float(np.clip(gain * wrap_angle(desired - red[2]), -w_max, w_max))
    if q_r > turn_slow:  # target well off the nose: slow down to turn tighter (radius v / w)
        a = -a_max
    elif d > 0.6:
        a = a_max
    else:
        a = float(np.clip((blue[3] - red[3]) / dt, -a_max, a_max))
    return np.array([a, w])


# ------------------------------------------------------------------------------------------------------------
# the environment
# ------------------------------------------------------------------------------------------------------------
class RobotConfrontationEnv(gym.Env):
    """Robot Confrontation Game with continuous actions ``[a, w]`` and vector reward ``[r_catch, r_move]``.

    Args:
        render_mode: ``None`` or ``"rgb_array"``.
        arena_size: Side of the square arena (m), centred on the origin. Default 5.
        dt: Step length (s). Default 0.2.
        v_max: Speed limit (m/s); speeds lie in ``[0, v_max]``. Default 0.5.
        a_max: Acceleration limit (paper: 0.2). w_max: turn-rate limit (paper: 0.8 rad/s).
        init_margin: Initial positions are uniform in the square shrunk by this margin (m). Default 1.
        init_distance: ``(low, high)`` initial distance between the robots (m), by rejection. Default (1, 2.5).
        init_speed: ``(low, high)`` of the uniform initial speeds (m/s). Default (0, 0.25).
        threat_weights: ``(a, b)`` of eq. 11 (paper: 0.1, 0.9).
        d_min: ``d_min`` of eq. 11 (m). Default 0: the closest two robots can be.
        d_max: ``d_max`` of eq. 11; default the arena's diagonal, the farthest they can be.
        win_angles: ``(q_own_max, q_other_min, beta_max)`` of eq. 10 in degrees (paper: 30, 30, 40).
        win_distance: ``d`` threshold of eq. 10 (paper: 0.3 m).
        blue_accels: Blue's candidate accelerations (default ``-a_max, 0, a_max``).
        blue_turns: Blue's candidate turn rates (default ``-w_max, -w_max/2, 0, w_max/2, w_max``).
        blue_lookahead: Length (s) of blue's single prediction step; default ``dt``.
        blue_safety_time: Blue drops actions that leave the arena within this time (s). Default 1.5; 0 disables.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, render_mode: str | None = None, arena_size: float = 5.0, dt: float = DEFAULT_DT,
                 v_max: float = 0.5, a_max: float = 0.2, w_max: float = 0.8, init_margin: float = 1.0,
                 init_distance: tuple[float, float] = (1.0, 2.5), init_speed: tuple[float, float] = (0.0, 0.25),
                 threat_weights: tuple[float, float] = (0.1, 0.9), d_min: float = 0.0, d_max: float | None = None,
                 win_angles: tuple[float, float, float] = (30.0, 30.0, 40.0), win_distance: float = 0.3,
                 blue_accels: Sequence[float] | None = None, blue_turns: Sequence[float] | None = None,
                 blue_lookahead: float | None = None, blue_safety_time: float = 1.5) -> None:
        def need(ok: bool, what: str) -> None:
            if not ok:
                raise EnvironmentError_(f"RobotConfrontation: {what}")

        need(render_mode is None or render_mode in self.metadata["render_modes"],
             f"render_mode={render_mode!r} is not supported; use None or 'rgb_array'")
        for name, val in (("arena_size", arena_size), ("dt", dt), ("v_max", v_max), ("a_max", a_max),
                          ("w_max", w_max), ("win_distance", win_distance)):
            need(math.isfinite(val) and val > 0, f"{name}={val} is out of range: must be > 0")
        self.half = arena_size / 2
        need(0 <= init_margin < self.half, f"init_margin={init_margin} is out of range: must lie in [0, {self.half})")
        lo_d, hi_d = init_distance
        inner = 2 * (self.half - init_margin)
        need(0 <= lo_d <= hi_d and lo_d < inner * math.sqrt(2),
             f"init_distance={init_distance} is out of range: need 0 <= low <= high and low < {inner * 2**0.5:.2f}")
        need(0 <= init_speed[0] <= init_speed[1] <= v_max,
             f"init_speed={init_speed} is out of range: need 0 <= low <= high <= v_max={v_max}")
        self.d_min = float(d_min)
        self.d_max = float(d_max) if d_max is not None else arena_size * math.sqrt(2)
        need(0 <= self.d_min < self.d_max, f"d_min={d_min}, d_max={d_max} are out of range: need 0 <= d_min < d_max")
        need(blue_safety_time >= 0, f"blue_safety_time={blue_safety_time} is out of range: must be >= 0")

        self.render_mode = render_mode
        self.arena_size, self.dt, self.v_max, self.a_max, self.w_max = arena_size, dt, v_max, a_max, w_max
        self.init_margin, self.init_distance, self.init_speed = init_margin, tuple(init_distance), tuple(init_speed)
        self.threat_weights = (float(threat_weights[0]), float(threat_weights[1]))
        self.win_thresholds = (*(math.radians(x) for x in win_angles), float(win_distance))
        acc = np.array([-a_max, 0.0, a_max]) if blue_accels is None else np.asarray(blue_accels, dtype=np.float64)
        turn = (np.array([-w_max, -w_max / 2, 0.0, w_max / 2, w_max]) if blue_turns is None
                else np.asarray(blue_turns, dtype=np.float64))
        need(acc.size > 0 and bool(np.all(np.abs(acc) <= a_max + 1e-12)),
             f"blue_accels={acc.tolist()} must be non-empty and within +-a_max={a_max} (same capabilities as red)")
        need(turn.size > 0 and bool(np.all(np.abs(turn) <= w_max + 1e-12)),
             f"blue_turns={turn.tolist()} must be non-empty and within +-w_max={w_max} (same capabilities as red)")
        self.blue_candidates = np.stack(np.meshgrid(acc, turn, indexing="ij"), axis=-1).reshape(-1, 2)
        self.blue_lookahead = dt if blue_lookahead is None else float(blue_lookahead)
        need(self.blue_lookahead > 0, f"blue_lookahead={blue_lookahead} is out of range: must be > 0")
        self.blue_safety_time = float(blue_safety_time)

        self.action_space = gym.spaces.Box(np.array([-a_max, -w_max], dtype=np.float32),
                                           np.array([a_max, w_max], dtype=np.float32), dtype=np.float32)
        self.observation_space = gym.spaces.Box(-1.0, 1.0, shape=(OBS_DIM,), dtype=np.float32)
        self.reward_space = gym.spaces.Box(np.array([-10.0, -10.0], dtype=np.float32),
                                           np.array([10.0, v_max * dt], dtype=np.float32), dtype=np.float32)
        self.reward_dim = 2
        self.red = np.zeros(4)
        self.blue = np.zeros(4)
        self.history: list[np.ndarray] = []  #: ``(2, 4)`` [red, blue] states of the episode, from the reset
        self.outcome = "running"
        self._fig: Any = None

    # -- state -------------------------------------------------------------------------------------------
    def _sample_initial(self) -> tuple[np.ndarray, np.ndarray]:
        lim = self.half - self.init_margin
        lo, hi = self.init_distance
        for _ in range(10_000):
            p = self.np_random.uniform(-lim, lim, size=(2, 2))
            if lo <= np.linalg.norm(p[0] - p[1]) <= hi:
                break
        else:  # pragma: no cover - the constructor checks the range is reachable
            raise EnvironmentError_(f"init_distance={self.init_distance} could not be met in the arena")
        th = self.np_random.uniform(-np.pi, np.pi, size=2)
        v = self.np_random.uniform(*self.init_speed, size=2)
        return np.array([*p[0], th[0], v[0]]), np.array([*p[1], th[1], v[1]])

    def set_state(self, red: Sequence[float], blue: Sequence[float]) -> np.ndarray:
        """Place both robots at ``(x, y, theta, v)`` (tests, scripted scenarios); return the observation."""
        self.red = np.asarray(red, dtype=np.float64).copy()
        self.blue = np.asarray(blue, dtype=np.float64).copy()
        self.history = [np.stack([self.red, self.blue])]
        self.outcome = "running"
        return self._obs()

    def _obs(self) -> np.ndarray:
        return observation(self.red, self.blue, self.half, self.v_max, self.d_max)

    def geometry(self) -> dict[str, float]:
        """``q_r, q_b, beta, d`` (radians, m), ``T_a, T_d`` and red's threat ``T`` at the current state."""
        q_r, q_b, beta, d = engagement_angles(self.red, self.blue)
        t_a = float(angle_threat(q_r, q_b))
        t_d = float(distance_threat(d, self.d_min, self.d_max))
        return {"q_r": float(q_r), "q_b": float(q_b), "beta": float(beta), "d": float(d), "T_a": t_a,
                "T_d": t_d, "T": float(threat_index(t_a, t_d, *self.threat_weights))}

    # -- gym API -----------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Draw both robots' states (see the class docstring), or use ``options={"red": ..., "blue": ...}``."""
        super().reset(seed=seed)
        if options and "red" in options and "blue" in options:
            red, blue = options["red"], options["blue"]
        else:
            red, blue = self._sample_initial()
        obs = self.set_state(red, blue)
        return obs, {"outcome": self.outcome, **self.geometry()}

    def blue_action(self) -> np.ndarray:
        """Blue's ``(a, w)`` for the current state (see :func:`blue_rule`)."""
        i = blue_rule(self.red, self.blue, self.blue_candidates, self.blue_lookahead, self.v_max, self.d_min,
                      self.d_max, self.threat_weights, self.half, self.blue_safety_time)
        return self.blue_candidates[i]

    def step(self, action: Any) -> tuple[np.ndarray, np.ndarray, bool, bool, dict]:
        """Advance both robots by ``dt``: red with ``action = [a, w]`` (clipped to the limits), blue by its rule."""
        act = np.asarray(action, dtype=np.float64).reshape(-1)
        if act.shape != (2,) or not np.all(np.isfinite(act)):
            raise EnvironmentError_(f"RobotConfrontation: action {action!r} is not a finite pair [a, w]")
        a = float(np.clip(act[0], -self.a_max, self.a_max))
        w = float(np.clip(act[1], -self.w_max, self.w_max))
        blue_act = self.blue_action()
        self.red = unicycle_step(self.red, a, w, self.dt, self.v_max)
        self.blue = unicycle_step(self.blue, blue_act[0], blue_act[1], self.dt, self.v_max)
        self.history.append(np.stack([self.red, self.blue]))
        geo = self.geometry()
        red_won, blue_won, red_out, blue_out = self._events(geo)
        reward = step_reward(red_won, blue_won, red_out, geo["T_a"], geo["T_d"], self.red[3], self.dt)
        self.outcome = ("red_win" if red_won else "blue_win" if blue_won else "red_out" if red_out
                        else "blue_out" if blue_out else "running")
        terminated = self.outcome != "running"
        info = {"outcome": self.outcome, "blue_action": blue_act.copy(), **geo}
        return self._obs(), reward, terminated, False, info

    def _events(self, geo: dict[str, float]) -> tuple[bool, bool, bool, bool]:
        qm, qo, bm, dm = self.win_thresholds
        red_won = bool(wins(geo["q_r"], geo["q_b"], geo["beta"], geo["d"], qm, qo, bm, dm))
        blue_won = bool(wins(geo["q_b"], geo["q_r"], geo["beta"], geo["d"], qm, qo, bm, dm))
        return red_won, blue_won, bool(out_of_arena(self.red, self.half)), bool(out_of_arena(self.blue, self.half))

    # -- rendering ---------------------------------------------------------------------------------------
    def hv_reference_point(self, gamma: float, horizon: int | None = None) -> np.ndarray:
        """Hypervolume reference point for returns discounted by ``gamma`` over ``horizon`` steps.

        :func:`mope.envs.default_ref_point` asks the environment for it: the worst return minus 1
        (:func:`reference_point`), so it follows the discount and episode length actually used.
        """
        return reference_point(gamma, horizon or DEFAULT_HORIZON)

    def render(self) -> np.ndarray | None:
        """An ``(H, W, 3)`` uint8 frame of the arena and both trajectories (``render_mode="rgb_array"``)."""
        if self.render_mode != "rgb_array":
            return None
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        if self._fig is None:  # a figure of its own (no pyplot, no global backend change)
            self._fig = Figure(figsize=(4, 4), dpi=100)
            FigureCanvasAgg(self._fig)
        fig = self._fig
        fig.clear()
        ax = fig.add_subplot(1, 1, 1)
        draw_episode(ax, np.asarray(self.history), self.half, title=f"t = {(len(self.history) - 1) * self.dt:.1f} s"
                     f"   {self.outcome}")
        fig.tight_layout()
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()

    def close(self) -> None:
        self._fig = None


OBS_DIM = 17


def observation(red: np.ndarray, blue: np.ndarray, half: float, v_max: float, d_max: float) -> np.ndarray:
    """The 17 normalised features red sees, all in [-1, 1] (clipped).

    ``0`` d / d_max; ``1, 2`` cos, sin of blue's bearing relative to red's heading (``q_r`` with its side);
    ``3, 4`` cos, sin of red's bearing relative to blue's heading (``q_b`` with its side); ``5, 6`` cos, sin of
    ``theta_b - theta_r`` (``beta`` with its side); ``7, 8`` v_r / v_max, v_b / v_max; ``9-12`` red's distance
    to the left, right, bottom and top walls / arena size; ``13, 14`` cos, sin of red's heading;
    ``15, 16`` blue's position / half the arena size.
    """
    dx, dy = blue[0] - red[0], blue[1] - red[1]
    d = math.hypot(dx, dy)
    los = math.atan2(dy, dx) if d > 0 else red[2]
    phi_r = los - red[2]
    phi_b = los + math.pi - blue[2]
    rel = blue[2] - red[2]
    size = 2 * half
    walls = [(red[0] + half) / size, (half - red[0]) / size, (red[1] + half) / size, (half - red[1]) / size]
    obs = np.array([d / d_max, math.cos(phi_r), math.sin(phi_r), math.cos(phi_b), math.sin(phi_b), math.cos(rel),
                    math.sin(rel), red[3] / v_max, blue[3] / v_max, *walls, math.cos(red[2]), math.sin(red[2]),
                    blue[0] / half, blue[1] / half], dtype=np.float64)
    return np.clip(obs, -1.0, 1.0).astype(np.float32)


def step_reward(red_won: bool, blue_won: bool, red_out: bool, t_a: float, t_d: float, v: float,
                dt: float) -> np.ndarray:
    """Vector reward ``[r_catch, r_move]`` of eq. 12.

    ``r_catch`` = 10 if red wins, -10 if blue wins, else ``(T_a - 1)/10 + (T_d - 1)/10`` (in [-0.4, 0]);
    ``r_move`` = -10 if red left the arena, else ``v dt`` (the distance red covered, with ``v`` its new speed).
    """
    r_catch = 10.0 if red_won else -10.0 if blue_won else (t_a - 1.0) / 10.0 + (t_d - 1.0) / 10.0
    r_move = -10.0 if red_out else v * dt
    return np.array([r_catch, r_move], dtype=np.float32)


def worst_return(gamma: float = 0.99, horizon: int = DEFAULT_HORIZON) -> np.ndarray:
    """The lowest (discounted) return each objective can take in an episode of at most ``horizon`` steps.

    ``r_catch``: every step costs at least -0.4 and a loss ends the episode with -10, so the worst is
    ``min_t [-0.4 sum_{k<t} gamma^k - 10 gamma^t]`` over ``t < horizon``, or -0.4 on every step.
    ``r_move``: every step gives ``>= 0`` except leaving the arena (-10, ends the episode), worst at the first step.
    """
    t = np.arange(horizon)
    g = np.power(float(gamma), t)
    before = np.concatenate([[0.0], np.cumsum(g)[:-1]])
    catch = min(float(np.min(-0.4 * before - 10.0 * g)), float(-0.4 * g.sum()))
    return np.array([catch, -10.0])


def reference_point(gamma: float = 0.99, horizon: int = DEFAULT_HORIZON) -> np.ndarray:
    """Hypervolume reference point: :func:`worst_return` minus 1 on each objective (as ``default_ref_point``)."""
    return worst_return(gamma, horizon) - 1.0


# ------------------------------------------------------------------------------------------------------------
# discrete actions
# ------------------------------------------------------------------------------------------------------------
class DiscreteConfrontation(gym.ActionWrapper):
    """Discretise the continuous ``[a, w]`` action into a grid of ``n_accel x n_turn`` actions.

    Action ``i`` is row ``i`` of :func:`action_grid` (accelerations major): with the default 3 x 5 grid, action
    ``5 j + k`` is acceleration ``(-0.2, 0, 0.2)[j]`` and turn rate ``(-0.8, -0.4, 0, 0.4, 0.8)[k]``.
    """

    def __init__(self, env: gym.Env, n_accel: int = 3, n_turn: int = 5) -> None:
        super().__init__(env)
        base = env.unwrapped
        self.grid = action_grid(base.a_max, base.w_max, n_accel, n_turn)
        self.action_space = gym.spaces.Discrete(len(self.grid))

    def action(self, action: Any) -> np.ndarray:
        """The ``(a, w)`` pair of a discrete action."""
        return self.grid[_index(action, len(self.grid))].astype(np.float32)


def _index(action: Any, n: int) -> int:
    i = int(np.asarray(action).reshape(-1)[0]) if np.size(action) == 1 else -1
    if not 0 <= i < n:
        raise EnvironmentError_(f"RobotConfrontation: action {action!r} is out of range: choose 0..{n - 1}")
    return i


class RobotConfrontationDiscreteEnv(RobotConfrontationEnv):
    """The game with :class:`DiscreteConfrontation`'s action grid built in (``mope/RobotConfrontationDiscrete-v0``).

    Same dynamics, rules and rewards as :class:`RobotConfrontationEnv`; the grid lives in the environment
    itself rather than in a wrapper so that ``env.unwrapped`` still takes integer actions and the id alone
    rebuilds the discrete game (checkpoints rebuild their environment from ``config.env_id``).

    Args:
        n_accel: Grid size along the acceleration (default 3: -a_max, 0, a_max).
        n_turn: Grid size along the turn rate (default 5: -w_max, -w_max/2, 0, w_max/2, w_max).
        **kwargs: As :class:`RobotConfrontationEnv`.
    """

    def __init__(self, n_accel: int = 3, n_turn: int = 5, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.grid = action_grid(self.a_max, self.w_max, n_accel, n_turn)
        self.action_space = gym.spaces.Discrete(len(self.grid))

    def step(self, action: Any) -> tuple[np.ndarray, np.ndarray, bool, bool, dict]:
        """Step with the grid action ``action`` (an int)."""
        return super().step(self.grid[_index(action, len(self.grid))])


# ------------------------------------------------------------------------------------------------------------
# plots
# ------------------------------------------------------------------------------------------------------------
def draw_episode(ax: Any, history: np.ndarray, half: float, title: str | None = None, legend: bool = True) -> None:
    """Draw an episode's ``(T, 2, 4)`` [red, blue] states on a matplotlib axis: arena, paths, final poses."""
    from matplotlib.patches import Rectangle

    ax.add_patch(Rectangle((-half, -half), 2 * half, 2 * half, fill=False, lw=1.5, color="k"))
    for i, (color, name) in enumerate((("tab:red", "red"), ("tab:blue", "blue"))):
        xy = history[:, i, :2]
        ax.plot(xy[:, 0], xy[:, 1], color=color, lw=1.4, label=name)
        ax.plot(*xy[0], "o", color=color, ms=4, mfc="white")
        th = history[-1, i, 2]
        ax.quiver(xy[-1, 0], xy[-1, 1], math.cos(th), math.sin(th), color=color, angles="xy", scale_units="xy",
                  scale=3.0, width=0.012)
    ax.set_xlim(-half * 1.08, half * 1.08)
    ax.set_ylim(-half * 1.08, half * 1.08)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=8)
    if legend:
        ax.legend(loc="upper right", fontsize=6)


def plot_trajectory(history: np.ndarray, path: str | Path, half: float = 2.5, title: str | None = None) -> Path:
    """Save a trajectory plot of one episode (``env.unwrapped.history``) as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.2, 4.2))
    draw_episode(ax, np.asarray(history), half, title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)


def plot_geometry(path: str | Path) -> Path:
    """The figure of ``docs/confrontation.md``: the angles ``q_r``, ``q_b``, ``beta`` and the distance ``d``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Arc

    red = np.array([0.0, 0.0, math.radians(45), 1.0])
    blue = np.array([2.0, 0.6, math.radians(75), 1.0])
    q_r, q_b, beta, d = engagement_angles(red, blue)
    los = math.atan2(blue[1] - red[1], blue[0] - red[0])
    fig, ax = plt.subplots(figsize=(6.0, 3.6))
    ax.plot([red[0], blue[0]], [red[1], blue[1]], "k--", lw=1)
    ax.text(1.0, 0.18, f"d = {d:.2f} m", fontsize=9)
    ext = 0.9
    for s, color, name in ((red, "tab:red", "red"), (blue, "tab:blue", "blue")):
        ax.annotate("", xy=(s[0] + ext * math.cos(s[2]), s[1] + ext * math.sin(s[2])), xytext=(s[0], s[1]),
                    arrowprops={"arrowstyle": "->", "color": color, "lw": 2})
        ax.plot(s[0], s[1], "o", color=color, ms=10)
        ax.text(s[0] - 0.15, s[1] - 0.25, f"{name}\nheading θ", color=color, fontsize=8, ha="center", va="top")
    # q_r: between red's heading and the line red -> blue
    ax.add_patch(Arc((0, 0), 1.0, 1.0, theta1=math.degrees(los), theta2=math.degrees(red[2]), color="tab:red"))
    ax.text(-0.55, 0.45, f"q_r = {math.degrees(q_r):.0f}°", color="tab:red", fontsize=9)
    # q_b: between blue's heading and the line blue -> red
    back = math.degrees(los + math.pi)
    ax.add_patch(Arc(blue[:2], 0.8, 0.8, theta1=math.degrees(blue[2]), theta2=back, color="tab:blue"))
    ax.text(blue[0] - 1.1, blue[1] + 0.45, f"q_b = {math.degrees(q_b):.0f}°", color="tab:blue", fontsize=9)
    # beta: between the headings (red's heading drawn again at blue)
    ax.annotate("", xy=(blue[0] + ext * math.cos(red[2]), blue[1] + ext * math.sin(red[2])), xytext=blue[:2],
                arrowprops={"arrowstyle": "->", "color": "tab:red", "lw": 1, "ls": ":"})
    ax.add_patch(Arc(blue[:2], 1.3, 1.3, theta1=math.degrees(red[2]), theta2=math.degrees(blue[2]), color="k"))
    ax.text(blue[0] + 0.7, blue[1] + 0.3, f"β = {math.degrees(beta):.0f}°", fontsize=9)
    ax.set_title("Red wins when q_r < 30°, q_b > 30°, β < 40°, d < 0.3 m (eq. 10); blue wins under the mirror",
                 fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlim(-0.6, 3.4)
    ax.set_ylim(-0.8, 1.8)
    ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return Path(path)


# ------------------------------------------------------------------------------------------------------------
# registration
# ------------------------------------------------------------------------------------------------------------
def register() -> None:
    """Register both ids with Gymnasium (a no-op for an id already registered)."""
    if CONTINUOUS_ID not in gym.registry:
        gym.register(id=CONTINUOUS_ID, entry_point=f"{__name__}:RobotConfrontationEnv",
                     max_episode_steps=DEFAULT_HORIZON)
    if DISCRETE_ID not in gym.registry:
        gym.register(id=DISCRETE_ID, entry_point=f"{__name__}:RobotConfrontationDiscreteEnv",
                     max_episode_steps=DEFAULT_HORIZON)


register()
