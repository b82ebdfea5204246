"""Where a convex-head checkpoint holds impossible return vectors, and where its greedy policies go.

    python scripts/inspect_components.py CHECKPOINT [--env ENV_ID] [--bound 124]

Prints, over the states reachable from the start, the largest first-objective component (against ``--bound``, the
largest possible return of that objective: 124 on the mirrored map, 23.7 on DST), how many (state, action, head,
component) vectors exceed it and at which states, and the greedy path from the start for a few preferences.
Used for docs/results/dst-maps/mirrored-probes.md (the mirrored map's divergence).
"""
import sys
from collections import Counter

import numpy as np
import torch

from mope.agent.agent import MoPE
from mope.envs import make_env
from mope.evaluation.diagnose import tabular_model


def option(flag: str, default: str) -> str:
    return sys.argv[sys.argv.index(flag) + 1] if flag in sys.argv else default


agent = MoPE.load(sys.argv[1], env=make_env(option("--env", "deep-sea-treasure-mirrored-v0")))
bound = float(option("--bound", "124"))
model = tabular_model(agent.env)
cols = np.asarray(agent.env.unwrapped.sea_map).shape[1]
states = np.where(model.reachable)[0]
with torch.no_grad():
    v = agent.q_net.components(agent._tensor(model.obs[states])).numpy()  # (S, H, A, C, m)
over = np.argwhere(v[..., 0] > bound + 1e-3)
print(f"largest first-objective component {v[..., 0].max():.1f} (bound {bound}); vectors above the bound: "
      f"{len(over)} of {v[..., 0].size}")
cells = Counter(divmod(int(states[i]), cols) for i, *_ in over)
print("cells with the most such vectors (row, col): count:", dict(cells.most_common(12)))
for w0 in (0.1, 0.3, 0.5, 0.7, 0.9):
    w, s, path = np.array([w0, 1 - w0]), model.start, []
    for _ in range(40):
        q = agent.q_values(model.obs[[s]], w[None])[0]
        a = int((q @ w).argmax())
        path.append(f"{divmod(int(s), cols)}{'^v<>'[a]}")
        if model.terminal[s, a]:
            path.append(f"treasure {model.reward[s, a][0]:g}")
            break
        s = model.next_state[s, a]
    else:
        path.append(f"... no treasure in 40 steps; last Q {np.round(q[a], 1).tolist()}")
    print(f"w = ({w0}, {1 - w0:.1f}):", " ".join(path))
