"""What a trained agent believes on a stochastic environment, against what its greedy policy returns on average.

For a run on resource-gathering-v0 (each enemy cell kills with probability 0.1): at the start state and the given
preference, the Q-vector of the greedy action and, with the convex head, every component of that action; then the
same policy's mean discounted return over many episodes from the same start; and, over 60 random preferences,
the policy's expected utility (40 episodes each) against the optimum from MO-Gymnasium's front.

Usage::

    .venv/bin/python scripts/stochastic_components.py docs/results/benchmark/resource-gathering-v0-mope-lb-abs-s0
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import torch

import mope
from mope.envs import make_env
from mope.evaluation.evaluator import solutions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--pref", type=float, nargs=3, default=[0.64, 0.03, 0.33])
    parser.add_argument("--episodes", type=int, default=400)
    args = parser.parse_args()
    torch.set_num_threads(1)
    algo = json.loads((args.run / "config.json").read_text()).get("algo", "mope")
    agent = (mope.MoPE if algo == "mope" else mope.EQL).load(args.run / "checkpoints" / "final.pt")
    env = make_env("resource-gathering-v0")
    gamma = agent.config.gamma
    pref = np.asarray(args.pref, dtype=np.float32)
    shown = [round(float(x), 2) for x in pref]
    obs, _ = env.reset(seed=0)
    with torch.no_grad():
        q = agent.q_net(torch.as_tensor(obs[None], dtype=torch.float32), torch.as_tensor(pref[None]))[0].numpy()
    a = int((q @ pref).argmax())
    print(f"preference {shown}: greedy action {a}, its Q-vector {np.round(q[a].astype(float), 3).tolist()} "
          f"(utility {q[a] @ pref:.3f})")
    if hasattr(agent.q_net, "components"):
        with torch.no_grad():
            comps = agent.q_net.components(torch.as_tensor(obs[None], dtype=torch.float32))[0, 0, a].numpy()
        print("  the action's components:", "; ".join(str(np.round(c.astype(float), 2).tolist()) for c in comps))
    sol = solutions(agent, env, np.repeat(pref[None], args.episodes, axis=0), gamma, seed=1)
    mean = sol.discounted.mean(axis=0)
    print(f"  the greedy policy's mean discounted return over {args.episodes} episodes: {np.round(mean, 3).tolist()} "
          f"(utility {mean @ pref:.3f}; {np.mean(sol.discounted[:, 0] < 0):.0%} of episodes end killed)")
    front = np.asarray(env.unwrapped.pareto_front(gamma=gamma))
    prefs = np.random.default_rng(0).dirichlet(np.ones(3), size=60).astype(np.float32)
    sol = solutions(agent, env, np.repeat(prefs, 40, axis=0), gamma, seed=2)
    utility = (sol.discounted.reshape(60, 40, 3).mean(axis=1) * prefs).sum(axis=1)
    optimum = (prefs @ front.T).max(axis=1)
    print(f"60 random preferences, 40 episodes each: expected utility {utility.mean():.3f} against the optimum "
          f"{optimum.mean():.3f} ({utility.mean() / optimum.mean():.1%})")


if __name__ == "__main__":
    main()
