"""Exact diagnostic of resource-gathering runs over training: every 5k-step checkpoint, as CSV on stdout.

Each row: the run, the step, and :func:`mope.evaluation.diagnose.diagnose`'s greedy_utility_share,
greedy_regret_mean, belief_gap_mean, path_error, state_error and overestimation_mean at 100 equally spaced
preferences (91 on the 3-objective lattice). Runs need their ``checkpoints/step_N.pt`` files
(``checkpoint_every`` 5,000 or a divisor of it, as the benchmark's 2,500).

Usage::

    .venv/bin/python scripts/rg_exact_series.py RUN [RUN ...] > series.csv
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

from mope.evaluation.diagnose import diagnose
from mope.experiments.runs import load_agent

KEYS = ("greedy_utility_share", "greedy_regret_mean", "belief_gap_mean", "path_error", "state_error",
        "overestimation_mean")


def main() -> None:
    out = csv.writer(sys.stdout)
    out.writerow(["run", "step", *KEYS])
    for run in sys.argv[1:]:
        for step in range(5000, 50001, 5000):
            path = Path(run) / "checkpoints" / f"step_{step}.pt"
            if not path.exists():
                continue
            agent = load_agent(path, None)
            d = diagnose(agent, agent.env, agent.config.gamma, 100)
            out.writerow([Path(run).name, step, *(f"{d[k]:.4f}" for k in KEYS)])
            sys.stdout.flush()


if __name__ == "__main__":
    main()
