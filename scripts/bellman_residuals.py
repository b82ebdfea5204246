"""A Deep-Sea-Treasure-family checkpoint's Bellman residuals on its own values, by how often replay holds each pair.

    python scripts/bellman_residuals.py RUN/checkpoints/final.pt [--env deep-sea-treasure-mirrored-v0]

For every reachable state s, action a and 101 equally spaced preferences w (exact model, environment units):
``res = w.Q(s, a, w) - (w.r(s, a) + gamma max_a' w.Q(s', a', w))`` and the error ``w.Q - w.Q*`` (value
iteration). Pairs are binned by their count in the replay buffer of the run's ``resume.pt`` (next to the
checkpoint). A converged run has small residuals wherever the data are dense; with gamma = 0.99 a residual of r
on the greedy actions holds a value error of about r / (1 - gamma) (docs/results/target-tau/README.md).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mope.agent.agent import MoPE
from mope.envs import make_env
from mope.evaluation.diagnose import agent_q, tabular_model, value_iteration
from mope.preferences import equally_spaced


def replay_counts(state_path: Path, model, n_states: int, n_actions: int) -> np.ndarray | None:
    """``(S, A)`` counts of the stored (state, action) pairs, or None without a resume checkpoint."""
    if not state_path.is_file():
        return None
    buffer = MoPE.load(state_path).buffer
    n = len(buffer)
    cols = int(model.obs[:, 1].max()) + 1
    obs = np.asarray(buffer.obs[:n]).reshape(n, -1)
    states = (obs[:, 0] * cols + obs[:, 1]).astype(int)
    counts = np.zeros((n_states, n_actions))
    np.add.at(counts, (states, np.asarray(buffer.actions[:n]).reshape(-1).astype(int)), 1)
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoint")
    ap.add_argument("--env", default="deep-sea-treasure-mirrored-v0")
    args = ap.parse_args()
    env = make_env(args.env)
    agent = MoPE.load(args.checkpoint, env=env)
    model = tabular_model(env)
    w = equally_spaced(2, 101)
    gamma = agent.config.gamma
    truth = value_iteration(model, w, gamma)
    scal = np.einsum("nm,nsam->nsa", w, agent_q(agent, model, w))
    nxt = scal.max(2)[:, model.next_state]
    res = scal - (np.einsum("nm,sam->nsa", w, model.reward) + gamma * np.where(model.terminal[None], 0.0, nxt))
    err = scal - truth.q
    mask = np.broadcast_to(model.reachable[None, :, None], res.shape)
    greedy = scal.argmax(2)[..., None]
    g_res, g_err = (np.take_along_axis(x, greedy, 2)[..., 0][:, model.reachable] for x in (res, err))
    print(f"all pairs: mean |residual| {np.abs(res[mask]).mean():.3f}, mean error {err[mask].mean():.2f}; "
          f"greedy actions: mean residual {g_res.mean():+.3f}, mean error {g_err.mean():+.2f}")
    counts = replay_counts(Path(args.checkpoint).with_name("resume.pt"), model, *model.next_state.shape)
    if counts is None:
        return
    c = np.broadcast_to(counts[None], res.shape)
    for lo, hi in [(0, 1), (1, 5), (5, 20), (20, 100), (100, np.inf)]:
        m = mask & (c >= lo) & (c < hi)
        if m.any():
            print(f"stored {lo}-{hi} times: {m.sum() // len(w)} pairs, mean |residual| {np.abs(res[m]).mean():.3f}, "
                  f"mean error {err[m].mean():+.2f}")


if __name__ == "__main__":
    main()
