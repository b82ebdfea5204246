"""Tests of mope.agent.replay: the vectorised sum tree and the (prioritized) replay buffer."""

from __future__ import annotations

import numpy as np
import pytest

from mope.agent.replay import ReplayBuffer, SumTree


# ------------------------------------------------------------------------------------------- SumTree
def test_sumtree_total_get_update() -> None:
    t = SumTree(4)
    assert t.total == 0.0
    t.update(np.arange(4), np.array([1.0, 2.0, 3.0, 4.0]))
    assert t.total == 10.0
    np.testing.assert_array_equal(t.get(np.arange(4)), [1.0, 2.0, 3.0, 4.0])
    # internal nodes: root 10, left pair 3, right pair 7
    assert t.tree[1] == 10.0 and t.tree[2] == 3.0 and t.tree[3] == 7.0
    t.update(np.array([1]), np.array([0.5]))
    assert t.total == 8.5
    assert t.tree[2] == 1.5
    np.testing.assert_array_equal(t.get(np.array([3, 1])), [4.0, 0.5])


def test_sumtree_find_on_hand_prefix_sums() -> None:
    # priorities [1, 2, 3, 4]: prefix intervals [0,1) [1,3) [3,6) [6,10)
    t = SumTree(4)
    t.update(np.arange(4), np.array([1.0, 2.0, 3.0, 4.0]))
    values = np.array([0.0, 0.5, 0.999, 1.0, 1.5, 2.999, 3.0, 3.5, 5.999, 6.0, 9.9])
    assert t.find(values).tolist() == [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3]


def test_sumtree_update_with_duplicate_indices_stays_consistent() -> None:
    t = SumTree(4)
    t.update(np.arange(4), np.array([1.0, 2.0, 3.0, 4.0]))
    t.update(np.array([2, 2, 0, 0]), np.array([5.0, 7.0, 0.25, 0.5]))
    # numpy fancy assignment keeps the last value given for a repeated index
    np.testing.assert_array_equal(t.get(np.arange(4)), [0.5, 2.0, 7.0, 4.0])
    assert t.total == pytest.approx(13.5)
    assert t.tree[2] == pytest.approx(2.5) and t.tree[3] == pytest.approx(11.0)
    assert t.find(np.array([0.4, 0.6, 2.6, 9.4, 9.6])).tolist() == [0, 1, 2, 2, 3]


def test_sumtree_single_leaf_updates_equal_a_rebuilt_tree() -> None:
    """Collection updates one leaf at a time (a scalar walk to the root); interleaved with batched updates, every
    internal node must still be the exact sum of its two children."""
    rng = np.random.default_rng(5)
    tree = SumTree(37)
    for k in range(300):
        if k % 3:
            tree.update(rng.integers(0, 37, 1), rng.random(1))
        else:
            tree.update(rng.integers(0, 37, 9), rng.random(9))
    t = tree.tree
    internal = np.arange(1, tree.size)
    assert np.array_equal(t[internal], t[2 * internal] + t[2 * internal + 1])
    assert tree.total == pytest.approx(tree.get(np.arange(37)).sum())


def test_sumtree_capacity_not_power_of_two() -> None:
    t = SumTree(5)
    assert t.size == 8 and t.depth == 3
    t.update(np.arange(5), np.array([1.0, 0.0, 2.0, 1.0, 4.0]))
    assert t.total == 8.0
    # prefix intervals: 0:[0,1) 1:empty 2:[1,3) 3:[3,4) 4:[4,8)
    assert t.find(np.array([0.5, 1.0, 2.9, 3.0, 3.5, 4.0, 7.99])).tolist() == [0, 2, 2, 3, 3, 4, 4]
    # never a padding leaf (index >= capacity), even at the top of the range
    assert t.find(np.array([np.nextafter(8.0, 0.0)])).tolist() == [4]


@pytest.mark.parametrize("capacity", [1, 3, 7, 13])
def test_sumtree_small_capacities(capacity: int) -> None:
    t = SumTree(capacity)
    pr = np.arange(1, capacity + 1, dtype=np.float64)
    t.update(np.arange(capacity), pr)
    assert t.total == pytest.approx(pr.sum())
    # the value at the left end of each leaf's interval finds that leaf
    starts = np.concatenate([[0.0], np.cumsum(pr)[:-1]])
    assert t.find(starts + 0.5).tolist() == list(range(capacity))


def test_sumtree_rejects_bad_input() -> None:
    with pytest.raises(ValueError, match="capacity"):
        SumTree(0)
    t = SumTree(4)
    with pytest.raises(ValueError, match="finite"):
        t.update(np.array([0]), np.array([-1.0]))
    with pytest.raises(ValueError, match="finite"):
        t.update(np.array([0]), np.array([np.nan]))
    t.update(np.array([], dtype=np.int64), np.array([]))  # empty update is a no-op
    assert t.total == 0.0


# Properties of the sum tree (find agrees with a cumulative sum, sampling frequency is proportional to
# priority, updates keep the total) live in tests/test_properties.py.


# ------------------------------------------------------------------------------------------- ReplayBuffer
def fill(buf: ReplayBuffer, n: int, start: int = 0) -> None:
    for i in range(start, start + n):
        buf.add(
            obs=np.array([i, -i], dtype=np.float32),
            pref=np.array([0.25, 0.75]) if i % 2 else np.array([1.0, 0.0]),
            action=i % 4,
            reward=np.array([float(i), -1.0]),
            next_obs=np.array([i + 1, -i - 1], dtype=np.float32),
            terminated=(i % 3 == 0),
        )


def test_buffer_stores_transitions() -> None:
    buf = ReplayBuffer(10, (2,), 2, prioritized=False)
    assert len(buf) == 0
    fill(buf, 4)
    assert len(buf) == 4
    np.testing.assert_array_equal(buf.obs[:4], [[0, 0], [1, -1], [2, -2], [3, -3]])
    np.testing.assert_array_equal(buf.next_obs[:4, 0], [1, 2, 3, 4])
    np.testing.assert_array_equal(buf.prefs[:4], [[1.0, 0.0], [0.25, 0.75], [1.0, 0.0], [0.25, 0.75]])
    np.testing.assert_array_equal(buf.actions[:4], [0, 1, 2, 3])
    np.testing.assert_array_equal(buf.rewards[:4], [[0, -1], [1, -1], [2, -1], [3, -1]])
    np.testing.assert_array_equal(buf.terminated[:4], [1.0, 0.0, 0.0, 1.0])


def test_buffer_fifo_wraps_around() -> None:
    buf = ReplayBuffer(5, (2,), 2, prioritized=True)
    fill(buf, 7)
    assert len(buf) == 5 and buf.full and buf.pos == 2
    # slots 0, 1 were overwritten by transitions 5, 6; slots 2..4 still hold 2..4
    np.testing.assert_array_equal(buf.obs[:, 0], [5, 6, 2, 3, 4])
    np.testing.assert_array_equal(buf.actions, [1, 2, 2, 3, 0])
    np.testing.assert_array_equal(buf.rewards[:, 0], [5, 6, 2, 3, 4])
    fill(buf, 3, start=7)
    np.testing.assert_array_equal(buf.obs[:, 0], [5, 6, 7, 8, 9])
    assert buf.pos == 0 and len(buf) == 5


def test_buffer_sample_returns_consistent_rows() -> None:
    buf = ReplayBuffer(8, (2,), 2, prioritized=True)
    fill(buf, 6)
    batch = buf.sample(32, np.random.default_rng(0))
    assert batch.obs.shape == (32, 2) and batch.prefs.shape == (32, 2) and batch.rewards.shape == (32, 2)
    assert batch.actions.shape == (32,) and batch.terminated.shape == (32,) and batch.weights.shape == (32,)
    assert batch.indices.min() >= 0 and batch.indices.max() <= 5
    i = batch.indices
    np.testing.assert_array_equal(batch.obs[:, 0], i)
    np.testing.assert_array_equal(batch.next_obs[:, 0], i + 1)
    np.testing.assert_array_equal(batch.actions, i % 4)
    np.testing.assert_array_equal(batch.rewards[:, 0], i)
    np.testing.assert_array_equal(batch.terminated, (i % 3 == 0).astype(np.float32))
    np.testing.assert_array_equal(batch.prefs[:, 0], np.where(i % 2, 0.25, 1.0))


def test_buffer_new_transitions_get_max_priority() -> None:
    buf = ReplayBuffer(8, (2,), 2, prioritized=True)
    fill(buf, 2)
    np.testing.assert_array_equal(buf.tree.get(np.arange(2)), [1.0, 1.0])
    buf.update_priorities(np.array([0, 1]), np.array([3.0, 0.5]))
    assert buf.max_priority == 3.0
    fill(buf, 1, start=2)
    np.testing.assert_array_equal(buf.tree.get(np.arange(3)), [3.0, 0.5, 3.0])
    assert buf.tree.total == 6.5


def test_buffer_prioritized_sampling_frequency() -> None:
    buf = ReplayBuffer(4, (2,), 2, prioritized=True)
    fill(buf, 4)
    buf.update_priorities(np.arange(4), np.array([1.0, 2.0, 3.0, 4.0]))
    rng = np.random.default_rng(0)
    counts = np.zeros(4)
    for _ in range(200):
        counts += np.bincount(buf.sample(100, rng).indices, minlength=4)
    freq = counts / counts.sum()
    np.testing.assert_allclose(freq, [0.1, 0.2, 0.3, 0.4], atol=0.01)
    # chi-square against the expected counts (3 degrees of freedom: 16.27 is the 0.1% critical value)
    expected = np.array([0.1, 0.2, 0.3, 0.4]) * counts.sum()
    assert float(((counts - expected) ** 2 / expected).sum()) < 16.27


def test_buffer_zero_priority_is_never_sampled() -> None:
    buf = ReplayBuffer(4, (2,), 2, prioritized=True)
    fill(buf, 4)
    buf.update_priorities(np.arange(4), np.array([1.0, 0.0, 1.0, 0.0]))
    idx = buf.sample(500, np.random.default_rng(1)).indices
    assert set(idx.tolist()) == {0, 2}


def test_buffer_is_weights_hand_values() -> None:
    # P = [0.1, 0.2, 0.3, 0.4], n = 4, beta = 1: w_i = 1 / (n P_i), normalised by max (the rarest item)
    buf = ReplayBuffer(4, (2,), 2, prioritized=True)
    fill(buf, 4)
    buf.update_priorities(np.arange(4), np.array([1.0, 2.0, 3.0, 4.0]))
    batch = buf.sample(400, np.random.default_rng(0), beta=1.0)
    expected = {0: 1.0, 1: 0.5, 2: 1.0 / 3.0, 3: 0.25}
    for i, w in zip(batch.indices, batch.weights, strict=True):
        assert w == pytest.approx(expected[int(i)], rel=1e-6)
    assert batch.weights.max() == pytest.approx(1.0)
    # beta = 0.5: w_i proportional to P_i^-0.5
    batch = buf.sample(400, np.random.default_rng(0), beta=0.5)
    for i, w in zip(batch.indices, batch.weights, strict=True):
        assert w == pytest.approx((0.1 / [0.1, 0.2, 0.3, 0.4][int(i)]) ** 0.5, rel=1e-6)


def test_buffer_is_weights_max_one_and_decreasing_in_priority() -> None:
    buf = ReplayBuffer(16, (2,), 2, prioritized=True)
    fill(buf, 16)
    pr = np.linspace(0.1, 5.0, 16)
    buf.update_priorities(np.arange(16), pr)
    batch = buf.sample(64, np.random.default_rng(3), beta=0.4)
    assert batch.weights.max() == pytest.approx(1.0)
    assert batch.weights.min() > 0
    order = np.argsort(pr[batch.indices], kind="stable")
    w_sorted = batch.weights[order]
    assert np.all(np.diff(w_sorted) <= 1e-7)  # higher priority -> lower (or equal) weight
    assert w_sorted[0] > w_sorted[-1]


def test_buffer_uniform_mode_ignores_priorities() -> None:
    buf = ReplayBuffer(4, (2,), 2, prioritized=False)
    fill(buf, 4)
    assert buf.tree is None
    buf.update_priorities(np.arange(4), np.array([100.0, 0.0, 0.0, 0.0]))  # ignored
    batch = buf.sample(20_000, np.random.default_rng(0))
    np.testing.assert_array_equal(batch.weights, 1.0)
    freq = np.bincount(batch.indices, minlength=4) / 20_000
    np.testing.assert_allclose(freq, 0.25, atol=0.015)


def test_buffer_uniform_samples_only_filled_slots() -> None:
    buf = ReplayBuffer(100, (2,), 2, prioritized=False)
    fill(buf, 3)
    idx = buf.sample(1000, np.random.default_rng(0)).indices
    assert set(idx.tolist()) == {0, 1, 2}


def test_buffer_prioritized_samples_only_filled_slots() -> None:
    buf = ReplayBuffer(100, (2,), 2, prioritized=True)
    fill(buf, 3)
    idx = buf.sample(999, np.random.default_rng(0)).indices
    assert set(idx.tolist()) == {0, 1, 2}
    assert np.bincount(idx).tolist() == [333, 333, 333]  # stratified over equal priorities


def test_buffer_empty_sample_raises() -> None:
    buf = ReplayBuffer(4, (2,), 2)
    with pytest.raises(ValueError, match="empty"):
        buf.sample(2, np.random.default_rng(0))


@pytest.mark.parametrize("prioritized", [True, False])
@pytest.mark.parametrize("n_added", [3, 9])
def test_buffer_state_dict_round_trip(prioritized: bool, n_added: int) -> None:
    buf = ReplayBuffer(6, (2,), 2, prioritized=prioritized)
    fill(buf, n_added)
    if prioritized:
        buf.update_priorities(np.array([0, 1]), np.array([2.5, 0.5]))
    state = buf.state_dict()
    other = ReplayBuffer(6, (2,), 2, prioritized=prioritized)
    other.load_state_dict(state)
    assert len(other) == len(buf)
    assert (other.pos, other.full, other.max_priority) == (buf.pos, buf.full, buf.max_priority)
    for key in ("obs", "next_obs", "prefs", "actions", "rewards", "terminated"):
        np.testing.assert_array_equal(getattr(other, key), getattr(buf, key))
    if prioritized:
        np.testing.assert_array_equal(other.tree.tree, buf.tree.tree)
        assert other.tree.total == buf.tree.total
    a = buf.sample(16, np.random.default_rng(5))
    b = other.sample(16, np.random.default_rng(5))
    np.testing.assert_array_equal(a.indices, b.indices)
    np.testing.assert_array_equal(a.weights, b.weights)
    # the restored buffer keeps writing at the same place
    fill(buf, 1, start=100)
    fill(other, 1, start=100)
    np.testing.assert_array_equal(other.obs, buf.obs)


# ------------------------------------------------------------------------------------------- n-step sequences
def chain(buf: ReplayBuffer, cells: list[int], done_at: set[int] = frozenset(), terminal_at: set[int] = frozenset()
          ) -> None:
    """Transitions cell c -> c + 1 (observation (c, 0)); ``done_at`` ends an episode there (the time limit), and
    ``terminal_at`` by termination."""
    for c in cells:
        buf.add(np.array([c, 0]), np.array([0.5, 0.5]), c % 4, np.array([float(c), -1.0]), np.array([c + 1, 0]),
                c in terminal_at, done=c in done_at or c in terminal_at)


def test_sequences_follow_an_episode_and_stop_at_its_end() -> None:
    buf = ReplayBuffer(10, (2,), 2, prioritized=False)
    chain(buf, [0, 1, 2, 3, 4, 5], done_at={2}, terminal_at={4})
    slots, valid = buf.sequences(np.array([0, 1, 2, 3, 4, 5]), 3)
    np.testing.assert_array_equal(slots[:, 0], [0, 1, 2, 3, 4, 5])
    np.testing.assert_array_equal(slots[1], [1, 2, 3])
    assert valid.tolist() == [
        [True, True, True],     # 0, 1, 2: 2 ends the episode after its own step
        [True, True, False],    # 1, 2 | 3 belongs to the next episode
        [True, False, False],   # 2 is the last step of its episode
        [True, True, False],    # 3, 4 | 4 terminated
        [True, False, False],
        [True, False, False],   # 5 is the newest transition: slot 6 is not written yet
    ]


def test_sequences_stop_at_the_write_position_of_a_full_buffer() -> None:
    buf = ReplayBuffer(4, (2,), 2, prioritized=False)
    chain(buf, [0, 1, 2, 3, 4, 5])  # slots hold cells 4, 5, 2, 3; the next write goes to slot 2
    slots, valid = buf.sequences(np.array([2, 3, 0, 1]), 3)
    np.testing.assert_array_equal(slots, [[2, 3, 0], [3, 0, 1], [0, 1, 2], [1, 2, 3]])
    assert valid.tolist() == [[True, True, True], [True, True, True], [True, True, False], [True, False, False]]
    np.testing.assert_array_equal(buf.obs[slots[0], 0], [2, 3, 4])  # consecutive cells across the wrap


def test_dones_of_checkpoints_without_them_are_inferred() -> None:
    buf = ReplayBuffer(10, (2,), 2, prioritized=False)
    chain(buf, [0, 1, 2, 7, 8], done_at={2})
    state = buf.state_dict()
    del state["dones"]  # a checkpoint saved before n_step
    other = ReplayBuffer(10, (2,), 2, prioritized=False)
    other.load_state_dict(state)
    assert other.dones[:5].tolist() == [False, False, True, False, True]  # the newest one: no successor yet
    np.testing.assert_array_equal(other.sequences(np.array([0, 3]), 3)[1], buf.sequences(np.array([0, 3]), 3)[1])
