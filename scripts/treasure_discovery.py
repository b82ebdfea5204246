"""When did a run first reach each treasure, and when did its greedy policies first cover the front?

Reads the replay buffer of each run's resumable checkpoint (``checkpoints/resume.pt``: every transition of a
20k-step run, in order, when ``buffer_size`` >= the steps) and the run's ``metrics.csv``. Prints, per run, the
step at which each treasure was first reached (under the behaviour policy, epsilon-greedy), the step at which the
last one was, and the first evaluation at CR = 1.

    python scripts/treasure_discovery.py runs/reproduce-dst/mope-s*
"""
import csv
import sys
from pathlib import Path

import numpy as np
import torch


def main(runs: list[str]) -> None:
    lasts, covers = [], []
    for run in map(Path, runs):
        state = torch.load(run / "checkpoints" / "resume.pt", weights_only=False)
        buf = state["buffer"]
        rewards = np.asarray(buf["rewards"])
        if int(state["global_step"]) > len(rewards):
            print(f"{run}: {state['global_step']} steps in a buffer of {len(rewards)}: the first transitions are gone")
            continue
        treasure = rewards[: int(state["global_step"]), 0]
        first: dict[float, int] = {}
        for step, t in enumerate(np.round(treasure, 1)):
            if t > 0 and float(t) not in first:
                first[float(t)] = step + 1
        with open(run / "metrics.csv") as f:
            rows = list(csv.DictReader(f))
        cover = next((int(r["step"]) for r in rows if float(r["cr"]) >= 1 - 1e-9), None)
        last = max(first.values())
        lasts.append(last)
        covers.append(cover if cover is not None else np.inf)
        order = ", ".join(f"{t:g}@{s}" for t, s in sorted(first.items(), key=lambda kv: kv[1]))
        print(f"{run.name}: {len(first)} treasures, last reached at step {last}; first CR = 1 at {cover}  [{order}]")
    if lasts:
        print(f"median step of the last treasure's first visit: {np.median(lasts):,.0f}; "
              f"median first CR = 1: {np.median(covers):,.0f} ({len(lasts)} runs)")


if __name__ == "__main__":
    main(sys.argv[1:])
