"""Are the robot game's exits checkpoint noise? Probe one run's checkpoints alone, as a Q-ensemble and averaged.

Usage::

    .venv/bin/python scripts/game_eval_ensembles.py RUN_DIR [--steps 150000,175000,200000]

``RUN_DIR`` is a training run folder with ``checkpoints/step_N.pt`` (and ``resume.pt`` for the target network).
Each line is :func:`mope.evaluation.game_probe.probe` (greedy play on the 100 common starts at w_catch 0, 0.1,
..., 1): the win share at w_catch 0.8-1, the out-of-arena shares at w_catch 0-0.5 and the EU over 11
preferences, for each checkpoint, the target network of ``resume.pt``, the ensemble that acts on the mean of the
checkpoints' scalarised Q-values (Averaged-DQN's average, Anschel et al. 2017) and one network with the
checkpoints' weights averaged. If the exits were noise between checkpoints, the ensemble would leave the arena
less than its members.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

import mope
from mope.evaluation.game_probe import probe


class QEnsemble:
    """Greedy actions on the mean of several agents' scalarised Q-values (what ``play_agent`` needs)."""

    def __init__(self, agents: list[mope.MoPE]) -> None:
        self.agents = agents

    @torch.inference_mode()
    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        o, p = torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(prefs, dtype=torch.float32)
        total = sum(torch.einsum("ram,rm->ra", a.q_net(o, p), p) for a in self.agents)
        return total.argmax(1).numpy()


def show(tag: str, agent: object) -> None:
    r = probe(agent)
    outs = [round(v["out"], 2) for w, v in r["rates"].items() if w <= 0.5]
    win = sum(r["rates"][w]["win"] for w in (0.8, 0.9, 1.0)) / 3
    print(f"{tag:14s} win w_catch 0.8-1 {win:.3f}  out at w_catch 0-0.5 {outs}  max {max(outs):.2f}  "
          f"EU {r['eu']:.3f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--steps", default="150000,175000,200000")
    args = parser.parse_args()
    torch.set_num_threads(1)
    steps = [int(s) for s in args.steps.split(",")]
    agents = [mope.MoPE.load(args.run / "checkpoints" / f"step_{s}.pt") for s in steps]
    for s, a in zip(steps, agents, strict=True):
        show(f"step {s}", a)
    resume = args.run / "checkpoints" / "resume.pt"
    if resume.exists():
        target = mope.MoPE.load(args.run / "checkpoints" / f"step_{steps[-1]}.pt")
        target.q_net.load_state_dict(torch.load(resume, weights_only=False, map_location="cpu")["target_net"])
        show("target net", target)
    show("Q-ensemble", QEnsemble(agents))
    averaged = mope.MoPE.load(args.run / "checkpoints" / f"step_{steps[-1]}.pt")
    states = [a.q_net.state_dict() for a in agents]
    averaged.q_net.load_state_dict({k: sum(s[k].float() for s in states) / len(states) for k in states[0]})
    show("weights mean", averaged)


if __name__ == "__main__":
    main()
