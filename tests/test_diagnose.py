"""The ground-truth diagnostic (mope.evaluation.diagnose): exact values on hand-made models, DST against its known
front, the seabed variant, and the diagnostic's numbers for hand-made agents."""

from __future__ import annotations

import mo_gymnasium as mo_gym
import numpy as np
import pytest

import mope  # noqa: F401 - registers mope's environments
from mope.errors import EnvironmentError_
from mope.evaluation.diagnose import TabularModel, diagnose, diagnose_q, tabular_model, value_iteration

STAY, SMALL_T, GO = 0, 1, 2
PREFS = np.array([[0.0, 1.0], [0.5, 0.5], [1.0, 0.0]])


def chain() -> TabularModel:
    """State 0 (start) and 1. Actions: stay (0, -1); take the small treasure (1, -1), terminal; go: from 0 to 1
    with (0, -1), from 1 take the big treasure (10, -1), terminal."""
    next_state = np.array([[0, 0, 1], [1, 1, 1]])
    reward = np.array([[[0, -1], [1, -1], [0, -1]], [[0, -1], [1, -1], [10, -1]]], dtype=float)
    terminal = np.array([[False, True, False], [False, True, True]])
    return TabularModel(np.array([[0], [1]]), next_state, reward, terminal, 0, np.array([True, True]))


def test_value_iteration_hand_values() -> None:
    truth = value_iteration(chain(), PREFS, gamma=0.5)
    w1, w2 = PREFS[:, 0], PREFS[:, 1]
    v1 = 10 * w1 - w2  # at state 1 the big treasure is best for every preference here
    np.testing.assert_allclose(truth.v[:, 1], v1)
    np.testing.assert_allclose(truth.q[:, 0, SMALL_T], w1 - w2)
    np.testing.assert_allclose(truth.q[:, 0, GO], -w2 + 0.5 * v1)  # = 5 w1 - 1.5 w2
    np.testing.assert_allclose(truth.v[:, 0], [-1.0, 1.75, 5.0])  # small for (0, 1); go for the others
    # vector returns of acting optimally after each action
    np.testing.assert_allclose(truth.q_vec[1, 0, GO], [5.0, -1.5])
    np.testing.assert_allclose(truth.q_vec[0, 0, SMALL_T], [1.0, -1.0])
    np.testing.assert_allclose(truth.q_vec[0, 0, STAY], [0.5, -1.5])  # stay once, then the small treasure


class FixedQ:
    """An agent whose vector Q-values are a table: always 'go' (and the big treasure), every other action -100."""

    def q_values(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        q = np.full((len(obs), 3, 2), -100.0)
        at0 = obs[:, 0] == 0
        q[at0, GO] = [5.0, -1.5]
        q[~at0, GO] = [10.0, -1.0]
        return q


def test_diagnostic_hand_values() -> None:
    model = chain()
    truth = value_iteration(model, PREFS, gamma=0.5)
    from mope.evaluation.diagnose import agent_q

    d = diagnose_q(agent_q(FixedQ(), model, PREFS), model, truth)
    # on-path pairs: w=(0,1) -> {0} (the small treasure ends it), wrong; the others -> {0, 1}, right
    assert d["path_error"] == pytest.approx(1 / 5)
    assert d["state_error"] == pytest.approx(1 / 6)  # every reachable state: (w=(0,1), s=0) is the one error
    assert d["path_failed_share"] == pytest.approx(1 / 3) and d["first_error_step"] == 0.0
    # max_a w^T Q(s0) - V*(s0): (0,1): -1.5 - (-1) = -0.5; (.5,.5): 1.75 - 1.75; (1,0): 5 - 5
    assert d["overestimation_mean"] == pytest.approx(-0.5 / 3) and d["overestimation_max"] == pytest.approx(0.0)


class Exact:
    def __init__(self, truth: object, model: TabularModel) -> None:
        self.truth, self.model = truth, model

    def q_values(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        s = self._state(obs)
        i = np.array([np.flatnonzero(np.all(self.truth.prefs == p, axis=1))[0] for p in prefs])
        return self.truth.q_vec[i, s]

    def _state(self, obs: np.ndarray) -> np.ndarray:
        flat = self.model.obs.reshape(len(self.model.obs), -1)
        return np.array([np.flatnonzero(np.all(flat == o, axis=1))[0] for o in obs.reshape(len(obs), -1)])


@pytest.mark.parametrize("env_id", ["deep-sea-treasure-v0", "deep-sea-treasure-concave-v0",
                                    "deep-sea-treasure-mirrored-v0", "mope/deep-sea-treasure-seabed-v0"])
def test_dst_values_match_the_known_front_and_the_exact_agent_scores_zero(env_id: str) -> None:
    env = mo_gym.make(env_id)
    model = tabular_model(env)
    w = np.stack([np.linspace(0, 1, 21), 1 - np.linspace(0, 1, 21)], axis=1)
    truth = value_iteration(model, w, gamma=0.99)
    front = np.asarray(env.unwrapped.pareto_front(gamma=0.99))
    np.testing.assert_allclose(truth.v[:, model.start], (w @ front.T).max(axis=1), atol=1e-9)
    d = diagnose(Exact(truth, model), env, gamma=0.99, prefs=w)
    assert d["path_error"] == 0 and d["state_error"] == 0 and abs(d["overestimation_max"]) < 1e-9


def test_seabed_variant_ends_on_the_rock() -> None:
    env = mo_gym.make("mope/deep-sea-treasure-seabed-v0")
    model = tabular_model(env)
    cols = env.unwrapped.sea_map.shape[1]
    s = 1 * cols + 1  # (1, 1): the rock (2, 0) is not below it, the 8.2 treasure (2, 1) is
    down, left = 1, 2
    assert model.terminal[s, down] and model.reward[s, down].tolist() == [8.2, -1.0]
    s = 5 * cols + 6  # (5, 6): left of it (5, 5) is rock
    assert model.terminal[s, left] and model.reward[s, left].tolist() == [-10.0, -1.0]
    obs, _ = env.reset(seed=0)
    env.unwrapped.current_state = np.array([5, 6])
    _, r, term, _, _ = env.step(left)
    assert term and r.tolist() == [-10.0, -1.0]


def test_unknown_dynamics_are_refused() -> None:
    with pytest.raises(EnvironmentError_, match="no ground truth for environment 'four-room-v0'"):
        tabular_model(mo_gym.make("four-room-v0"))


# ------------------------------------------------------------------------------------------------------------
# resource-gathering: a stochastic model (each enemy cell kills with probability 0.1)
# ------------------------------------------------------------------------------------------------------------
def rollout_mean(env: object, model: TabularModel, pi: np.ndarray, episodes: int, gamma: float = 0.99) -> np.ndarray:
    """Monte Carlo mean discounted return of a tabular policy ``pi (S,)`` from the env's start."""
    index = {tuple(o): i for i, o in enumerate(model.obs)}
    total = np.zeros(3)
    for e in range(episodes):
        obs, _ = env.reset(seed=e)
        disc = 1.0
        for _ in range(100):
            obs, r, term, trunc, _ = env.step(int(pi[index[tuple(obs)]]))
            total += disc * np.asarray(r)
            disc *= gamma
            if term or trunc:
                break
    return total / episodes


def test_resource_gathering_model_agrees_with_the_environment_on_a_risky_route() -> None:
    """Straight up through the enemy E1 to the gold and straight back: killed with probability 0.1 on each of the
    two visits. The model's exact expected return and 4,000 sampled episodes agree (within 4 standard errors)."""
    from mope.evaluation.diagnose import policy_returns

    env = mo_gym.make("resource-gathering-v0")
    model = tabular_model(env)
    assert model.prob is not None and model.n_states == 100 and tuple(model.obs[model.start]) == (4, 2, 0, 0)
    pi = np.where(model.obs[:, 2] == 1, 1, 0)  # up until the gold is carried, then down
    exact = policy_returns(model, pi[None], 0.99)[0, model.start]
    g = 0.99
    killed = 0.1 * g**2 + 0.9 * 0.1 * g**4  # E1 on the way up (step 3), then on the way back (step 5)
    np.testing.assert_allclose(exact, [-killed, 0.81 * g**7, 0.0], atol=1e-12)
    mc = rollout_mean(env, model, pi, 4000)
    assert np.all(np.abs(mc - exact) <= 4 * 0.5 / np.sqrt(4000)), (mc, exact)


def test_resource_gathering_exact_front_and_the_published_one() -> None:
    """The exact discounted CCS at gamma 0.99 is the three safe routes: the gem (10 steps, reward at step 9), the
    gold (12 steps) and both (18 steps, around both enemies). MO-Gymnasium's published front has neither the last
    nor the right exponents, so its optimal EUM is 0.045 too low; the evaluator uses the exact one."""
    from mope import metrics
    from mope.evaluation.diagnose import WRONG_PUBLISHED_FRONTS, exact_front, reference_front
    from mope.evaluation.evaluator import Evaluator

    env = mo_gym.make("resource-gathering-v0")
    g = 0.99
    want = np.array([[0.0, 0.0, g**9], [0.0, g**11, 0.0], [0.0, g**17, g**17]])
    front = exact_front(env, g)
    np.testing.assert_allclose(front[np.lexsort(front.T)], want[np.lexsort(want.T)], atol=1e-12)
    assert "ResourceGathering" in WRONG_PUBLISHED_FRONTS
    ev = Evaluator(env, "resource-gathering-v0")
    np.testing.assert_array_equal(ev.front, reference_front(env, g))
    exact_eum = metrics.optimal_utility(ev.eum_prefs, ev.front).mean()
    published = metrics.optimal_utility(ev.eum_prefs, np.asarray(env.unwrapped.pareto_front(gamma=g))).mean()
    assert exact_eum == pytest.approx(0.5707, abs=1e-4) and exact_eum - published > 0.04
    # Deep-Sea-Treasure's published front is right (the DST test above): it is still the one used
    dst = mo_gym.make("deep-sea-treasure-v0")
    np.testing.assert_array_equal(reference_front(dst, g), np.asarray(dst.unwrapped.pareto_front(gamma=g)))


class GreedyTable:
    """An agent whose Q-vectors make a fixed tabular policy greedy and believe ``belief`` of it at every state."""

    def __init__(self, model: TabularModel, pi: np.ndarray, belief: np.ndarray) -> None:
        self.model, self.pi, self.belief = model, pi, belief

    def q_values(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        index = {tuple(o): i for i, o in enumerate(self.model.obs)}
        q = np.full((len(obs), 4, 3), -10.0)
        for row, o in enumerate(obs):
            q[row, self.pi[index[tuple(o)]]] = self.belief
        return q


def test_greedy_policy_metrics_measure_the_utility_given_up_and_the_optimism() -> None:
    """The exact agent gives up nothing and believes what it gets; an agent that takes the risky gold route while
    believing it safe gives up exactly the difference, and its belief gap is what the enemy costs it."""
    env = mo_gym.make("resource-gathering-v0")
    model = tabular_model(env)
    w = np.array([[0.5, 0.5, 0.0], [0.2, 0.8, 0.0]])
    truth = value_iteration(model, w, 0.99)
    d = diagnose(Exact(truth, model), env, gamma=0.99, prefs=w)
    assert abs(d["greedy_regret_mean"]) < 1e-9 and d["greedy_utility_share"] == pytest.approx(1.0)
    assert abs(d["belief_gap_mean"]) < 1e-9 and d["path_error"] == 0
    g = 0.99
    risky = np.where(model.obs[:, 2] == 1, 1, 0)
    got = np.array([-(0.1 * g**2 + 0.09 * g**4), 0.81 * g**7, 0.0])
    believed = np.array([0.0, g**7, 0.0])  # the lucky outcome: never killed
    d = diagnose(GreedyTable(model, risky, believed), env, gamma=0.99, prefs=w)
    best = truth.v[:, model.start]
    np.testing.assert_allclose(d["greedy_regret_mean"], np.mean(best - w @ got), atol=1e-12)
    np.testing.assert_allclose(d["belief_gap_mean"], np.mean(w @ (believed - got)), atol=1e-12)
    assert d["greedy_utility_share"] == pytest.approx((w @ got).sum() / best.sum())
    assert d["path_error"] > 0  # the risky route's first step is not optimal for either preference


# ------------------------------------------------------------------------------------------------------------
# four-room: no published front; the exact one from a programme over its tours (mope.evaluation.four_room)
# ------------------------------------------------------------------------------------------------------------
#: A small four-room maze: 5 shapes of 3 kinds, a wall with one door, start bottom left, goal top right.
SMALL_MAZE = np.array([["1", " ", "X", " ", "G"],
                       [" ", "2", "X", "3", " "],
                       [" ", " ", "1", " ", " "],
                       ["3", " ", "X", " ", "2"],
                       ["_", " ", "X", " ", " "]])


def _four_room(maze: np.ndarray | None = None):
    from mo_gymnasium.envs.four_room.four_room import MAZE, FourRoom

    return FourRoom(maze=MAZE if maze is None else maze)


@pytest.mark.parametrize("gamma", [0.99, 0.9])
def test_four_room_tours_are_value_iterations_optimum_and_play_as_computed(gamma: float) -> None:
    """On a small maze (5 x 5 cells x 32 flag sets) the tour programme's optimal value equals value iteration's on the
    cell-level model at every preference, and each optimal tour, played in the real environment, ends at the goal
    with the programme's discounted return. The door (2, 2) holds a shape: every tour must collect it."""
    from mope.evaluation.diagnose import four_room_model as cell_model
    from mope.evaluation.four_room import optimal_tours
    from mope.preferences import equally_spaced

    env = _four_room(SMALL_MAZE)
    prefs = equally_spaced(3, 36)
    returns, tours = optimal_tours(env, prefs, gamma)
    truth = value_iteration(cell_model(env), prefs, gamma)
    model = cell_model(env)
    np.testing.assert_allclose(np.einsum("nm,nm->n", returns, prefs), truth.v[:, model.start], atol=1e-9)
    for w_return, tour in zip(returns, tours, strict=True):
        env.reset(seed=0)
        total, discount, done = np.zeros(3), 1.0, False
        for a in tour:
            assert not done
            _, r, done, _, _ = env.step(a)
            total, discount = total + discount * r, discount * gamma
        assert done
        np.testing.assert_allclose(total, w_return, atol=1e-6)
    assert returns[:, 0].min() > 0  # the door's kind-1 shape is on every tour


def test_four_room_reference_front_is_the_stored_exact_one() -> None:
    """The evaluator's front for MO-Gymnasium's four-room at gamma 0.99 is the stored convex coverage set: its optimal
    EUM over the evaluation's 100 preferences is the one scripts/four_room_exact.py computed (3.580), each point is
    on the simplex's upper envelope (no point dominated), and another discount or map gets no front."""
    import json

    from mope.evaluation.diagnose import reference_front
    from mope.evaluation.evaluator import N_EUM_PREFS
    from mope.evaluation.four_room import STORED_FRONT
    from mope.metrics import convex_coverage_set, optimal_utility
    from mope.preferences import equally_spaced

    env = mo_gym.make("four-room-v0")
    front = reference_front(env, 0.99)
    stored = json.loads(STORED_FRONT.read_text())
    assert front is not None and front.shape == (len(stored["ccs"]), 3)
    eum = float(np.mean(optimal_utility(equally_spaced(3, N_EUM_PREFS), front)))
    assert eum == pytest.approx(stored["eum_optimal"], abs=1e-9) and eum == pytest.approx(3.580, abs=1e-3)
    assert len(convex_coverage_set(front)) == len(front)
    assert stored["longest_optimal_tour"] < stored["horizon"] == env.spec.max_episode_steps
    assert reference_front(env, 0.95) is None
    assert reference_front(_four_room(SMALL_MAZE), 0.99) is None
