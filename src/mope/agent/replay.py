"""Replay buffer with the acting preference stored per transition, and prioritized sampling.

Each transition is ``(s, omega_b, a, r, s', terminated)``: the preference ``omega_b`` the agent acted under is
kept so experience exploration can relabel around it (paper sec. 3).

Prioritized replay (Schaul et al. 2016) uses a :class:`SumTree` whose updates and prefix-sum searches are
vectorised over the batch: one numpy operation per tree level, never a Python loop per sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: ``return_steps`` of a transition without a stored return.
NO_RETURN = -(2**62)


class SumTree:
    """Binary sum tree over ``capacity`` non-negative priorities (leaf ``i`` holds priority ``i``).

    The tree is stored in one array of size ``2 * size`` with the root at index 1 and the leaves at
    ``[size, 2 * size)``, where ``size`` is ``capacity`` rounded up to a power of two.
    """

    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"SumTree capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self.size = 1 << max(0, (capacity - 1).bit_length())
        self.depth = self.size.bit_length() - 1
        self.tree = np.zeros(2 * self.size, dtype=np.float64)

    @property
    def total(self) -> float:
        """Sum of all priorities."""
        return float(self.tree[1])

    def get(self, idx: np.ndarray) -> np.ndarray:
        """Priorities at leaf indices ``idx``."""
        return self.tree[self.size + np.asarray(idx)]

    def update(self, idx: np.ndarray, priorities: np.ndarray) -> None:
        """Set leaf priorities and refresh their ancestors, one vectorised step per level."""
        idx = np.asarray(idx, dtype=np.int64).reshape(-1)
        pr = np.asarray(priorities, dtype=np.float64).reshape(-1)
        if idx.size == 0:
            return
        bad = ~np.isfinite(pr) | (pr < 0)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise ValueError(f"priority {pr[i]} at index {int(idx[i])} is out of range: priorities must be finite "
                             "and >= 0")
        tree = self.tree
        tree[self.size + idx] = pr
        if idx.size == 1:  # one leaf (each collection step): a scalar walk to the root, ~10x faster than arrays
            node = (self.size + int(idx[0])) >> 1
            while node:
                tree[node] = tree[2 * node] + tree[2 * node + 1]
                node >>= 1
            return
        # Level by level, each touched parent from its two children: row p of the (size, 2) view is (tree[2p],
        # tree[2p + 1]), so one gather and one row sum per level (a parent touched twice gets the same sum twice).
        pairs = tree.reshape(-1, 2)
        nodes = self.size + idx
        for _ in range(self.depth):
            nodes = nodes >> 1
            tree[nodes] = pairs[nodes].sum(axis=1)

    def find(self, values: np.ndarray) -> np.ndarray:
        """Leaf index whose prefix-sum interval contains each value in ``values`` (all in ``[0, total)``)."""
        v = np.asarray(values, dtype=np.float64).copy()
        nodes = np.ones(v.shape, dtype=np.int64)
        for _ in range(self.depth):
            left = self.tree[2 * nodes]
            right = v >= left
            v = np.where(right, v - left, v)
            nodes = 2 * nodes + right
        leaves = nodes - self.size
        return np.minimum(leaves, self.capacity - 1)


@dataclass
class Batch:
    """A sampled batch; ``weights`` are importance-sampling weights (ones without PER)."""

    indices: np.ndarray
    obs: np.ndarray
    prefs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_obs: np.ndarray
    terminated: np.ndarray
    weights: np.ndarray


class ReplayBuffer:
    """FIFO replay buffer of ``(s, omega_b, a, r, s', terminated)`` with optional prioritized sampling.

    Args:
        capacity: Maximum number of transitions.
        obs_shape: Shape of one observation.
        n_objectives: m.
        prioritized: Sample proportionally to priority^alpha (priorities are given already exponentiated).
        obs_dtype: Storage dtype of observations.
    """

    def __init__(self, capacity: int, obs_shape: tuple[int, ...], n_objectives: int, prioritized: bool = True,
                 obs_dtype: np.dtype = np.float32) -> None:
        self.capacity = capacity
        self.prioritized = prioritized
        self.obs = np.zeros((capacity, *obs_shape), dtype=obs_dtype)
        self.next_obs = np.zeros((capacity, *obs_shape), dtype=obs_dtype)
        self.prefs = np.zeros((capacity, n_objectives), dtype=np.float32)
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros((capacity, n_objectives), dtype=np.float32)
        self.terminated = np.zeros(capacity, dtype=np.float32)
        #: Whether each transition ended its episode (terminated or truncated): n-step sequences stop there.
        self.dones = np.zeros(capacity, dtype=bool)
        #: Greedy-tail return of each transition under its own preference, and the step it was computed at
        #: (``NO_RETURN``: none); written by :meth:`set_returns` when an episode ends.
        self.returns = np.zeros((capacity, n_objectives), dtype=np.float32)
        self.return_steps = np.full(capacity, NO_RETURN, dtype=np.int64)
        #: The demonstrator's action in each transition's state (DAgger's label, ``-1``: none), for the margin
        #: loss on the learner's own transitions (``Config.demo_label_weight``).
        self.expert_actions = np.full(capacity, -1, dtype=np.int64)
        self.tree = SumTree(capacity) if prioritized else None
        self.max_priority = 1.0
        #: Slots ``[0, reserved)`` are kept for good (demonstrations, :meth:`keep_written`); the FIFO ring runs over
        #: ``[reserved, capacity)``.
        self.reserved = 0
        #: Environments that write together (:meth:`add_batch`): each writes every ``stride``-th ring slot, so
        #: the successor of a transition in its episode is ``stride`` ring slots on.
        self.stride = 1
        self.pos = 0
        self.full = False

    def __len__(self) -> int:
        return self.capacity if self.full else self.pos

    def add(self, obs: np.ndarray, pref: np.ndarray, action: int, reward: np.ndarray, next_obs: np.ndarray,
            terminated: bool, done: bool | None = None) -> None:
        """Store one transition; a new transition gets the largest priority seen so far.

        ``done`` (default: ``terminated``) says the episode ended here, by termination or the time limit.
        """
        self.add_batch(np.asarray(obs)[None], np.asarray(pref)[None], np.asarray([action]),
                       np.asarray(reward)[None], np.asarray(next_obs)[None], np.asarray([terminated]),
                       np.asarray([terminated if done is None else done]))

    def add_batch(self, obs: np.ndarray, prefs: np.ndarray, actions: np.ndarray, rewards: np.ndarray,
                  next_obs: np.ndarray, terminated: np.ndarray, dones: np.ndarray,
                  expert: np.ndarray | None = None) -> np.ndarray:
        """Store one transition per environment (row ``k`` from env ``k``) in consecutive ring slots, each with the
        largest priority seen so far; returns the slots. The batch size must be :attr:`stride`, except in a
        buffer whose stride is 1 (any one-by-one writer). ``expert``: the demonstrator's actions (``-1``: none)."""
        n = len(actions)
        ring = self.capacity - self.reserved
        idx = self.reserved + (self.pos - self.reserved + np.arange(n)) % ring
        self.obs[idx] = obs
        self.prefs[idx] = prefs
        self.actions[idx] = actions
        self.rewards[idx] = rewards
        self.next_obs[idx] = next_obs
        self.terminated[idx] = np.asarray(terminated, dtype=np.float32)
        self.dones[idx] = dones
        self.return_steps[idx] = NO_RETURN
        self.expert_actions[idx] = -1 if expert is None else expert
        if self.tree is not None:
            self.tree.update(idx, np.full(n, self.max_priority))
        end = self.pos - self.reserved + n
        self.pos = self.reserved + end % ring
        self.full = self.full or end >= ring
        return idx

    def keep_written(self) -> None:
        """Keep every transition written so far for good (e.g. demonstrations, written first): the FIFO ring
        then runs over the slots after them."""
        if self.full or self.pos >= self.capacity - 1:
            raise ValueError(f"cannot keep {len(self)} transitions for good in a buffer of {self.capacity}: "
                             "the ring needs at least two slots")
        self.reserved = self.pos

    def sample(self, batch_size: int, rng: np.random.Generator, beta: float = 0.4, kept: int = 0) -> Batch:
        """Sample a batch; with PER, stratified proportional sampling and IS weights normalised by their max.

        ``kept`` rows (at the end of the batch) are drawn uniformly from the kept slots (:meth:`keep_written`, e.g.
        demonstrations) instead, with IS weight 1: a fixed share of every batch, however full the ring is.
        """
        n = len(self)
        if n == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        kept = min(kept, batch_size - 1) if self.reserved else 0
        if kept:
            batch = self.sample(batch_size - kept, rng, beta)
            idx = np.concatenate([batch.indices, rng.integers(0, self.reserved, kept)])
            weights = np.concatenate([batch.weights, np.ones(kept, dtype=np.float32)])
            return Batch(idx, self.obs[idx], self.prefs[idx], self.actions[idx], self.rewards[idx],
                         self.next_obs[idx], self.terminated[idx], weights)
        if self.tree is None:
            idx = rng.integers(0, n, size=batch_size)
            weights = np.ones(batch_size, dtype=np.float32)
        else:
            total = self.tree.total
            seg = total / batch_size
            values = (np.arange(batch_size) + rng.random(batch_size)) * seg
            idx = self.tree.find(np.minimum(values, np.nextafter(total, 0)))
            idx = np.minimum(idx, n - 1)
            probs = self.tree.get(idx) / total
            w = (n * np.maximum(probs, 1e-12)) ** (-beta)
            weights = (w / w.max()).astype(np.float32)
        return Batch(idx, self.obs[idx], self.prefs[idx], self.actions[idx], self.rewards[idx],
                     self.next_obs[idx], self.terminated[idx], weights)

    def sequences(self, idx: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The slots of the ``n`` transitions that start at each index in ``idx`` and whether each is there.

        Transitions of one episode sit :attr:`stride` ring slots apart (``n_envs`` environments write one slot
        each in turn), so the sequence from slot ``i`` is ``i, i+stride, ...`` (wrapping inside the ring);
        reserved slots (demonstrations) hold whole episodes one slot apart. Step ``k`` is valid while no earlier
        step ended the episode and it was written after step ``k - 1`` (a slot at or past the write position is
        older, or not written yet).

        Returns:
            ``(slots, valid)``, both ``(len(idx), n)``; ``valid[:, 0]`` is all True.
        """
        idx = np.asarray(idx, dtype=np.int64)
        ring, r = self.capacity - self.reserved, self.reserved
        in_ring = idx >= r
        # ring slots step by the stride (wrapping inside the ring); reserved slots step by one
        step = np.where(in_ring, self.stride, 1)[:, None] * np.arange(n)
        slots = np.where(in_ring[:, None], r + (idx[:, None] - r + step) % ring, idx[:, None] + step)
        slots = np.minimum(slots, self.capacity - 1)
        valid = np.ones(slots.shape, dtype=bool)
        if n > 1:
            # a successor is there while no earlier step ended the episode and it was written after its
            # predecessor (ring age: writes since; the slot at the write position is the oldest or unwritten)
            age = (self.pos - 1 - slots) % ring
            later = np.where(in_ring[:, None], age[:, 1:] < age[:, :-1], True)
            cont = ~self.dones[slots[:, :-1]] & later
            valid[:, 1:] = np.logical_and.accumulate(cont, axis=1)
        return slots, valid

    def set_returns(self, idx: np.ndarray, returns: np.ndarray, step: int) -> None:
        """Store the returns of a finished episode's transitions (slots ``idx``), computed at ``step``."""
        self.returns[idx] = returns
        self.return_steps[idx] = step

    def update_priorities(self, idx: np.ndarray, priorities: np.ndarray) -> None:
        """Set new priorities (already raised to alpha) for sampled indices."""
        if self.tree is None:
            return
        self.tree.update(idx, priorities)
        self.max_priority = max(self.max_priority, float(np.max(priorities)))

    def state_dict(self) -> dict:
        """Arrays and pointers, for checkpoints."""
        n = len(self)
        state = {
            "obs": self.obs[:n].copy(), "next_obs": self.next_obs[:n].copy(), "prefs": self.prefs[:n].copy(),
            "actions": self.actions[:n].copy(), "rewards": self.rewards[:n].copy(),
            "terminated": self.terminated[:n].copy(), "dones": self.dones[:n].copy(),
            "returns": self.returns[:n].copy(),
            "return_steps": self.return_steps[:n].copy(), "expert_actions": self.expert_actions[:n].copy(),
            "pos": self.pos, "full": self.full,
            "max_priority": self.max_priority, "reserved": self.reserved,
        }
        if self.tree is not None:
            state["priorities"] = self.tree.get(np.arange(n))
        return state

    def load_state_dict(self, state: dict) -> None:
        """Restore from :meth:`state_dict`."""
        n = len(state["actions"])
        for key in ("obs", "next_obs", "prefs", "actions", "rewards", "terminated"):
            getattr(self, key)[:n] = np.asarray(state[key])
        for key in ("returns", "return_steps", "expert_actions"):  # absent from older checkpoints
            if key in state:
                getattr(self, key)[:n] = np.asarray(state[key])
        if "dones" in state:
            self.dones[:n] = np.asarray(state["dones"])
        else:  # checkpoints before n_step: an episode ended where the next slot does not start at this next_obs
            succ = np.roll(np.arange(n), -1)
            self.dones[:n] = (self.terminated[:n] > 0) | np.any(
                (self.next_obs[:n] != self.obs[succ]).reshape(n, -1), axis=1)
        self.pos, self.full, self.max_priority = int(state["pos"]), bool(state["full"]), float(state["max_priority"])
        self.reserved = int(state.get("reserved", 0))
        if self.tree is not None and "priorities" in state:
            self.tree.update(np.arange(n), np.asarray(state["priorities"]))
