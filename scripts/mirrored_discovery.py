"""How often does exploration leave the mirrored map's path to its 50 treasure for the 74 or 124 treasure?

The greedy policy walks the shortest path to the 50 treasure (row 7, column 17); with probability epsilon a step
explores: one uniform random action (epsilon-greedy), or one kept for n ~ zeta(2) steps (ez-greedy, mope's default).
Prints, per epsilon and rule, the treasures 20,000 episodes of 100 steps end at and the share that reach 74 or 124
(docs/results/ez-greedy).

    .venv/bin/python scripts/mirrored_discovery.py
"""

from __future__ import annotations

from collections import deque

import mo_gymnasium as mg
import numpy as np

import mope.envs  # noqa: F401  (registers the mirrored map)

SEA = mg.make("deep-sea-treasure-mirrored-v0").unwrapped.sea_map
MOVES = ((-1, 0), (1, 0), (0, -1), (0, 1))  # up, down, left, right
GOAL = (7, 17)  # the 50 treasure


def _inside(r: int, c: int) -> bool:
    return 0 <= r < SEA.shape[0] and 0 <= c < SEA.shape[1]


def distances_to_goal() -> np.ndarray:
    """Steps from every open cell to the 50 treasure (breadth-first search over open cells)."""
    dist = np.full(SEA.shape, 10**6)
    dist[GOAL] = 0
    queue = deque([GOAL])
    while queue:
        r, c = queue.popleft()
        for dr, dc in MOVES:
            a, b = r - dr, c - dc
            if _inside(a, b) and SEA[a, b] == 0 and dist[a, b] > dist[r, c] + 1:
                dist[a, b] = dist[r, c] + 1
                queue.append((a, b))
    return dist


def step(s: tuple[int, int], k: int) -> tuple[int, int]:
    a, b = s[0] + MOVES[k][0], s[1] + MOVES[k][1]
    return (a, b) if _inside(a, b) and SEA[a, b] != -10 else s


def greedy(s: tuple[int, int], dist: np.ndarray) -> int:
    return min(range(4), key=lambda k: dist[step(s, k)] if step(s, k) != s else 10**7)


def episodes(eps: float, mu: float | None, n: int, rng: np.random.Generator, dist: np.ndarray) -> dict[int, int]:
    """Treasure -> how many of ``n`` episodes ended there."""
    found: dict[int, int] = {}
    for _ in range(n):
        s, left, action = (0, 0), 0, 0
        for _t in range(100):
            if left > 0:
                left -= 1
            elif rng.random() < eps:
                action = int(rng.integers(4))
                left = min(int(rng.zipf(mu)), 100) - 1 if mu else 0
            else:
                action = greedy(s, dist)
            s = step(s, action)
            if SEA[s] > 0:
                found[int(SEA[s])] = found.get(int(SEA[s]), 0) + 1
                break
    return found


def main() -> None:
    dist, rng, n = distances_to_goal(), np.random.default_rng(0), 20_000
    for eps in (0.05, 0.1, 0.2, 0.3, 0.5):
        for mu in (None, 2.0):
            f = episodes(eps, mu, n, rng, dist)
            far = (f.get(74, 0) + f.get(124, 0)) / n
            print(f"epsilon {eps}, {'ez-greedy mu 2' if mu else 'one-step'}: {dict(sorted(f.items()))}  "
                  f"P(74 or 124) = {far:.4f}")


if __name__ == "__main__":
    main()
