"""Is the Robot Confrontation Game balanced enough to learn? Play two fixed red policies against blue's rule.

* the scripted pursuer (``mope.envs.confrontation.scripted_pursuer``: lead pursuit, brakes to turn tighter,
  keeps off the walls) should win a fair share of games;
* a uniformly random red (``a ~ U[-0.2, 0.2]``, ``w ~ U[-0.8, 0.8]`` each step) should lose most of them.

Usage: ``python scripts/confrontation_balance.py [--episodes 200] [--seed 0]``. Episode ``i`` resets with seed
``seed + i`` (the same initial states for both red policies); the random red draws from ``default_rng(seed)``.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter

import numpy as np

import mope.envs.confrontation as C


def play(policy: str, episodes: int, seed: int) -> Counter:
    """Outcome counts of ``episodes`` games of red ``policy`` ("pursuer" or "random") against blue."""
    env = C.RobotConfrontationEnv()
    rng = np.random.default_rng(seed)
    counts: Counter = Counter()
    for i in range(episodes):
        env.reset(seed=seed + i)
        info = {"outcome": "running"}
        for _ in range(C.DEFAULT_HORIZON):
            if policy == "pursuer":
                act = C.scripted_pursuer(env.red, env.blue, env.half, env.a_max, env.w_max, env.v_max, env.dt)
            else:
                act = rng.uniform([-env.a_max, -env.w_max], [env.a_max, env.w_max])
            *_, term, _, info = env.step(act)
            if term:
                break
        counts[info["outcome"]] += 1
    return counts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    t0 = time.perf_counter()
    print(f"{args.episodes} episodes each, reset seeds {args.seed}..{args.seed + args.episodes - 1}, "
          f"{C.DEFAULT_HORIZON} steps of {C.DEFAULT_DT} s")
    print("| red policy | red wins | blue wins | red out | blue out | time-out |")
    print("|---|---|---|---|---|---|")
    for policy in ("pursuer", "random"):
        c = play(policy, args.episodes, args.seed)
        n = args.episodes
        print(f"| {policy} | {c['red_win'] / n:.3f} | {c['blue_win'] / n:.3f} | {c['red_out'] / n:.3f} | "
              f"{c['blue_out'] / n:.3f} | {c['running'] / n:.3f} |")
    print(f"[{time.perf_counter() - t0:.0f} s]")


if __name__ == "__main__":
    main()
