"""What a minecart checkpoint's greedy carts do from the start, and its Q-values there.

    python scripts/minecart_rollouts.py CHECKPOINT

For four preferences (ore only, mostly ore, mostly fuel, fuel only) plays one greedy episode from the seeded start
(1,000-step limit) and prints its length, whether it ended at home, its undiscounted return, how often each action was
taken (0 mine, 1 left, 2 right, 3 accelerate, 4 brake, 5 idle) and ``w^T Q(s0, a, w)`` of the six actions.
Used for docs/results/minecart-probes/README.md.
"""
import sys
from collections import Counter

import numpy as np

from mope.agent.agent import MoPE
from mope.envs import make_env

if __name__ == "__main__":
    env = make_env("minecart-deterministic-v0", 1000)
    agent = MoPE.load(sys.argv[1], env=env)
    for w in [(0.5, 0.5, 0.0), (0.45, 0.45, 0.1), (0.2, 0.2, 0.6), (0.0, 0.0, 1.0)]:
        obs, _ = env.reset(seed=0)
        q0 = agent.q_values(obs[None], np.array([w]))[0] @ np.array(w)
        actions, ret, term, t = Counter(), np.zeros(3), False, 0
        for t in range(1000):  # noqa: B007 - t is the episode's length below
            a = int(agent.act(obs, np.array(w)))
            actions[a] += 1
            obs, r, term, trunc, _ = env.step(a)
            ret += r
            if term or trunc:
                break
        print(f"w {w}: {t + 1} steps, home {term}, return {ret.round(3)}, actions {dict(sorted(actions.items()))}, "
              f"w.Q(s0, a) {q0.round(3)}")
