"""Tests of mope.evaluation.evaluator and the batched Deep-Sea-Treasure: exact dynamics, and the metrics of known
policies."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import mope.evaluation.evaluator as evaluation
from mope.envs import make_batched, make_env
from mope.envs.batched import DeepSeaTreasureBatch, EnvList
from mope.evaluation.evaluator import Evaluator, solutions
from mope.preferences import sample_simplex

# Deep-Sea-Treasure convex map: (row, col) of each treasure, in the order of pareto_front().
TREASURE_CELLS = np.array([(1, 0), (2, 1), (3, 2), (4, 3), (4, 4), (4, 5), (7, 6), (7, 7), (9, 8), (10, 9)])
TREASURE_VALUES = np.array([0.7, 8.2, 11.5, 14.0, 15.1, 16.1, 19.6, 20.3, 22.4, 23.7])
# the shortest path (right along row 0, then down) takes row + col steps: 1, 3, 5, 7, 8, 9, 13, 14, 17, 19
FRONT = np.stack([TREASURE_VALUES, -(TREASURE_CELLS.sum(axis=1))], axis=1)

DST_IDS = ["deep-sea-treasure-v0", "deep-sea-treasure-concave-v0", "deep-sea-treasure-mirrored-v0"]

# gymnasium warns about float64 bounds each time a DST copy is made; it is noise here
pytestmark = pytest.mark.filterwarnings("ignore:.*precision lowered by casting:UserWarning")


def make(env_id: str, **kwargs: object):  # noqa: ANN201 - a gymnasium env
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return make_env(env_id, **kwargs)


@pytest.fixture(scope="module")
def dst():  # noqa: ANN201
    return make("deep-sea-treasure-v0")


class Oracle:
    """For each preference, sail the shortest path to the treasure of highest discounted utility w . v."""

    def __init__(self, env, gamma: float = 0.99) -> None:  # noqa: ANN001
        self.front = np.asarray(env.unwrapped.pareto_front(gamma), dtype=np.float64)
        assert len(self.front) == len(TREASURE_CELLS)

    def targets(self, prefs: np.ndarray) -> np.ndarray:
        return np.argmax(prefs @ self.front.T, axis=1)

    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        cell = TREASURE_CELLS[self.targets(prefs)]
        return np.where(obs[:, 1] < cell[:, 1], 3, 1)  # right until the column matches, then down


class Constant:
    def __init__(self, action: int) -> None:
        self.action = action

    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        return np.full(len(obs), self.action, dtype=np.int64)


class Scripted:
    """A fixed, deterministic but state- and preference-dependent policy (for comparing batch implementations)."""

    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.int64)
        k = (3 * obs[:, 0] + 5 * obs[:, 1] + (prefs[:, 0] * 7).astype(np.int64)) % 7
        return np.array([1, 3, 1, 0, 2, 3, 1])[k]


# ------------------------------------------------------------------------------------------- batched DST
def test_front_points_follow_from_the_map(dst) -> None:  # noqa: ANN001
    sea = np.asarray(dst.unwrapped.sea_map)
    np.testing.assert_array_equal(sea[TREASURE_CELLS[:, 0], TREASURE_CELLS[:, 1]], TREASURE_VALUES)
    np.testing.assert_allclose(np.asarray(dst.unwrapped.pareto_front(1.0)), FRONT)


def test_make_batched_picks_the_fast_path(dst) -> None:  # noqa: ANN001
    assert isinstance(make_batched(dst, 3), DeepSeaTreasureBatch)
    assert DeepSeaTreasureBatch.supports(dst)


@pytest.mark.parametrize(
    ("env_id", "kwargs"), [(i, {}) for i in DST_IDS] + [("deep-sea-treasure-v0", {"float_state": True})]
)
def test_batched_dst_matches_mo_gymnasium_step_by_step(env_id: str, kwargs: dict) -> None:
    env = make(env_id, **kwargs)
    n = 64
    refs = [make(env_id, **kwargs).unwrapped for _ in range(n)]
    batch = DeepSeaTreasureBatch(env, n)
    rng = np.random.default_rng(0)
    n_terminated = 0
    for episode in range(3):
        obs = batch.reset()
        ref_obs = np.stack([r.reset(seed=episode)[0] for r in refs])
        np.testing.assert_array_equal(obs, ref_obs)
        assert obs.dtype == ref_obs.dtype
        running = np.arange(n)
        for _ in range(60):
            # bias towards down/right so that many episodes reach a treasure; all four moves occur
            actions = rng.choice(4, size=running.size, p=[0.15, 0.35, 0.15, 0.35])
            b_obs, b_rew, b_term = batch.step(running, actions)
            for j, (i, a) in enumerate(zip(running, actions, strict=True)):
                r_obs, r_rew, r_term, r_trunc, _ = refs[i].step(int(a))
                np.testing.assert_array_equal(b_obs[j], r_obs)
                np.testing.assert_array_equal(b_rew[j], np.asarray(r_rew, dtype=np.float64))
                assert bool(b_term[j]) == bool(r_term)
                assert not r_trunc
            n_terminated += int(b_term.sum())
            running = running[~b_term]
            if running.size == 0:
                break
    assert n_terminated >= 50  # the comparison covered many treasure hits, not only wandering


def walk(b: DeepSeaTreasureBatch, copy: int, actions: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    out = None
    for a in actions:
        out = b.step(np.array([copy]), np.array([a]))
    assert out is not None
    return out


def test_batched_dst_moves_edges_rocks_and_treasures(dst) -> None:  # noqa: ANN001
    b = DeepSeaTreasureBatch(dst, 4)
    np.testing.assert_array_equal(b.reset(), [[0, 0]] * 4)
    # from (0, 0): up and left hit the map edge and stay; right moves; down lands on the 0.7 treasure
    obs, rew, term = b.step(np.arange(4), np.array([0, 2, 3, 1]))
    np.testing.assert_array_equal(obs, [[0, 0], [0, 0], [0, 1], [1, 0]])
    np.testing.assert_allclose(rew, [[0, -1], [0, -1], [0, -1], [0.7, -1]], atol=1e-6)
    assert term.tolist() == [False, False, False, True]
    # copy 2 from (0, 1): down twice reaches 8.2 at (2, 1)
    obs, rew, term = walk(b, 2, [1, 1])
    np.testing.assert_array_equal(obs, [[2, 1]])
    np.testing.assert_allclose(rew, [[8.2, -1]], atol=1e-6)
    assert term.tolist() == [True]
    # copy 0: to (5, 6), then left into the rock at (5, 5): it stays, no reward, not terminal
    obs, rew, term = walk(b, 0, [3] * 6 + [1] * 5)
    np.testing.assert_array_equal(obs, [[5, 6]])
    assert not term[0]
    obs, rew, term = walk(b, 0, [2])
    np.testing.assert_array_equal(obs, [[5, 6]])
    assert rew.tolist() == [[0.0, -1.0]] and term.tolist() == [False]
    # copy 1: to the right edge (0, 10), one more right stays; to the bottom (10, 10), one more down stays
    obs, _, _ = walk(b, 1, [3] * 11)
    np.testing.assert_array_equal(obs, [[0, 10]])
    obs, _, term = walk(b, 1, [1] * 11)
    np.testing.assert_array_equal(obs, [[10, 10]])
    assert not term[0]
    # then left onto 23.7 at (10, 9)
    obs, rew, term = walk(b, 1, [2])
    np.testing.assert_array_equal(obs, [[10, 9]])
    np.testing.assert_allclose(rew, [[23.7, -1]], atol=1e-5)
    assert term.tolist() == [True]
    # the copies moved independently: copy 3 was never stepped again
    np.testing.assert_array_equal(b.pos[3], [1, 0])


def test_envlist_steps_like_the_batched_dst(dst) -> None:  # noqa: ANN001
    n = 16
    fast = DeepSeaTreasureBatch(dst, n)
    slow = EnvList(dst, n)
    np.testing.assert_array_equal(fast.reset(), slow.reset())
    rng = np.random.default_rng(1)
    running = np.arange(n)
    for _ in range(40):
        a = rng.integers(0, 4, running.size)
        f, s = fast.step(running, a), slow.step(running, a)
        for x, y in zip(f, s, strict=True):
            np.testing.assert_array_equal(x, y)
        running = running[~f[2]]
        if running.size == 0:
            break


@pytest.mark.parametrize("policy", [Scripted(), Constant(1), Constant(3)])
def test_envlist_gives_the_same_solutions(dst, monkeypatch: pytest.MonkeyPatch, policy) -> None:  # noqa: ANN001
    prefs = np.stack([np.linspace(0, 1, 21), 1 - np.linspace(0, 1, 21)], axis=1)
    fast = solutions(policy, dst, prefs, 0.99, close_loops=False)  # step for step, bit for bit
    closed = solutions(policy, dst, prefs, 0.99)  # loops closed in closed form: equal up to rounding
    monkeypatch.setattr(evaluation, "make_batched", lambda env, n, seed=0: EnvList(env, n, seed))
    slow = solutions(policy, dst, prefs, 0.99)
    for field in ("prefs", "returns", "discounted", "lengths", "terminated"):
        np.testing.assert_array_equal(getattr(fast, field), getattr(slow, field))
        np.testing.assert_allclose(getattr(closed, field), getattr(slow, field), rtol=0, atol=1e-9)


# ------------------------------------------------------------------------------------------- solutions()
def test_solutions_of_the_oracle_are_the_front_points(dst) -> None:  # noqa: ANN001
    oracle = Oracle(dst)
    prefs = sample_simplex(300, 2, np.random.default_rng(0))
    sols = solutions(oracle, dst, prefs, 0.99)
    target = oracle.targets(prefs)
    # undiscounted returns are (treasure, -steps) of the chosen treasure
    np.testing.assert_allclose(sols.returns, FRONT[target], atol=1e-5)
    np.testing.assert_array_equal(sols.lengths, TREASURE_CELLS[target].sum(axis=1))
    assert sols.terminated.all()
    # discounted returns are the discounted front points
    np.testing.assert_allclose(sols.discounted, oracle.front[target], atol=1e-4)
    assert len(np.unique(target)) == 10


def test_solutions_hand_case_single_preferences(dst) -> None:  # noqa: ANN001
    # w = (1, 0): all weight on treasure -> 23.7 after 19 steps; w = (0, 1): all on time -> 0.7 after 1 step
    sols = solutions(Oracle(dst), dst, np.array([[1.0, 0.0], [0.0, 1.0]]), gamma=0.5)
    np.testing.assert_allclose(sols.returns, [[23.7, -19.0], [0.7, -1.0]], atol=1e-5)
    assert sols.lengths.tolist() == [19, 1]
    # discounted with gamma 0.5: treasure * 0.5^18 and -(1 - 0.5^19) / (1 - 0.5)
    np.testing.assert_allclose(sols.discounted[0], [23.7 * 0.5**18, -(1 - 0.5**19) / 0.5], rtol=1e-6)
    np.testing.assert_allclose(sols.discounted[1], [0.7, -1.0], rtol=1e-6)


def test_solutions_time_limit(dst) -> None:  # noqa: ANN001
    sols = solutions(Constant(0), dst, np.array([[0.5, 0.5]]), 0.99, max_steps=7)
    assert sols.lengths.tolist() == [7]
    assert sols.terminated.tolist() == [False]
    np.testing.assert_allclose(sols.returns, [[0.0, -7.0]])
    # default limit: the registered one (100)
    sols = solutions(Constant(0), dst, np.array([[0.5, 0.5]]), 0.99)
    assert sols.lengths.tolist() == [100]


def test_solutions_leaves_the_callers_env_alone() -> None:
    env = make("deep-sea-treasure-v0")
    env.reset(seed=0)
    env.step(3)
    env.step(3)  # at (0, 2), mid-episode
    solutions(Constant(1), env, np.array([[0.5, 0.5]]), 0.99)
    np.testing.assert_array_equal(env.unwrapped.current_state, [0, 2])


def test_solutions_validates_preferences(dst) -> None:  # noqa: ANN001
    from mope.errors import PreferenceError

    with pytest.raises(PreferenceError):
        solutions(Constant(1), dst, np.array([[0.5, 0.6]]), 0.99)
    with pytest.raises(PreferenceError):
        solutions(Constant(1), dst, np.array([[0.2, 0.3, 0.5]]), 0.99)


def test_solutions_calls_policy_only_on_running_episodes(dst) -> None:  # noqa: ANN001
    seen: list[int] = []

    class Recorder(Oracle):
        def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
            seen.append(len(obs))
            return super().greedy_actions(obs, prefs)

    # targets: 0.7 (1 step), 8.2 (3 steps), 23.7 (19 steps)
    prefs = np.array([[0.0, 1.0], [0.35, 0.65], [1.0, 0.0]])
    oracle = Recorder(dst)
    assert oracle.targets(prefs).tolist() == [0, 1, 9]
    sols = solutions(oracle, dst, prefs, 0.99)
    assert sols.lengths.tolist() == [1, 3, 19]
    assert seen == [3, 2, 2] + [1] * 16


# ------------------------------------------------------------------------------------------- Evaluator
@pytest.fixture(scope="module")
def evaluator(dst) -> Evaluator:  # noqa: ANN001
    return Evaluator(dst, "deep-sea-treasure-v0", n_prefs=2000)


def test_evaluator_protocol(evaluator: Evaluator) -> None:
    assert evaluator.prefs.shape == (2000, 2)
    assert evaluator.eum_prefs.shape == (100, 2)
    assert evaluator.max_steps == 100
    assert evaluator.gamma == 0.99
    np.testing.assert_array_equal(evaluator.ref_point, [0.0, -25.0])
    assert evaluator.front.shape == (10, 2)
    # a fixed preference set: a second evaluator draws the same one
    other = Evaluator(evaluator.env, "deep-sea-treasure-v0", n_prefs=2000)
    np.testing.assert_array_equal(other.prefs, evaluator.prefs)


def test_oracle_is_perfect(evaluator: Evaluator, dst) -> None:  # noqa: ANN001
    res, sols = evaluator.evaluate(Oracle(dst))
    assert res["cr"] == 1.0
    assert res["precision"] == 1.0 and res["recall"] == 1.0
    assert res["optimal_share"] == 1.0
    assert abs(res["eum_gap"]) < 1e-3
    assert res["timeout_share"] == 0.0
    assert res["cardinality"] == 10
    # solutions: undiscounted returns are the front points, time = -steps
    assert sols.returns.shape == (2000, 2)
    returned = {tuple(np.round(r, 4)) for r in sols.returns}
    assert returned == {tuple(np.round(r, 4)) for r in FRONT}
    np.testing.assert_array_equal(-sols.returns[:, 1], sols.lengths)
    np.testing.assert_allclose(sols.returns, FRONT[Oracle(dst).targets(sols.prefs)], atol=1e-5)


def test_always_up_times_out_everywhere(evaluator: Evaluator) -> None:
    res, sols = evaluator.evaluate(Constant(0))
    assert res["timeout_share"] == 1.0
    assert not sols.terminated.any()
    np.testing.assert_array_equal(sols.returns[:, 1], -evaluator.max_steps)
    np.testing.assert_array_equal(sols.returns[:, 1], -100.0)
    np.testing.assert_array_equal(sols.returns[:, 0], 0.0)
    assert res["cr"] == 0.0 and res["recall"] == 0.0
    assert res["optimal_share"] == 0.0
    assert res["eum_gap"] > 0


def test_always_nearest_treasure(evaluator: Evaluator) -> None:
    # always down: the 0.7 treasure after one step, whatever the preference
    res, sols = evaluator.evaluate(Constant(1))
    np.testing.assert_allclose(sols.returns, np.tile([0.7, -1.0], (2000, 1)), atol=1e-6)
    assert res["precision"] == 1.0
    assert res["recall"] == pytest.approx(0.1)
    assert res["cr"] == pytest.approx(2 * (1 * 0.1) / (1 + 0.1))
    assert res["cardinality"] == 1
    assert res["timeout_share"] == 0.0
    # the share of preferences for which 0.7 is the best treasure: those with w_time / w_treasure > ~3.8
    share = float(np.mean(Oracle(evaluator.env).targets(evaluator.prefs) == 0))
    assert res["optimal_share"] == pytest.approx(share)


class _Recorder:
    """A fixed-action policy that records the observations it is shown."""

    def __init__(self, action: int) -> None:
        self.action = action
        self.seen: list[np.ndarray] = []

    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        self.seen.append(np.asarray(obs).copy())
        return np.full(len(obs), self.action)


def test_rollouts_keep_observation_wrappers():
    import gymnasium as gym

    env = gym.wrappers.TransformObservation(make_env("deep-sea-treasure-v0"), lambda o: o * 10.0 + 5.0,
                                            make_env("deep-sea-treasure-v0").observation_space)
    assert not DeepSeaTreasureBatch.supports(env) and DeepSeaTreasureBatch.supports(make_env("deep-sea-treasure-v0"))
    policy = _Recorder(action=1)  # down: treasure 0.7 after one step
    sols = solutions(policy, env, np.array([[0.5, 0.5]]), gamma=0.99, max_steps=5)
    assert np.all(policy.seen[0] >= 5.0), "the policy must see the wrapped observation"
    np.testing.assert_allclose(sols.returns[0], [0.7, -1.0])


def test_rollouts_keep_action_wrappers_of_continuous_envs():
    from mope.envs import DiscreteActions

    env = DiscreteActions(_continuous_env(), bins=3)
    sols = solutions(_Recorder(action=2), env, np.array([[0.5, 0.5], [0.2, 0.8]]), gamma=0.99, max_steps=20)
    assert sols.returns.shape == (2, env.unwrapped.reward_space.shape[0])
    assert np.all(np.isfinite(sols.returns)) and np.all(sols.lengths == 20)


def _continuous_env():
    import mo_gymnasium as mo_gym

    return mo_gym.make("mo-mountaincarcontinuous-v0")


class _ObsPolicy:
    """A deterministic greedy stand-in: the action is a fixed function of (observation, preference)."""

    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        row, col = np.round(np.asarray(obs, dtype=np.float64) * 10).astype(int).T
        down = (prefs[:, 0] > 0.5) | (col % 2 == 1)  # treasure-minded rows dive; others bounce between columns
        return np.where(down & (row < 3), 1, np.where(col % 2 == 0, 3, 2))


def test_closing_loops_is_exact_and_stops_early():
    env = make_env("deep-sea-treasure-v0")
    prefs = sample_simplex(300, 2, np.random.default_rng(0))
    stepped = solutions(_ObsPolicy(), env, prefs, gamma=0.99, max_steps=100, close_loops=False)
    closed = solutions(_ObsPolicy(), env, prefs, gamma=0.99, max_steps=100)
    assert (~stepped.terminated).any() and stepped.terminated.any(), "the test needs loops and endings"
    np.testing.assert_array_equal(closed.lengths, stepped.lengths)
    np.testing.assert_array_equal(closed.terminated, stepped.terminated)
    np.testing.assert_allclose(closed.returns, stepped.returns, rtol=0, atol=1e-9)
    np.testing.assert_allclose(closed.discounted, stepped.discounted, rtol=0, atol=1e-9)

    calls = []

    class Counting(_ObsPolicy):
        def greedy_actions(self, obs, prefs):
            calls.append(len(obs))
            return super().greedy_actions(obs, prefs)

    solutions(Counting(), env, prefs, gamma=0.99, max_steps=100)
    assert len(calls) < 20, "loops must be closed as soon as a state repeats, not stepped to the time limit"
