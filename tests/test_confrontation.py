"""Robot Confrontation Game: dynamics (eq. 9), angles and threat (eq. 11), outcomes (eq. 10), rewards (eq. 12)."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import mo_gymnasium as mo_gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import mope.envs.confrontation as C
from mope.envs import check_env_fits, make_env
from mope.errors import EnvironmentError_, MopeError

DEG = math.pi / 180


def state(x: float, y: float, th_deg: float, v: float) -> np.ndarray:
    return np.array([x, y, th_deg * DEG, v])


# --- eq. 9 ----------------------------------------------------------------------------------------------------
def test_straight_line_at_constant_speed() -> None:
    s = state(0.1, -0.2, 30, 0.4)
    for _ in range(10):
        s = C.unicycle_step(s, 0.0, 0.0, 0.1, v_max=0.5)
    assert s[0] == pytest.approx(0.1 + 0.4 * math.cos(30 * DEG), abs=1e-12)
    assert s[1] == pytest.approx(-0.2 + 0.4 * math.sin(30 * DEG), abs=1e-12)
    assert s[2] == pytest.approx(30 * DEG) and s[3] == pytest.approx(0.4)


def test_turning_circle_has_radius_v_over_w() -> None:
    v, w = 0.4, 0.8
    s = state(0.0, 0.0, 0, v)
    pts = []
    for _ in range(200):
        s = C.unicycle_step(s, 0.0, w, 0.05, v_max=0.5)
        pts.append(s[:2])
    pts = np.array(pts)
    center = np.array([0.0, v / w])  # turning left from the origin heading +x
    assert np.allclose(np.linalg.norm(pts - center, axis=1), v / w, atol=1e-12)
    # a full turn takes 2 pi / w seconds: back at the start
    s = state(0.0, 0.0, 0, v)
    n = 100
    for _ in range(n):
        s = C.unicycle_step(s, 0.0, w, 2 * math.pi / w / n, v_max=0.5)
    assert np.allclose(s[:3], [0, 0, 0], atol=1e-9)


def test_acceleration_and_speed_limits() -> None:
    s = state(0, 0, 0, 0.0)
    s1 = C.unicycle_step(s, 0.2, 0.0, 1.0, v_max=0.5)
    assert s1[3] == pytest.approx(0.2) and s1[0] == pytest.approx(0.1)  # x = a t^2 / 2
    s2 = C.unicycle_step(state(0, 0, 0, 0.45), 0.2, 0.0, 1.0, v_max=0.5)
    assert s2[3] == pytest.approx(0.5)
    s3 = C.unicycle_step(state(0, 0, 0, 0.05), -0.2, 0.0, 1.0, v_max=0.5)
    assert s3[3] == 0.0
    batch = C.unicycle_step(np.zeros((3, 4)), np.array([0.2, 0, -0.2]), np.array([0.0, 0.8, -0.8]), 0.5, 0.5)
    assert batch.shape == (3, 4) and np.allclose(batch[:, 2], [0, 0.4, -0.4])


# --- angles, threat (eq. 10-11) --------------------------------------------------------------------------------
def test_angles_tail_chase() -> None:
    red, blue = state(0, 0, 0, 0.3), state(0.2, 0, 0, 0.3)  # red right behind blue, same heading
    q_r, q_b, beta, d = C.engagement_angles(red, blue)
    assert (q_r, q_b, beta, d) == pytest.approx((0, math.pi, 0, 0.2))
    assert C.angle_threat(q_r, q_b) == pytest.approx(1.0)


def test_angles_head_on_and_crossing() -> None:
    q_r, q_b, beta, d = C.engagement_angles(state(0, 0, 0, 0.3), state(1, 0, 180, 0.3))
    assert (q_r, q_b, beta, d) == pytest.approx((0, 0, math.pi, 1))
    assert C.angle_threat(q_r, q_b) == pytest.approx(0.0)
    # blue at (1, 1) heading +y; red at origin heading +x
    q_r, q_b, beta, d = C.engagement_angles(state(0, 0, 0, 0.3), state(1, 1, 90, 0.3))
    assert q_r == pytest.approx(45 * DEG) and q_b == pytest.approx(135 * DEG) and beta == pytest.approx(90 * DEG)
    assert d == pytest.approx(math.sqrt(2))
    assert C.angle_threat(q_r, q_b) == pytest.approx(0.5)
    # angles are symmetric in the side: the mirror image gives the same values
    mirrored = C.engagement_angles(state(0, 0, 0, 0.3), state(1, -1, -90, 0.3))
    assert np.allclose(mirrored, (q_r, q_b, beta, d))


def test_distance_threat_and_index() -> None:
    assert C.distance_threat(0.0, 0.0, 4.0) == pytest.approx(1.0)
    assert C.distance_threat(4.0, 0.0, 4.0) == pytest.approx(-1.0)
    assert C.distance_threat(1.0, 0.0, 4.0) == pytest.approx(0.5)
    assert C.distance_threat(9.0, 0.0, 4.0) == pytest.approx(-1.0)  # clipped
    assert C.threat_index(1.0, 0.5) == pytest.approx(0.1 + 0.45)


def test_win_conditions_both_sides() -> None:
    red, blue = state(0, 0, 10, 0.3), state(0.25, 0, 0, 0.3)  # red 0.25 m behind blue, pointing at it
    q_r, q_b, beta, d = C.engagement_angles(red, blue)
    assert C.wins(q_r, q_b, beta, d) and not C.wins(q_b, q_r, beta, d)
    assert not C.wins(q_r, q_b, beta, 0.31)  # too far
    q_r, q_b, beta, d = C.engagement_angles(state(0.25, 0, 0, 0.3), state(0, 0, 10, 0.3))  # the mirror
    assert C.wins(q_b, q_r, beta, d) and not C.wins(q_r, q_b, beta, d)
    # head-on: nobody wins (beta = 180)
    q_r, q_b, beta, d = C.engagement_angles(state(0, 0, 0, 0.3), state(0.2, 0, 180, 0.3))
    assert not C.wins(q_r, q_b, beta, d) and not C.wins(q_b, q_r, beta, d)


# --- environment: termination and rewards (eq. 12) -------------------------------------------------------------
def env_at(red: np.ndarray, blue: np.ndarray, **kw: object) -> C.RobotConfrontationEnv:
    env = C.RobotConfrontationEnv(**kw)
    env.reset(seed=0, options={"red": red, "blue": blue})
    return env


def test_red_wins_reward_and_termination() -> None:
    env = env_at(state(0, 0, 0, 0.3), state(0.3, 0, 0, 0.2), blue_safety_time=0)
    _, r, term, trunc, info = env.step([0.0, 0.0])
    assert info["outcome"] == "red_win" and term and not trunc
    assert r.dtype == np.float32 and r[0] == 10.0 and r[1] == pytest.approx(0.3 * env.dt)


def test_blue_wins_reward_and_termination() -> None:
    env = env_at(state(0.3, 0, 0, 0.2), state(0, 0, 0, 0.3))
    _, r, term, _, info = env.step([0.0, 0.0])
    assert info["outcome"] == "blue_win" and term
    assert r[0] == -10.0 and r[1] == pytest.approx(0.2 * env.dt)


def test_red_out_of_arena() -> None:
    env = env_at(state(2.45, 0, 0, 0.5), state(-1, 0, 90, 0.0))
    _, r, term, _, info = env.step([0.2, 0.0])
    assert info["outcome"] == "red_out" and term and r[1] == -10.0
    assert r[0] == pytest.approx((info["T_a"] - 1) / 10 + (info["T_d"] - 1) / 10)


def test_blue_out_of_arena_ends_the_episode() -> None:
    env = env_at(state(-1, 0, 90, 0.0), state(0, 2.45, 90, 0.5), blue_safety_time=0,
                 blue_accels=[0.2], blue_turns=[0.0])
    _, r, term, _, info = env.step([0.0, 0.0])
    assert info["outcome"] == "blue_out" and term and r[1] == 0.0


def test_dense_reward_while_running() -> None:
    env = env_at(state(0, 0, 0, 0.3), state(1.5, 1.0, 90, 0.3))
    _, r, term, _, info = env.step([0.1, 0.4])
    assert not term and info["outcome"] == "running"
    q_r, q_b, _, d = C.engagement_angles(env.red, env.blue)
    t_a, t_d = C.angle_threat(q_r, q_b), C.distance_threat(d, 0.0, 5 * math.sqrt(2))
    assert r[0] == pytest.approx((t_a - 1) / 10 + (t_d - 1) / 10, abs=1e-6)
    assert r[1] == pytest.approx(env.red[3] * env.dt, abs=1e-7) and env.red[3] == pytest.approx(0.32)
    assert env.reward_space.contains(r)


def test_blue_picks_the_action_with_maximum_threat() -> None:
    red, blue = state(0, 0, 0, 0.3), state(1.0, 1.0, 0, 0.3)
    env = env_at(red, blue, blue_safety_time=0)
    cands = env.blue_candidates
    threats = []
    red_next = C.unicycle_step(red, 0, 0, env.dt, env.v_max)
    for a, w in cands:
        q_r, q_b, _, d = C.engagement_angles(red_next, C.unicycle_step(blue, a, w, env.dt, env.v_max))
        threats.append(C.threat_index(C.angle_threat(q_b, q_r), C.distance_threat(d, env.d_min, env.d_max)))
    chosen = env.blue_action()
    assert np.allclose(chosen, cands[int(np.argmax(threats))])
    assert chosen[1] < 0  # red is to blue's lower left: blue turns right (clockwise) towards it
    assert len(cands) == 15 and np.allclose(np.unique(cands[:, 0]), [-0.2, 0, 0.2])


def test_blue_avoids_the_wall() -> None:
    red, blue = state(2.3, 0.0, 90, 0.1), state(1.8, 0.0, 0, 0.5)  # red near the right wall, blue heading there
    greedy = env_at(red, blue, blue_safety_time=0).blue_action()
    careful = env_at(red, blue).blue_action()  # default: drop actions that leave the arena within 1.5 s
    reach = C._arc_points(blue, np.stack([greedy, careful]), 1.5, 0.5)[..., 0].max(axis=1)
    assert reach[0] > 2.5 and reach[1] <= 2.5
    assert np.allclose(greedy, [0.0, 0.4]) and np.allclose(careful, [-0.2, 0.4])


# --- spaces, registration, discretisation, rendering -----------------------------------------------------------
def test_registered_and_fits_mope() -> None:
    assert C.CONTINUOUS_ID in gym.registry and C.DISCRETE_ID in gym.registry
    C.register()  # idempotent
    env = make_env(C.DISCRETE_ID)
    spec = check_env_fits(env)
    assert spec.n_actions == 15 and spec.n_objectives == 2 and spec.max_episode_steps == C.DEFAULT_HORIZON
    with pytest.raises(EnvironmentError_, match="continuous action space"):
        make_env(C.CONTINUOUS_ID)
    cont = mo_gym.make(C.CONTINUOUS_ID)
    assert isinstance(cont.action_space, gym.spaces.Box) and cont.unwrapped.reward_space.shape == (2,)
    obs, _ = cont.reset(seed=3)
    assert obs.shape == (C.OBS_DIM,) and cont.observation_space.contains(obs)


def test_check_env_passes_with_vector_reward() -> None:
    for env_id in (C.CONTINUOUS_ID, C.DISCRETE_ID):
        env = mo_gym.make(env_id, render_mode="rgb_array").unwrapped
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env, skip_render_check=False)
        other = [str(w.message) for w in caught if "reward returned by `step()` must be a float" not in str(w.message)]
        assert other == []


def test_discrete_grid_and_wrapper_agree() -> None:
    grid = C.action_grid(0.2, 0.8, 3, 5)
    assert grid.shape == (15, 2) and np.allclose(grid[7], [0, 0]) and np.allclose(grid[5 * 2 + 4], [0.2, 0.8])
    wrapped = C.DiscreteConfrontation(C.RobotConfrontationEnv(), n_accel=2, n_turn=3)
    built = C.RobotConfrontationDiscreteEnv(n_accel=2, n_turn=3)
    assert wrapped.action_space.n == built.action_space.n == 6
    wrapped.reset(seed=5)
    built.reset(seed=5)
    for a in [0, 5, 3, 1]:
        o1, r1, *_ = wrapped.step(a)
        o2, r2, *_ = built.step(a)
        assert np.array_equal(o1, o2) and np.array_equal(r1, r2)
    with pytest.raises(MopeError, match="out of range"):
        built.step(6)


def test_initial_states_follow_the_documented_distribution() -> None:
    env = C.RobotConfrontationEnv()
    ds = []
    for seed in range(50):
        env.reset(seed=seed)
        assert np.all(np.abs(env.red[:2]) <= 1.5) and np.all(np.abs(env.blue[:2]) <= 1.5)
        assert 0 <= env.red[3] <= 0.25
        ds.append(np.linalg.norm(env.red[:2] - env.blue[:2]))
    assert min(ds) >= 1.0 and max(ds) <= 2.5
    env.reset(seed=7)
    r7 = env.red.copy()
    env.reset(seed=7)
    assert np.array_equal(env.red, r7)


def test_bad_constructor_arguments_name_the_value() -> None:
    with pytest.raises(EnvironmentError_, match="dt=-1"):
        C.RobotConfrontationEnv(dt=-1)
    with pytest.raises(EnvironmentError_, match="blue_turns"):
        C.RobotConfrontationEnv(blue_turns=[2.0])
    with pytest.raises(EnvironmentError_, match="action"):
        C.RobotConfrontationEnv().step([0.1])


def test_render_and_trajectory_plot(tmp_path) -> None:
    env = mo_gym.make(C.DISCRETE_ID, render_mode="rgb_array")
    env.reset(seed=1)
    for a in range(5):
        env.step(a)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape[2] == 3 and frame.std() > 0
    assert len(env.unwrapped.history) == 6
    path = C.plot_trajectory(env.unwrapped.history, tmp_path / "traj.png")
    assert path.stat().st_size > 1000
    assert C.plot_geometry(tmp_path / "geo.png").stat().st_size > 1000


def test_worst_return_bounds_every_return() -> None:
    w = C.worst_return(0.99, 150)
    assert w[1] == -10.0 and -40 < w[0] < -30
    assert C.worst_return(1.0, 10)[0] == pytest.approx(-0.4 * 9 - 10)
    assert np.allclose(C.reference_point(0.99, 150), w - 1)


def test_balance_pursuer_beats_blue_and_blue_beats_random() -> None:
    env = C.RobotConfrontationEnv()
    rng = np.random.default_rng(0)
    outcomes = {"pursuer": [], "random": []}
    for name in outcomes:
        for seed in range(10):
            env.reset(seed=seed)
            for _ in range(C.DEFAULT_HORIZON):
                act = (C.scripted_pursuer(env.red, env.blue, env.half) if name == "pursuer"
                       else rng.uniform([-0.2, -0.8], [0.2, 0.8]))
                *_, term, _, info = env.step(act)
                if term:
                    break
            outcomes[name].append(info["outcome"])
    assert outcomes["pursuer"].count("red_win") >= 3
    assert outcomes["random"].count("blue_win") >= 6


def test_mope_agent_trains_and_evaluates_on_the_discrete_id() -> None:
    from mope.agent.agent import MoPE
    from mope.evaluation.evaluator import Evaluator

    agent = MoPE(C.DISCRETE_ID, seed=0, n_omega=4, learning_starts=16, batch_size=8, total_steps=40, demos="")
    agent.train(40)
    assert agent.global_step == 40 and agent.n_actions == 15 and agent.m == 2
    ev = Evaluator(make_env(C.DISCRETE_ID), C.DISCRETE_ID, 0.99, n_prefs=3, seed=0, max_steps=12,
                   ref_point=C.reference_point(0.99, 12))
    res, sols = ev.evaluate(agent)
    assert sols.returns.shape == (3, 2) and np.all(sols.lengths <= 12)
    assert np.all(sols.discounted >= C.worst_return(0.99, 12) - 1e-6)
    assert res["hv"] > 0


@pytest.mark.slow
def test_a_short_training_beats_random_red() -> None:
    """8k environment steps of the MoPE learner (the game's 4 batched envs, no demonstrations), seeds 0-2: on
    average over the seeds blue wins far less often than against random red (0.86 over these reset seeds), and red's
    discounted catch return is higher than random red's.

    Three seeds, not one: a single seed's outcome depends on the CPU (runs are deterministic on one machine, not
    across machines). With one env and 5k steps (the test before 2026-12-07: 300 s of the suite), seed 0 alone had
    loss share 0.48 on the AMD EPYC development machine and 0.78 on an Intel Xeon one, where seeds 1 and 2 had 0.60
    and 0.52 (2026-12-04). With 4 envs (2026-12-07, AMD EPYC, 55 s a seed): at 8k steps loss shares 0.40 / 0.40 /
    0.22 and catch returns -9.80 / -10.15 / -10.03 (random red -11.01, the bound -10.51); at 5k steps 0.52 / 0.44 /
    0.28 and -10.34 / -10.76 / -10.40, a catch mean 0.01 above the bound, too close to assert.
    """
    from mope.agent.agent import MoPE
    from mope.envs.confrontation_batch import play_reference
    from mope.evaluation.evaluator import Evaluator

    _, disc, outcomes = play_reference("random", list(range(200)))
    random_loss = outcomes.count("blue_win") / len(outcomes)
    assert random_loss >= 0.8
    ev = Evaluator(make_env(C.DISCRETE_ID), C.DISCRETE_ID, 0.99, n_prefs=50, seed=0, max_steps=150,
                   ref_point=C.reference_point(0.99, 150))
    losses, catches = [], []
    for seed in range(3):
        # the learner alone, with the game's 4 envs (its defaults add demonstrations: tests/test_learning_from_
        # demonstrations.py has their short-training test)
        agent = MoPE(C.DISCRETE_ID, seed=seed, total_steps=8000, n_envs=4, buffer_size=20_000, demos="",
                     demo_batch_share=0.0)
        agent.train(8000)
        res, sols = ev.evaluate(agent)
        losses.append(res["loss_share"])
        catches.append(float(sols.discounted[:, 0].mean()))
    assert np.mean(losses) <= random_loss - 0.15, (losses, random_loss)
    assert np.mean(catches) >= disc[:, 0].mean() + 0.5, (catches, disc[:, 0].mean())
