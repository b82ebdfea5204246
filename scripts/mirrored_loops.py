"""A Deep-Sea-Treasure-family checkpoint read against the exact Q*: its loops, its value errors, its targets' bias.

    python scripts/mirrored_loops.py CHECKPOINT [--env deep-sea-treasure-mirrored-v0] [--pref 0.95]

Prints (docs/results/reward-scale/README.md, "What the late loops are made of"):

1. every greedy cycle from the start over 101 equally spaced preferences, with the agent's Q-vector of the greedy
   action at each state of the cycle beside Q* and the agent's value of the optimal action;
2. the map of ``max_a w^T Q(s, a, w) - V*(s, w)`` for one preference (``--pref``: the first objective's weight);
3. the mean gap between the default target (the target network's best component for the online network's action)
   and double Q over the components (online picks the flat (action, component), the target network reads it),
   and each one's mean error against V*, over every reachable state and the 101 preferences.
"""
import argparse

import numpy as np
import torch

from mope.agent.agent import MoPE
from mope.envs import make_env
from mope.evaluation.diagnose import agent_q, tabular_model, value_iteration
from mope.preferences import equally_spaced


def cycles(model, greedy: np.ndarray) -> dict[tuple[int, ...], list[int]]:
    """Preferences (indices) per greedy cycle reached from the start."""
    found: dict[tuple[int, ...], list[int]] = {}
    for i in range(greedy.shape[0]):
        s, seen = model.start, []
        while s not in seen and len(seen) < 1000:
            seen.append(s)
            a = greedy[i, s]
            if model.terminal[s, a]:
                break
            s = model.next_state[s, a]
        else:
            if s in seen:
                found.setdefault(tuple(seen[seen.index(s):]), []).append(i)
    return found


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("checkpoint")
    ap.add_argument("--env", default="deep-sea-treasure-mirrored-v0")
    ap.add_argument("--pref", type=float, default=0.95)
    args = ap.parse_args()
    env = make_env(args.env)
    agent = MoPE.load(args.checkpoint, env=env)
    model = tabular_model(env)
    w = equally_spaced(2, 101)
    truth = value_iteration(model, w, agent.config.gamma)
    q = agent_q(agent, model, w)
    scal = np.einsum("nm,nsam->nsa", w, q)
    greedy = scal.argmax(2)
    loops = cycles(model, greedy)
    print(f"preferences looping: {sum(len(v) for v in loops.values())} of {len(w)}")
    for cyc, ii in loops.items():
        i = ii[len(ii) // 2]
        print(f"cycle {[tuple(int(x) for x in model.obs[c]) for c in cyc]}, preferences {w[ii[0]].round(2)} to "
              f"{w[ii[-1]].round(2)} ({len(ii)}); at {w[i].round(2)}:")
        for c in cyc:
            a, best = greedy[i, c], truth.q[i, c].argmax()
            print(f"  state {tuple(int(x) for x in model.obs[c])}: action {a}, Q {q[i, c, a].round(1)} "
                  f"(w.Q {scal[i, c, a]:.1f}), Q* {truth.q_vec[i, c, a].round(1)} (V* {truth.v[i, c]:.1f}); "
                  f"optimal action {best}: Q {q[i, c, best].round(1)}")

    one = np.array([[args.pref, 1 - args.pref]])
    t1 = value_iteration(model, one, agent.config.gamma)
    v1 = np.einsum("m,sam->sa", one[0], agent_q(agent, model, one)[0]).max(1)
    rows, cols = (int(model.obs[:, k].max()) + 1 for k in (0, 1))
    grid = np.full((rows, cols), np.nan)
    for s in np.flatnonzero(model.reachable):
        grid[tuple(int(x) for x in model.obs[s])] = v1[s] - t1.v[0, s]
    np.set_printoptions(linewidth=250, precision=0, suppress=True)
    print(f"\nmax_a w.Q - V* under w = {one[0].round(2)} (rows x columns; nan: not reachable)\n{grid}")

    states = np.flatnonzero(model.reachable)
    obs = torch.as_tensor(model.obs[states], dtype=torch.float32)
    prefs = torch.as_tensor(w, dtype=torch.float32)
    with torch.no_grad():
        s_on = torch.einsum("sacm,nm->snac", agent.q_net.components(obs)[:, 0], prefs) / agent.reward_scale
        s_tg = torch.einsum("sacm,nm->snac", agent.target_net.components(obs)[:, 0], prefs) / agent.reward_scale
    act = s_on.amax(3).argmax(2)
    default = s_tg.amax(3).gather(2, act[..., None])[..., 0]
    double = s_tg.flatten(2).gather(2, s_on.flatten(2).argmax(2)[..., None])[..., 0]
    v_star = torch.as_tensor(truth.v[:, states].T, dtype=torch.float32)
    gap = (default - double).flatten()
    print(f"\ntargets' values: default - V* {float((default - v_star).mean()):.2f}, double over components - V* "
          f"{float((double - v_star).mean()):.2f}; default - double: mean {float(gap.mean()):.2f}, 90th percentile "
          f"{float(torch.quantile(gap, 0.9)):.2f}")


if __name__ == "__main__":
    main()
