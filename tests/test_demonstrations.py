"""Tests of mope.agent.demonstrations: collecting, merging, saving and loading demonstrations, and their errors."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from mope.agent.demonstrations import (
    KEYS,
    SCRIPTED_POLICIES,
    Demonstrations,
    collect_demonstrations,
    default_demonstrations,
    load_demonstrations,
    outcome_shares,
    save_demonstrations,
    snap_action,
)
from mope.envs import make_env
from mope.errors import DemonstrationError, MopeError

GAME = "mope/RobotConfrontationDiscrete-v0"
DST = "deep-sea-treasure-v0"
# deep-sea-treasure actions: 0 up, 1 down, 2 left, 3 right; from the start (0, 0) "down" ends on the 0.7 treasure
DOWN, LEFT = 1, 2


def always(action: int):
    def policy(obs: np.ndarray, env: gym.Env) -> int:
        return action
    return policy


def random_policy(obs: np.ndarray, env: gym.Env) -> int:
    return int(env.action_space.sample())


def check_episodes(d: Demonstrations) -> None:
    """Structure every collected Demonstrations must have: contiguous episodes, one preference each."""
    for s, e in d.episode_bounds():
        assert d.dones[e - 1] and not d.dones[s:e - 1].any()
        np.testing.assert_array_equal(d.obs[s + 1:e], d.next_obs[s:e - 1])  # s_{t+1} is the next row's s
        assert (d.prefs[s:e] == d.prefs[s]).all()
    np.testing.assert_allclose(d.prefs.sum(1), 1.0, atol=1e-6)
    assert not (d.terminated & ~d.dones).any()


# ------------------------------------------------------------------------------------------------------------
# collection
# ------------------------------------------------------------------------------------------------------------
def test_collect_from_a_named_scripted_policy() -> None:
    env = make_env(GAME)
    d = collect_demonstrations(env, "pursuer", n_episodes=3, seed=5, max_steps=40)
    assert d.n_episodes == 3 and d.obs_shape == (17,) and d.n_objectives == 2
    assert d.actions.dtype == np.int64 and d.rewards.dtype == np.float32 and d.dones.dtype == bool
    assert d.actions.min() >= 0 and d.actions.max() < env.action_space.n
    check_episodes(d)
    assert all(e - s <= 40 for s, e in d.episode_bounds())
    # the registered range of the pursuer: w_catch in [0.5, 1]
    assert ((d.prefs[:, 0] >= 0.5) & (d.prefs[:, 0] <= 1.0)).all()
    assert len(np.unique(d.prefs[:, 0])) == 3
    # episode i starts from reset(seed=seed + i)
    for i, (s, _) in enumerate(d.episode_bounds()):
        np.testing.assert_array_equal(d.obs[s], env.reset(seed=5 + i)[0])
    # the same seed collects the same data
    again = collect_demonstrations(env, "pursuer", n_episodes=3, seed=5, max_steps=40)
    for k in KEYS:
        np.testing.assert_array_equal(getattr(again, k), getattr(d, k))


def test_collect_from_a_callable_on_deep_sea_treasure() -> None:
    env = make_env(DST)
    d = collect_demonstrations(env, always(DOWN), n_episodes=4, seed=0)
    assert len(d) == 4 and d.n_episodes == 4  # one step each: down from the start is the first treasure
    np.testing.assert_allclose(d.rewards, [[0.7, -1.0]] * 4)
    assert d.terminated.all() and d.dones.all()
    assert d.obs.dtype == np.float32 and d.obs_shape == (2,)
    # a callable with no range: uniform on the simplex, a different preference per episode
    check_episodes(d)
    assert len(np.unique(d.prefs[:, 0])) == 4
    d2 = collect_demonstrations(env, always(DOWN), n_episodes=2, pref_range=(0.2, 0.2))
    np.testing.assert_allclose(d2.prefs, [[0.2, 0.8]] * 2)


def test_truncation_by_max_steps_and_by_the_time_limit_is_done_not_terminated() -> None:
    d = collect_demonstrations(make_env(DST), always(LEFT), n_episodes=2, max_steps=3)  # left at x=0: stays put
    assert len(d) == 6
    np.testing.assert_array_equal(d.dones, [False, False, True] * 2)
    assert not d.terminated.any()
    d = collect_demonstrations(make_env(DST, max_episode_steps=4), always(LEFT), n_episodes=1)
    np.testing.assert_array_equal(d.dones, [False, False, False, True])
    assert not d.terminated.any()


def test_default_demonstrations_and_the_registry() -> None:
    offered = dict(default_demonstrations(GAME))
    # circle and evade (pursuit shown from chases) only by name
    assert offered == {"pursuer": (0.45, 1.0), "pursuit": (0.0, 0.35)}
    assert SCRIPTED_POLICIES[GAME]["evade"].starts is not None
    assert set(offered) == {n for n, e in SCRIPTED_POLICIES[GAME].items() if e.default}
    assert "circle" in SCRIPTED_POLICIES[GAME]
    assert default_demonstrations(DST) == []


def test_snap_action_picks_the_nearest_grid_action() -> None:
    game = make_env(GAME).unwrapped  # grid: accel (-0.2, 0, 0.2) major, turn (-0.8, -0.4, 0, 0.4, 0.8)
    for i, (a, w) in enumerate(game.grid):
        assert snap_action(game, a, w) == i
    assert snap_action(game, 0.09, 0.21) == 5 + 3  # accel 0.09 -> 0, turn 0.21 -> 0.4
    assert snap_action(game, 0.11, -0.61) == 10 + 0  # accel 0.11 -> 0.2, turn -0.61 -> -0.8
    assert snap_action(game, -5.0, 5.0) == 4  # beyond the limits: the corner


def test_the_pursuer_wins_far_more_often_than_random_play() -> None:
    env = make_env(GAME)
    pursuer = outcome_shares(env, "pursuer", 50, seed=1000)
    random = outcome_shares(env, random_policy, 50, seed=1000)
    # measured on 200 games: 60.5 % against 2 %
    assert pursuer.get("red_win", 0.0) >= 0.4
    assert pursuer.get("red_win", 0.0) >= random.get("red_win", 0.0) + 0.3
    assert pursuer.get("red_out", 0.0) == 0.0


@pytest.mark.parametrize("name", ["pursuit", "circle"])
def test_the_move_policies_stay_in_the_arena(name: str) -> None:
    shares = outcome_shares(make_env(GAME), name, 15, seed=2000)
    assert shares.get("red_out", 0.0) == 0.0
    assert shares.get("running", 0.0) >= 0.8  # they last until the time limit: long games, r_move every step


def test_concatenate_keeps_episodes_whole() -> None:
    env = make_env(DST)
    a = collect_demonstrations(env, always(DOWN), n_episodes=2)
    b = collect_demonstrations(env, always(LEFT), n_episodes=1, max_steps=3)
    ab = Demonstrations.concatenate([a, b])
    assert len(ab) == 5 and ab.n_episodes == 3
    np.testing.assert_array_equal(ab.episode_bounds(), [[0, 1], [1, 2], [2, 5]])
    np.testing.assert_array_equal(ab.actions, [DOWN, DOWN, LEFT, LEFT, LEFT])
    game = collect_demonstrations(make_env(GAME), "pursuer", n_episodes=1, max_steps=2)
    with pytest.raises(DemonstrationError, match="merge demonstrations of one environment"):
        Demonstrations.concatenate([a, game])
    with pytest.raises(DemonstrationError, match="no demonstrations"):
        Demonstrations.concatenate([])


# ------------------------------------------------------------------------------------------------------------
# files
# ------------------------------------------------------------------------------------------------------------
def test_save_load_round_trip(tmp_path: Path) -> None:
    env = make_env(GAME)
    d = collect_demonstrations(env, "circle", n_episodes=2, seed=3, max_steps=10)
    path = save_demonstrations(tmp_path / "demos", d)
    assert path == tmp_path / "demos.npz" and path.is_file()
    back = load_demonstrations(path, obs_shape=env.observation_space.shape, n_actions=env.action_space.n, m=2)
    for k in KEYS:
        np.testing.assert_array_equal(getattr(back, k), getattr(d, k))
        assert getattr(back, k).dtype == getattr(d, k).dtype
    assert back.n_episodes == 2


def valid_arrays() -> dict[str, np.ndarray]:
    """Two episodes (2 steps, then 1), 2-d observations, 2 objectives, 4 actions."""
    obs = np.arange(6, dtype=np.float32).reshape(3, 2)
    return {"obs": obs, "actions": np.array([0, 3, 1]), "rewards": np.ones((3, 2), np.float32),
            "next_obs": obs + 1, "terminated": np.array([False, True, False]),
            "dones": np.array([False, True, True]), "prefs": np.array([[0.3, 0.7]] * 2 + [[1.0, 0.0]], np.float32)}


def with_(**changes: object) -> dict[str, object]:
    arrays: dict[str, object] = valid_arrays()
    arrays.update(changes)
    return {k: v for k, v in arrays.items() if v is not None}


BAD_ARRAYS = {
    "missing key": (with_(prefs=None), "lacks prefs"),
    "wrong length": (with_(rewards=np.ones((2, 2))), "'rewards' has shape (2, 2), expected (3, 2)"),
    "obs rows": (with_(obs=np.zeros((4, 2))), "'obs' has shape (4, 2)"),
    "next_obs shape": (with_(next_obs=np.zeros((3, 3))), "'next_obs' has shape (3, 3)"),
    "actions not 1-d": (with_(actions=np.zeros((3, 1), np.int64)), "must be (T,)"),
    "negative action": (with_(actions=np.array([0, -1, 1])), "action -1 is out of range"),
    "fractional action": (with_(actions=np.array([0.0, 1.5, 1.0])), "action 1.5 is not an integer"),
    "nan reward": (with_(rewards=np.array([[1, 1], [np.nan, 1], [1, 1]], np.float32)),
                   "'rewards' has a non-finite value at transition 1"),
    "inf obs": (with_(next_obs=np.array([[0, 0], [0, np.inf], [0, 0]], np.float32)), "'next_obs' has a non-finite"),
    "negative pref": (with_(prefs=np.array([[1.2, -0.2]] * 2 + [[1, 0]], np.float32)), "negative weight"),
    "nan pref": (with_(prefs=np.array([[np.nan, 1.0]] * 2 + [[1, 0]], np.float32)), "'prefs' has a non-finite"),
    "pref length": (with_(prefs=np.full((3, 3), 1 / 3, np.float32)), "'prefs' has shape (3, 3), expected (3, 2)"),
    "pref sum": (with_(prefs=np.array([[0.5, 0.6]] * 2 + [[1, 0]], np.float32)), "sums to 1.1"),
    "pref inside episode": (with_(prefs=np.array([[0.3, 0.7], [0.4, 0.6], [1, 0]], np.float32)),
                            "changes inside an episode at transition 1"),
    "no final done": (with_(dones=np.array([False, True, False])), "has no final done"),
    "terminated not done": (with_(terminated=np.array([True, False, False])), "terminated but not done"),
    "dones not boolean": (with_(dones=np.array([0, 2, 1])), "'dones' must hold booleans"),
    "empty": ({k: v[:0] for k, v in valid_arrays().items()}, "hold no transitions"),
}


@pytest.mark.parametrize("case", list(BAD_ARRAYS))
def test_bad_files_give_one_line_errors(tmp_path: Path, case: str) -> None:
    arrays, expected = BAD_ARRAYS[case]
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(DemonstrationError) as err:
        load_demonstrations(path)
    msg = str(err.value)
    assert expected in msg and "\n" not in msg and str(path) in msg
    assert isinstance(err.value, MopeError)
    if "prefs" in arrays and "missing" not in case:  # the same check guards the constructor
        with pytest.raises(DemonstrationError, match="demonstration"):
            Demonstrations(**arrays)  # type: ignore[arg-type]


def test_the_valid_arrays_load(tmp_path: Path) -> None:
    np.savez(tmp_path / "ok.npz", **valid_arrays())
    d = load_demonstrations(tmp_path / "ok.npz", obs_shape=(2,), n_actions=4, m=2)
    assert len(d) == 3 and d.n_episodes == 2


@pytest.mark.parametrize(("kwargs", "expected"), [
    ({"obs_shape": (17,)}, "observations have shape (2,) but the environment's are (17,)"),
    ({"n_actions": 3}, "action 3 is out of range: the environment has actions 0..2"),
    ({"m": 3}, "have 2 objectives but the environment has 3"),
])
def test_demonstrations_that_do_not_fit_the_env(tmp_path: Path, kwargs: dict, expected: str) -> None:
    np.savez(tmp_path / "ok.npz", **valid_arrays())
    with pytest.raises(DemonstrationError) as err:
        load_demonstrations(tmp_path / "ok.npz", **kwargs)
    assert expected in str(err.value) and "\n" not in str(err.value)


def test_unreadable_files(tmp_path: Path) -> None:
    cases = {}
    cases["missing"] = (tmp_path / "nothing.npz", "does not exist")
    text = tmp_path / "text.npz"
    text.write_text("obs,actions\n1,2\n")
    cases["text"] = (text, "is not an .npz archive")
    single = tmp_path / "single.npy"
    np.save(single, np.zeros(3))
    cases["npy"] = (single, "is a single array, not an .npz archive")
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, **with_(obs=np.array([object()] * 3, dtype=object)))
    cases["pickle"] = (pickled, "cannot be read")
    for name, (path, expected) in cases.items():
        with pytest.raises(DemonstrationError) as err:
            load_demonstrations(path)
        assert expected in str(err.value) and "\n" not in str(err.value), name


# ------------------------------------------------------------------------------------------------------------
# bad collection arguments
# ------------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(("env_id", "policy", "kwargs", "expected"), [
    (GAME, "pursuier", {}, "unknown scripted policy 'pursuier' for 'mope/RobotConfrontationDiscrete-v0' (did you "
                           "mean 'pursuer'?)"),
    (DST, "pursuer", {}, "no scripted policy is registered for 'deep-sea-treasure-v0'"),
    (DST, always(DOWN), {"n_episodes": 0}, "n_episodes=0 is out of range"),
    (DST, always(DOWN), {"max_steps": 0}, "max_steps=0 is out of range"),
    (DST, always(DOWN), {"roll_in": -1}, "roll_in=-1 is out of range"),
    (DST, always(DOWN), {"roll_in": 100_000, "max_steps": 1}, "ended during its random roll-in"),
    (DST, always(DOWN), {"pref_range": (0.6, 0.2)}, "need 0 <= lo <= hi <= 1"),
    (DST, always(DOWN), {"pref_range": (0.0, 1.5)}, "need 0 <= lo <= hi <= 1"),
    (DST, always(4), {}, "returned action 4, out of range: choose 0..3"),
    (DST, always(1.0), {}, "it must return one integer action"),
    (DST, 3, {}, "neither a callable"),
    (DST, always(DOWN), {"starts": lambda rng, env: [1, 2]}, "starts returned list, not a dict of reset options"),
])
def test_bad_collection_arguments(env_id: str, policy: object, kwargs: dict, expected: str) -> None:
    args = {"n_episodes": 1, **kwargs}
    with pytest.raises(DemonstrationError) as err:
        collect_demonstrations(make_env(env_id), policy, **args)  # type: ignore[arg-type]
    assert expected in str(err.value) and "\n" not in str(err.value)


# ------------------------------------------------------------------------------------------------------------
# random roll-in
# ------------------------------------------------------------------------------------------------------------
def test_roll_in_starts_the_demonstrator_from_other_states() -> None:
    env = make_env(GAME)
    plain = collect_demonstrations(env, "pursuer", 6, seed=5)
    same = collect_demonstrations(env, "pursuer", 6, seed=5, roll_in=0)
    for key in ("obs", "actions", "rewards", "prefs", "dones"):  # roll_in=0 is today's stream, bit for bit
        np.testing.assert_array_equal(getattr(plain, key), getattr(same, key))
    rolled = collect_demonstrations(env, "pursuer", 6, seed=5, roll_in=30)
    starts = [make_env(GAME).reset(seed=5 + i)[0] for i in range(6)]
    first = rolled.obs[np.r_[0, np.flatnonzero(rolled.dones[:-1]) + 1]]
    # most episodes start where random play left them, not at their reset state
    moved = sum(not any(np.allclose(f, s) for s in starts) for f in first)
    assert moved >= 4, moved
    again = collect_demonstrations(env, "pursuer", 6, seed=5, roll_in=30)  # reproducible
    np.testing.assert_array_equal(rolled.obs, again.obs)


def test_config_roll_in_must_be_non_negative() -> None:
    from mope.config import Config
    from mope.errors import ConfigError

    with pytest.raises(ConfigError, match="demo_roll_in"):
        Config(demo_roll_in=-3)
    assert Config(demo_roll_in=20).demo_roll_in == 20


# ------------------------------------------------------------------------------------------------------------
# scenarios: demonstrations from chosen starts
# ------------------------------------------------------------------------------------------------------------
def test_chase_starts_put_blue_on_reds_tail() -> None:
    from mope.agent.demonstrations import chase_starts
    from mope.envs.confrontation import engagement_angles

    env = make_env(GAME)
    rng = np.random.default_rng(0)
    for _ in range(50):
        opts = chase_starts(rng, env)
        env.reset(seed=0, options=opts)
        game = env.unwrapped
        q_r, q_b, _, d = engagement_angles(game.red, game.blue)
        assert q_r > np.pi - 0.5 - 1e-9 and q_b < 0.3 + 1e-9 and 0.5 <= d <= 1.5  # behind red, heading at it
        assert np.abs(game.red[:2]).max() <= game.half - 1.0 and np.abs(game.blue[:2]).max() < game.half - 0.3


def test_a_scenario_policy_starts_every_episode_from_its_scenario() -> None:
    from mope.agent.demonstrations import chase_starts, pursuit_policy

    env = make_env(GAME)
    named = collect_demonstrations(env, "evade", 4, seed=7)
    # the same as pursuit with the scenario given by hand, drawn from default_rng(seed + 2)
    by_hand = collect_demonstrations(env, pursuit_policy, 4, pref_range=(0.0, 0.55), seed=7, starts=chase_starts)
    for key in ("obs", "actions", "rewards", "prefs"):
        np.testing.assert_array_equal(getattr(named, key), getattr(by_hand, key))
    rng = np.random.default_rng(9)
    first = named.obs[0]
    np.testing.assert_array_equal(first, make_env(GAME).reset(seed=7, options=chase_starts(rng, env))[0])
    plain = collect_demonstrations(env, "pursuit", 4, seed=7)  # no scenario: the env's own resets
    np.testing.assert_array_equal(plain.obs[0], make_env(GAME).reset(seed=7)[0])
    assert named.prefs[:, 0].max() <= 0.55


def test_pursuit_from_chases_stays_in_the_arena_where_driving_on_leaves() -> None:
    from mope.agent.demonstrations import chase_starts, straight_on_policy

    env = make_env(GAME)

    def out_share(policy) -> float:
        d = collect_demonstrations(env, policy, 20, pref_range=(0.5, 0.5), starts=chase_starts)
        return float(np.mean([d.rewards[e - 1, 1] <= -10 for _, e in d.episode_bounds()]))

    assert out_share("pursuit") <= 0.05 and out_share(straight_on_policy) >= 0.9
