"""Vectorised collection: ``n_envs`` training environments stepped together, and the replay ratio knobs
(``train_freq``, ``gradient_steps``)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from mope import Config, MoPE
from mope.agent.replay import ReplayBuffer
from mope.envs import confrontation as C
from mope.envs import make_env

SMALL = {"hidden_sizes": (32, 32), "n_omega": 8, "batch_size": 16, "learning_starts": 40, "buffer_size": 4000,
         "seed": 2}


def replayed(env_id: str, seed: int, actions: list[int]) -> gym.Env:
    """A fresh env in the state of an episode: its seeded reset, then its actions."""
    env = make_env(env_id)
    env.reset(seed=seed)
    for a in actions:
        env.step(a)
    return env


@pytest.mark.parametrize("env_id", ["deep-sea-treasure-v0", C.DISCRETE_ID])
def test_batched_collection_stores_what_stepping_each_env_alone_gives(env_id: str) -> None:
    """Each collection step of n envs stores, in its n slots, exactly the transitions that stepping a copy of each
    env by itself with the same action gives; finished episodes restart from a seeded reset."""
    agent = MoPE(env_id, **SMALL, n_envs=3, epsilon_start=0.5, demos="")  # the game's defaults add demos
    agent.collect_step()  # starts every env's episode
    resets = set(range(2, 2 + agent.episodes_started))  # seed + 0, 1, 2, ... in the order episodes start
    assert {ep.seed for ep in agent._episodes} <= resets and agent.episodes_started == 3 + agent.episodes
    for _ in range(120):
        before = [replayed(env_id, ep.seed, ep.actions) for ep in agent._episodes]  # (deepcopy loses DST's state)
        obs = [np.asarray(ep.obs).copy() for ep in agent._episodes]
        prefs = [ep.pref.copy() for ep in agent._episodes]
        pos = agent.buffer.pos
        agent.collect_step()
        for k in range(3):
            slot = pos + k
            o, r, term, trunc, _ = before[k].step(int(agent.buffer.actions[slot]))
            np.testing.assert_array_equal(agent.buffer.obs[slot], obs[k])
            np.testing.assert_array_equal(agent.buffer.next_obs[slot], o)
            np.testing.assert_allclose(agent.buffer.rewards[slot], np.asarray(r, dtype=np.float32))
            np.testing.assert_allclose(agent.buffer.prefs[slot], prefs[k].astype(np.float32))
            assert bool(agent.buffer.terminated[slot]) == term and bool(agent.buffer.dones[slot]) == (term or trunc)
            ep = agent._episodes[k]
            if term or trunc:  # a new episode from the next seed's reset
                assert ep.actions == [] and ep.seed not in resets
                resets.add(ep.seed)
                np.testing.assert_array_equal(ep.obs, agent.envs[k].reset(seed=ep.seed)[0])
                agent.envs[k].reset(seed=ep.seed)  # the check above reset it too: same state
            else:
                np.testing.assert_array_equal(ep.obs, o)
    assert agent.global_step == 3 * 121 and len(agent.buffer) == 3 * 121
    assert resets == set(range(2, 2 + agent.episodes_started)) and agent.episodes_started == agent.episodes + 3


def test_every_envs_episode_preference_is_drawn_by_the_sampler() -> None:
    agent = MoPE("deep-sea-treasure-v0", **SMALL, n_envs=4)
    drawn: list[np.ndarray] = []
    original = agent.pref_sampler.sample

    def spy(rng: np.random.Generator) -> np.ndarray:
        drawn.append(original(rng))
        return drawn[-1]

    agent.pref_sampler.sample = spy  # type: ignore[method-assign]
    for _ in range(100):
        agent.collect_step()
    assert len(drawn) == agent.episodes_started == agent.pref_sampler.counts.sum() > 4
    stored = {tuple(p) for p in agent.buffer.prefs[: len(agent.buffer)]}
    assert stored <= {tuple(p.astype(np.float32)) for p in drawn}
    assert len(stored) >= len(drawn) - 4  # every finished episode's preference was acted under


def test_one_env_steps_through_act_like_a_hand_written_loop() -> None:
    """n_envs = 1: the stored stream is that of calling act() and env.step() one step at a time (today's path), with
    one-step epsilon-greedy: ez-greedy's kept actions live in collection, not in act() (tests/test_agent.py)."""
    one_step = {**SMALL, "epsilon_repeat_mu": None}
    agent = MoPE("deep-sea-treasure-v0", **one_step)
    twin = MoPE("deep-sea-treasure-v0", **one_step)
    env = twin.env
    obs, pref, seed = None, None, SMALL["seed"]
    for step in range(300):
        agent.collect_step()
        if obs is None:
            obs, _ = env.reset(seed=seed)
            seed += 1
            pref = twin.pref_sampler.sample(twin.rng)
        action = twin.act(obs, pref, greedy=False)
        nxt, r, term, trunc, _ = env.step(action)
        assert agent.buffer.actions[step] == action
        np.testing.assert_array_equal(agent.buffer.next_obs[step], nxt)
        np.testing.assert_array_equal(agent.buffer.prefs[step], pref.astype(np.float32))
        twin.global_step += 1
        obs = None if term or trunc else nxt
    assert agent.global_step == 300


def test_train_freq_and_gradient_steps_set_the_updates_per_env_step() -> None:
    updates = {}
    for n_envs, train_freq, gradient_steps in [(1, 1, 1), (4, 2, 1), (4, 1, 3), (8, 4, 2)]:
        agent = MoPE("deep-sea-treasure-v0", **SMALL, n_envs=n_envs, train_freq=train_freq,
                     gradient_steps=gradient_steps)
        count = 0
        original = agent.update

        def counting(original=original) -> dict[str, float]:
            nonlocal count
            count += 1
            return original()

        agent.update = counting  # type: ignore[method-assign]
        agent.train(840)
        updates[(n_envs, train_freq, gradient_steps)] = count
    # env steps after learning_starts (40) / (n_envs * train_freq) rounds, times gradient_steps
    assert updates == {(1, 1, 1): 800, (4, 2, 1): 100, (4, 1, 3): 600, (8, 4, 2): 50}


def test_callbacks_fire_on_the_multiples_they_pass_with_several_envs() -> None:
    agent = MoPE("deep-sea-treasure-v0", **SMALL, n_envs=3, eval_prefs=20)
    records = agent.train(600, eval_env=make_env("deep-sea-treasure-v0"), eval_every=100)
    assert [r["step"] for r in records] == [102, 201, 300, 402, 501, 600]


def test_n_envs_is_checked() -> None:
    with pytest.raises(Exception, match="n_envs=0 is out of range"):
        Config(n_envs=0)
    with pytest.raises(Exception, match="n_envs=600 is out of range"):
        Config(n_envs=600, buffer_size=1000)
    with pytest.raises(Exception, match="train_freq=0 is out of range"):
        Config(train_freq=0)


def test_sequences_follow_each_envs_episode_with_a_stride() -> None:
    """Three envs write slots in turn: env k's n-step sequence from slot i is i, i+3, ... within the ring,
    cut at its episode's end and at transitions not written yet."""
    buf = ReplayBuffer(10, (2,), 2, prioritized=False)
    buf.stride = 3
    for t in range(3):  # env k at time t: cell (k, t); env 1's episode ends at t = 1
        obs = np.array([[k, t] for k in range(3)])
        buf.add_batch(obs, np.full((3, 2), 0.5), np.zeros(3, dtype=np.int64), np.zeros((3, 2)), obs + [0, 1],
                      np.zeros(3, dtype=bool), np.array([False, t == 1, False]))
    slots, valid = buf.sequences(np.array([0, 1, 2, 6]), 3)
    np.testing.assert_array_equal(slots, [[0, 3, 6], [1, 4, 7], [2, 5, 8], [6, 9, 2]])
    assert valid.tolist() == [[True, True, True], [True, True, False], [True, True, True],
                              [True, False, False]]  # slot 9 is not written yet (the write position)
    # one more round wraps: slots 9, 0, 1; env 0's sequence from 6 goes on to 9 and stops at the overwritten 2
    buf.add_batch(np.array([[0, 3], [1, 3], [2, 3]]), np.full((3, 2), 0.5), np.zeros(3, dtype=np.int64),
                  np.zeros((3, 2)), np.array([[0, 4], [1, 4], [2, 4]]), np.zeros(3, dtype=bool), np.zeros(3, bool))
    slots, valid = buf.sequences(np.array([6]), 3)
    np.testing.assert_array_equal(slots, [[6, 9, 2]])
    assert valid.tolist() == [[True, True, False]]
    np.testing.assert_array_equal(buf.obs[[6, 9]], [[0, 2], [0, 3]])


def test_kept_transitions_stay_while_the_ring_turns() -> None:
    buf = ReplayBuffer(8, (2,), 2, prioritized=True)
    for t in range(3):  # three kept transitions, one episode
        buf.add(np.array([9, t]), np.array([0.5, 0.5]), 0, np.zeros(2), np.array([9, t + 1]), False, done=t == 2)
    buf.keep_written()
    for t in range(20):
        buf.add(np.array([0, t]), np.array([0.5, 0.5]), 1, np.zeros(2), np.array([0, t + 1]), False)
    assert len(buf) == 8 and buf.full
    np.testing.assert_array_equal(buf.obs[:3], [[9, 0], [9, 1], [9, 2]])
    assert sorted(buf.obs[3:, 1].tolist()) == list(range(15, 20))
    slots, valid = buf.sequences(np.array([0, 1]), 3)
    assert valid.tolist() == [[True, True, True], [True, True, False]]
    state = buf.state_dict()
    again = ReplayBuffer(8, (2,), 2, prioritized=True)
    again.load_state_dict(state)
    assert again.reserved == 3 and again.pos == buf.pos


def test_a_fixed_share_of_every_batch_comes_from_the_kept_slots() -> None:
    buf = ReplayBuffer(50, (2,), 2, prioritized=True)
    for t in range(4):
        buf.add(np.array([9, t]), np.array([0.5, 0.5]), 0, np.zeros(2), np.array([9, t + 1]), False, done=t == 3)
    buf.keep_written()
    for t in range(40):
        buf.add(np.array([0, t]), np.array([0.5, 0.5]), 1, np.zeros(2), np.array([0, t + 1]), False)
    batch = buf.sample(16, np.random.default_rng(0), kept=6)
    assert len(batch.indices) == 16 and (batch.indices[10:] < 4).all()
    np.testing.assert_array_equal(batch.weights[10:], 1.0)
    assert buf.sample(16, np.random.default_rng(0)).indices.shape == (16,)
