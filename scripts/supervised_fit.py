"""How precisely can a Q-network represent Deep-Sea-Treasure's exact Q*? Regression on Q*, no reinforcement learning.

Each network is fitted for ``--steps`` Adam steps (learning rate decayed from ``--lr`` to 1 % of it on a cosine, so
the final weights are settled) on batches of ``--rows`` (state, action, preference) samples: the
state uniform over the reachable ones, the preference uniform on a fine grid, the target the exact vector
``Q*(s, a, w)`` (value iteration, :mod:`mope.evaluation.diagnose`). Then the ground-truth diagnostic measures its greedy
policy. A network that cannot reach a small path error *with the answer given* cannot reach it by TD learning
either: this separates the function class from the learning dynamics (docs/design.md, "The learner").

    python scripts/supervised_fit.py --out docs/results/learning-study/supervised-fit.md

Heads: ``conditioned`` (the paper's: the preference is an input, one vector per action), fitted with the vector
loss ``||Q - Q*||^2``; ``convex`` (mope's: C vectors per action from the state alone, the preferred one is
Q(s, a, w)), fitted with that loss plus the component loss of :func:`mope.agent.losses.component_loss`.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import mo_gymnasium as mo_gym
import numpy as np
import torch

from mope.agent.losses import component_loss
from mope.agent.networks import ConvexQNetwork, QNetwork
from mope.evaluation.diagnose import agent_q, diagnose_q, tabular_model, value_iteration
from mope.preferences import equally_spaced

#: (label, head, observation encoding, hidden layers)
VARIANTS = [
    ("paper: conditioned, scaled (x, y), 64-128-128-64", "conditioned", "scale", (64, 128, 128, 64)),
    ("conditioned, one-hot, 64-128-128-64", "conditioned", "onehot", (64, 128, 128, 64)),
    ("conditioned, one-hot, 256-256-256", "conditioned", "onehot", (256, 256, 256)),
    ("convex (C = 12), one-hot, 64-128-128-64", "convex", "onehot", (64, 128, 128, 64)),
    ("convex (C = 12), one-hot, 256-256-256 (mope's default)", "convex", "onehot", (256, 256, 256)),
]


class Fitted:
    """The fitted network behind the ``q_values`` protocol of the diagnostic."""

    def __init__(self, net: torch.nn.Module) -> None:
        self.net = net

    @torch.no_grad()
    def q_values(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        return self.net(torch.as_tensor(obs), torch.as_tensor(prefs, dtype=torch.float32)).numpy()


def fit(head: str, encoding: str, hidden: tuple[int, ...], steps: int, rows: int, lr: float, seed: int
        ) -> tuple[dict[str, float], float]:
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    env = mo_gym.make("deep-sea-treasure-v0")
    model = tabular_model(env)
    grid = equally_spaced(2, 4001)
    truth = value_iteration(model, grid, 0.99)
    reach = np.flatnonzero(model.reachable)
    space, n_actions = env.observation_space, env.action_space.n
    net = (ConvexQNetwork(space, n_actions, 2, hidden, encoding, 12) if head == "convex"
           else QNetwork(space, n_actions, 2, hidden, encoding))
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps, eta_min=lr / 100)
    obs_all = torch.as_tensor(model.obs)
    t0 = time.perf_counter()
    for _ in range(steps):
        s = reach[rng.integers(len(reach), size=rows)]
        g = rng.integers(len(grid), size=rows)
        target = torch.as_tensor(truth.q_vec[g, s], dtype=torch.float32)  # (rows, A, m)
        w = torch.as_tensor(grid[g], dtype=torch.float32)
        if head == "convex":
            comps = net.components(obs_all[s])  # (rows, A, C, m)
            q = net.select(comps, w[:, None, :])[:, 0]
            extra = component_loss(comps.reshape(-1, 12, 2), target.reshape(-1, 1, 2)).mean()
        else:
            q, extra = net(obs_all[s], w), 0.0
        loss = (q - target).pow(2).sum(-1).mean() + extra
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
    seconds = time.perf_counter() - t0
    test = equally_spaced(2, 101)
    d = diagnose_q(agent_q(Fitted(net), model, test), model, value_iteration(model, test, 0.99))
    return d, seconds


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=10_000)
    p.add_argument("--rows", type=int, default=1024)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--out", type=Path, default=None)
    a = p.parse_args()
    torch.set_num_threads(1)
    lines = [f"Supervised fit to the exact Q* of deep-sea-treasure-v0: {a.steps:,} Adam steps (lr {a.lr}, cosine "
             f"decay to {a.lr / 100:g}) of {a.rows:,} samples; the diagnostic on 101 equally spaced preferences; "
             f"mean over seeds 0-{a.seeds - 1} (each seed's value in brackets for the path error).", "",
             "| network | path error | state error | preferences whose path has an error | mean \\|w^T Q - w^T Q*\\| "
             "| fit s (one seed) |", "|---|---:|---:|---:|---:|---:|"]
    for label, head, encoding, hidden in VARIANTS:
        runs = [fit(head, encoding, hidden, a.steps, a.rows, a.lr, seed) for seed in range(a.seeds)]
        mean = {k: float(np.mean([d[k] for d, _ in runs])) for k in ("path_error", "state_error",
                                                                      "path_failed_share", "abs_error_mean")}
        per = ", ".join(f"{d['path_error']:.4f}" for d, _ in runs)
        lines.append(f"| {label} | {mean['path_error']:.4f} ({per}) | {mean['state_error']:.4f} | "
                     f"{mean['path_failed_share']:.3f} | {mean['abs_error_mean']:.4f} | {runs[0][1]:.0f} |")
        print(lines[-1], flush=True)
    lines += ["", f"Command: `python scripts/supervised_fit.py --steps {a.steps} --rows {a.rows} --lr {a.lr} "
              f"--seeds {a.seeds}`"]
    text = "\n".join(lines) + "\n"
    print(text)
    if a.out is not None:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text)


if __name__ == "__main__":
    main()
