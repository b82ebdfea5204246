"""The batched Robot Confrontation Game equals the single game, step for step."""

from __future__ import annotations

import mo_gymnasium as mo_gym
import numpy as np
import pytest

import mope.envs.confrontation as conf
from mope.envs import DiscreteActions, make_batched
from mope.envs.confrontation_batch import ConfrontationBatch


def random_actions(env_id: str, rng: np.random.Generator, k: int, wrapped: bool) -> np.ndarray:
    if env_id == conf.DISCRETE_ID:
        return rng.integers(0, 15, k)
    if wrapped:
        return rng.integers(0, 9, k)
    return rng.uniform(-1.2, 1.2, (k, 2)) * [0.2, 0.8]  # some beyond the limits: both clip them


@pytest.mark.parametrize(("env_id", "wrapped"), [(conf.DISCRETE_ID, False), (conf.CONTINUOUS_ID, False),
                                                 (conf.CONTINUOUS_ID, True)])
@pytest.mark.parametrize("seed", [0, 7])
def test_batched_game_equals_the_single_game_step_for_step(env_id: str, wrapped: bool, seed: int) -> None:
    def make() -> object:
        env = mo_gym.make(env_id)
        return DiscreteActions(env, bins=3) if wrapped else env

    n = 40
    batch = ConfrontationBatch(make(), n, seed=100 * seed)
    envs = [make() for _ in range(n)]
    obs_b = batch.reset()
    obs_s = np.stack([e.reset(seed=100 * seed + i)[0] for i, e in enumerate(envs)])
    np.testing.assert_array_equal(obs_b, obs_s)
    rng = np.random.default_rng(seed)
    running = np.arange(n)
    ended = 0
    for _ in range(150):
        actions = random_actions(env_id, rng, len(running), wrapped)
        o, r, term = batch.step(running, actions)
        single = [envs[i].step(actions[k]) for k, i in enumerate(running)]
        np.testing.assert_array_equal(o, np.stack([s[0] for s in single]))
        np.testing.assert_array_equal(r, np.stack([s[1] for s in single]).astype(np.float64))
        np.testing.assert_array_equal(term, [s[2] for s in single])
        for k, i in enumerate(running):
            if term[k]:
                assert batch.outcomes()[i] == single[k][4]["outcome"]
                ended += 1
        running = running[~term]
        if not len(running):
            break
    assert ended > 0  # random red loses to blue or leaves the arena in most games


def test_the_evaluation_uses_the_batched_game() -> None:
    assert isinstance(make_batched(mo_gym.make(conf.DISCRETE_ID), 3), ConfrontationBatch)
    assert isinstance(make_batched(DiscreteActions(mo_gym.make(conf.CONTINUOUS_ID), bins=3), 3), ConfrontationBatch)


def test_play_episodes_on_the_batch_equals_stepping_each_game() -> None:
    from mope.paper.ppo import play_episodes

    seeds = [10_000 + j for _ in range(6) for j in range(2)]
    policy = lambda obs, idx: (idx * 5 + (obs[:, 0] * 10).astype(int)) % 15  # noqa: E731 - depends on the state

    def make() -> object:
        return mo_gym.make(conf.DISCRETE_ID).unwrapped

    batched = play_episodes(policy, make, len(seeds), seeds, 150, record=True)
    envs = [make() for _ in seeds]
    obs = np.stack([e.reset(seed=s)[0] for e, s in zip(envs, seeds, strict=True)])
    ret = np.zeros((len(seeds), 2))
    running = np.arange(len(seeds))
    outcomes = ["running"] * len(seeds)
    for _ in range(150):
        acts = policy(obs[running], running)
        done = []
        for a, i in zip(acts, running, strict=True):
            o, r, term, _, info = envs[i].step(a)
            obs[i], outcomes[i] = o, info["outcome"]
            ret[i] += r
            done.append(term)
        running = running[~np.asarray(done)]
        if not len(running):
            break
    np.testing.assert_allclose(batched.returns, ret, rtol=0, atol=1e-9)
    assert batched.outcomes == outcomes
    np.testing.assert_array_equal(batched.histories[3], np.asarray(envs[3].history))
