"""Four-room's exact front (mope.evaluation.four_room), checked, written where the evaluator reads it.

Three checks before writing:
* random play in the real environment against a cell-level model of its dynamics (:func:`check_model`);
* each preference's optimal tour, played in the real environment, returns the programme's vector value;
* plain value iteration over the ~690k (cell, flags) states (:func:`value_iteration_start`) gives the programme's
  optimal value at three preferences.

The evaluation (``mope.evaluation.evaluator.Evaluator``) plays the 100 equally spaced preferences greedily from the
start and scores the discounted (gamma 0.99) return, so the optimal EUM is the mean of the optimal values there.

usage: python scripts/four_room_exact.py [OUT.json] [N_PREFS]
(default: src/mope/evaluation/fronts/four-room-v0.json, 400 equally spaced preferences and the evaluation's 100)
"""

from __future__ import annotations

import json
import sys
import time

import gymnasium as gym
import mo_gymnasium  # noqa: F401  (registers four-room-v0)
import numpy as np

from mope.evaluation.diagnose import four_room_model, value_iteration
from mope.evaluation.evaluator import N_EUM_PREFS
from mope.evaluation.four_room import STORED_FRONT, exact_front, optimal_tours
from mope.metrics import convex_coverage_set
from mope.preferences import equally_spaced

GAMMA, HORIZON = 0.99, 200


def base_env() -> gym.Env:
    return gym.make("four-room-v0").unwrapped


def cell_model() -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """MO-Gymnasium's map as ``(next_state (S, 4), reward (S, 4, 3), terminal (S, 4), start)``
    (:func:`mope.evaluation.diagnose.four_room_model`)."""
    model = four_room_model(base_env())
    return model.next_state, model.reward, model.terminal, model.start


def check_model(steps: int = 20_000, seed: int = 0) -> None:
    """Random play in the real environment: every step's next state, reward and end must be the model's."""
    nxt, rew, term, start = cell_model()
    env = base_env()
    rng = np.random.default_rng(seed)
    n_masks, cols = 1 << len(env.shape_ids), env.maze.shape[1]

    def index(obs: np.ndarray) -> int:
        return (int(obs[0]) * cols + int(obs[1])) * n_masks + int(sum(int(f) << k for k, f in enumerate(obs[2:])))

    obs, _ = env.reset(seed=seed)
    s = index(obs)
    assert s == start, (s, start)
    for _ in range(steps):
        a = int(rng.integers(4))
        obs, r, done, _, _ = env.step(a)
        assert np.array_equal(r, rew[s, a]) and bool(done) == bool(term[s, a]), (s, a, r, rew[s, a], done)
        if done:
            obs, _ = env.reset()
        else:
            assert index(obs) == nxt[s, a], (s, a)
        s = index(obs)


def value_iteration_start(prefs: np.ndarray) -> np.ndarray:
    """Infinite-horizon V*(s0, w) by plain value iteration on the cell-level model (slow: a check)."""
    model = four_room_model(base_env())
    return value_iteration(model, prefs, GAMMA).v[:, model.start]


def play(actions: list[int]) -> np.ndarray:
    """The discounted vector return of ``actions`` in the real environment (it must end at the goal)."""
    env = base_env()
    env.reset(seed=0)
    total, discount, done = np.zeros(3), 1.0, False
    for a in actions:
        assert not done
        _, r, done, _, _ = env.step(a)
        total += discount * r
        discount *= GAMMA
    assert done, "the tour does not end at the goal"
    return total


def main(out: str, n_prefs: int) -> None:
    t0 = time.time()
    check_model()
    env = base_env()
    eum_prefs = equally_spaced(3, N_EUM_PREFS)
    eum_returns, tours = optimal_tours(env, eum_prefs, GAMMA)
    for i, tour in enumerate(tours):
        assert np.allclose(play(tour), eum_returns[i], atol=1e-5), i  # the env's rewards are float32
    probe = np.array([[1 / 3, 1 / 3, 1 / 3], [0.7, 0.2, 0.1], [0.0, 0.0, 1.0]])
    vi = value_iteration_start(probe)
    dp = np.einsum("nm,nm->n", optimal_tours(env, probe, GAMMA)[0], probe)
    assert np.allclose(vi, dp, atol=1e-9), (vi, dp)
    ccs, returns, longest = exact_front(env, GAMMA, n_prefs, HORIZON)
    ccs = convex_coverage_set(np.unique(np.concatenate([ccs, eum_returns]).round(12), axis=0))
    result = {"env_id": "four-room-v0", "gamma": GAMMA, "horizon": HORIZON,
              "eum_optimal": float(np.mean(np.einsum("nm,nm->n", eum_prefs, eum_returns))),
              "eum_prefs": len(eum_prefs), "front_prefs": len(returns) + len(eum_prefs),
              "longest_optimal_tour": max(longest, max(len(t) for t in tours)),
              "value_iteration_check": {"prefs": probe.tolist(), "v": vi.tolist()},
              "seconds": round(time.time() - t0, 1),
              "command": " ".join(["python scripts/four_room_exact.py", *sys.argv[1:]]),
              "ccs": ccs.round(12).tolist()}
    with open(out, "w") as fh:
        json.dump(result, fh, indent=1)
    print(json.dumps({k: result[k] for k in ("eum_optimal", "longest_optimal_tour", "front_prefs", "seconds")}),
          len(ccs), "CCS points")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else str(STORED_FRONT), int(sys.argv[2]) if len(sys.argv) > 2 else 400)
