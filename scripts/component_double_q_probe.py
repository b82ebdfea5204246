"""Probe (not in mope): double Q over the convex head's components on resource-gathering.

With the convex head the default target lets the online network pick the action and the *target* network pick its
own best component for it (``ConvexQNetwork.double_q_values``): a max over C noisy vectors that double Q does not
cover (docs/design.md, "Known gap"). This probe selects the flat (action, component) with the online network and
reads that same component from the target network.

    python scripts/component_double_q_probe.py ARM SEED OUT
        ARM: default | double-components;  the config is the benchmark's (docs/results/benchmark/...-mope-s0)
"""
import json
import sys
from pathlib import Path

import torch

from mope.agent.networks import ConvexQNetwork
from mope.config import Config
from mope.experiments.runs import train_run


def double_components(v_online: torch.Tensor, v_target: torch.Tensor, prefs: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor]:
    x, a, c, m = v_online.shape
    n = prefs.shape[1]
    best = torch.bmm(v_online.reshape(x, a * c, m), prefs.transpose(1, 2)).max(dim=1).indices  # (X, N) flat (a, c)
    values = v_target.reshape(x, a * c, m).gather(1, best.unsqueeze(-1).expand(x, n, m))
    return values, torch.div(best, c, rounding_mode="floor")


if __name__ == "__main__":
    arm, seed, out = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3])
    bench = Path(__file__).resolve().parents[1] / "docs/results/benchmark"
    base = bench / "resource-gathering-v0-mope-lb-abs-s0/config.json"
    cfg = Config.from_dict({**json.loads(base.read_text()), "seed": seed})
    if arm == "double-components":
        ConvexQNetwork.double_q_values = staticmethod(double_components)
    elif arm != "default":
        raise SystemExit(f"unknown arm {arm}")
    torch.set_num_threads(1)
    res = train_run(cfg, out, progress=False, overwrite=True)
    print(arm, seed, {k: res.final.get(k) for k in ("eum", "timeout_share")})
