"""Deep-Sea-Treasure with the seabed rule of the EQL authors' code (Yang et al. 2019, RunzheYang/MORL).

MO-Gymnasium's Deep-Sea-Treasure leaves the submarine in place when it moves into the rock of the seabed, with
reward ``(0, -1)``: a self-loop. In the EQL authors' own environment (``synthetic/envs/deep_sea_treasure.py``) the
submarine enters the rock and the episode ends with reward ``(-10, -1)`` (treasure -10, time -1): their
passability test compares against -1 while rock cells hold -10, so the move is allowed and the rock's value is
paid as a treasure. The MoPE paper builds on that code and likely used this rule. Moving off the grid still
leaves the submarine in place with ``(0, -1)``, as in both versions. Map, start, treasures and the front are
MO-Gymnasium's.

Registered as ``mope/deep-sea-treasure-seabed-v0`` (100-step limit, like ``deep-sea-treasure-v0``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.spaces import Box
from mo_gymnasium.envs.deep_sea_treasure.deep_sea_treasure import DeepSeaTreasure

SEABED_ID = "mope/deep-sea-treasure-seabed-v0"
#: The treasure-objective reward of moving into the rock (the episode then ends).
SEABED_REWARD = -10.0


class SeabedDeepSeaTreasure(DeepSeaTreasure):
    """Deep-Sea-Treasure where moving into the seabed ends the episode with reward ``(-10, -1)``."""

    seabed_terminates = True
    seabed_reward = SEABED_REWARD

    def __init__(self, render_mode: str | None = None, dst_map: Any = None, float_state: bool = False) -> None:
        if dst_map is None:
            super().__init__(render_mode, float_state=float_state)
        else:
            super().__init__(render_mode, dst_map, float_state)
        self.reward_space = Box(low=np.array([SEABED_REWARD, -1.0]), high=np.array([np.max(self.sea_map), -1.0]),
                                dtype=np.float32)

    def step(self, action: int) -> tuple[np.ndarray, np.ndarray, bool, bool, dict]:
        nxt = self.current_state + self.dir[int(action)]
        rows, cols = self.sea_map.shape
        if 0 <= nxt[0] < rows and 0 <= nxt[1] < cols and self.sea_map[nxt[0], nxt[1]] == -10:
            self.current_state = nxt  # the submarine hits the rock: the episode ends
            if self.render_mode == "human":
                self.render()
            return self._get_state(), np.array([SEABED_REWARD, -1.0], dtype=np.float32), True, False, {}
        return super().step(action)
