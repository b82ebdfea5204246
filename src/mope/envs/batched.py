"""Batched stepping of many copies of an environment, for evaluation rollouts.

``BatchedEnv`` steps ``n`` episodes at once. :class:`EnvList` does it for any Gymnasium environment (one
``step`` call per running copy: an environment written in Python can only be stepped one copy at a time).
:class:`DeepSeaTreasureBatch` is an exact numpy re-implementation of MO-Gymnasium's Deep-Sea-Treasure
dynamics (same map, moves, walls, rewards and start state, read from the environment itself) that steps all
copies with a few array operations; ``tests/test_envs.py`` checks it against the original step by step.
"""

from __future__ import annotations

import copy
from typing import Protocol

import gymnasium as gym
import numpy as np


class BatchedEnv(Protocol):
    """``n`` episodes of one environment stepped together."""

    n: int

    def reset(self) -> np.ndarray:
        """Reset all copies; return ``(n, *obs_shape)`` observations."""

    def step(self, idx: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Step copies ``idx`` with ``actions``; return their observations, vector rewards and terminated flags."""


class EnvList:
    """Any environment: ``n`` deep copies stepped one by one (time limits are enforced by the caller)."""

    def __init__(self, env: gym.Env, n: int, seed: int = 0) -> None:
        self.n = n
        self.seed = seed
        # the whole wrapper chain is copied: action, observation and reward wrappers are part of the task the
        # agent was trained on; a time-limit wrapper only flags truncation, which is ignored here
        self.envs = [copy.deepcopy(env) for _ in range(n)]

    def reset(self) -> np.ndarray:
        return np.stack([e.reset(seed=self.seed + i)[0] for i, e in enumerate(self.envs)])

    def step(self, idx: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        out = [self.envs[i].step(int(a)) for i, a in zip(idx, actions, strict=True)]
        obs = np.stack([o[0] for o in out])
        rew = np.stack([np.asarray(o[1], dtype=np.float64) for o in out])
        term = np.array([bool(o[2]) for o in out])
        return obs, rew, term


#: Wrappers that neither change observations, actions nor rewards (the vectorised DST may stand in for them).
BENIGN_WRAPPERS = frozenset({"TimeLimit", "OrderEnforcing", "PassiveEnvChecker", "EnvCompatibility"})


class DeepSeaTreasureBatch:
    """Vectorised Deep-Sea-Treasure (MO-Gymnasium's ``DeepSeaTreasure``), all three maps."""

    MOVES = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]], dtype=np.int64)  # up, down, left, right

    def __init__(self, env: gym.Env, n: int) -> None:
        base = copy.deepcopy(env.unwrapped)  # never touch the caller's episode
        self.n = n
        self.map = np.asarray(base.sea_map, dtype=np.float64)
        self.float_state = bool(base.float_state)
        base.reset()
        self.start = np.asarray(base.current_state, dtype=np.int64).copy()
        self.pos = np.tile(self.start, (n, 1))
        #: The EQL authors' rule (mope.envs.dst): moving into the rock ends the episode with (seabed_reward, -1).
        self.seabed_terminates = bool(getattr(base, "seabed_terminates", False))
        self.seabed_reward = float(getattr(base, "seabed_reward", 0.0))

    @staticmethod
    def supports(env: gym.Env) -> bool:
        """True for MO-Gymnasium's Deep-Sea-Treasure with no wrapper that changes what the agent sees or does."""
        if type(env.unwrapped).__name__ not in ("DeepSeaTreasure", "SeabedDeepSeaTreasure") \
                or not hasattr(env.unwrapped, "sea_map"):
            return False
        layer = env
        while isinstance(layer, gym.Wrapper):
            if type(layer).__name__ not in BENIGN_WRAPPERS:
                return False
            layer = layer.env
        return True

    #: Every step that does not end an episode gives exactly this reward (no treasure, one time step).
    loop_reward = np.array([0.0, -1.0])

    @property
    def n_states(self) -> int:
        """Size of the (finite, deterministic) state space: the grid cells."""
        return int(self.map.size)

    def state_index(self, idx: np.ndarray) -> np.ndarray:
        """The state (grid cell) of the episodes ``idx``; with :attr:`loop_reward`, lets a rollout close loops."""
        pos = self.pos[idx]
        return pos[:, 0] * self.map.shape[1] + pos[:, 1]

    def _obs(self, pos: np.ndarray) -> np.ndarray:
        return pos.astype(np.float32) * 0.1 if self.float_state else pos.astype(np.int32)

    def reset(self) -> np.ndarray:
        self.pos = np.tile(self.start, (self.n, 1))
        return self._obs(self.pos)

    def step(self, idx: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        pos = self.pos[idx]
        nxt = pos + self.MOVES[np.asarray(actions, dtype=np.int64)]
        rows, cols = self.map.shape
        inside = (nxt[:, 0] >= 0) & (nxt[:, 0] < rows) & (nxt[:, 1] >= 0) & (nxt[:, 1] < cols)
        safe = np.where(inside[:, None], nxt, pos)
        rock = inside & (self.map[safe[:, 0], safe[:, 1]] == -10)
        valid = inside & (~rock | self.seabed_terminates)
        pos = np.where(valid[:, None], nxt, pos)
        self.pos[idx] = pos
        value = self.map[pos[:, 0], pos[:, 1]]
        term = (value != 0) & ((value != -10) | self.seabed_terminates)
        treasure = np.where(term, np.where(value == -10, self.seabed_reward, value), 0.0).astype(np.float32)
        rew = np.stack([treasure, np.full(len(idx), -1.0, dtype=np.float32)], axis=1).astype(np.float64)
        return self._obs(pos), rew, term


def __getattr__(name: str) -> None:
    if name == "make_batched":  # it picks among this module's batches and the game's, which imports this module
        raise AttributeError("make_batched moved: import it from mope.envs (from mope.envs import make_batched)")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
