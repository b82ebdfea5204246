"""Summarise run folders: metrics at chosen steps, mean +- std over seeds, as a markdown table.

Usage::

    .venv/bin/python scripts/summarize_runs.py runs/eql-s0 runs/eql-s1 runs/eql-s2 --steps 5000 10000 20000
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from mope.experiments.runs import read_metrics

KEYS = ("cr", "eum", "eum_optimal", "optimal_share", "timeout_share", "hv")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--steps", nargs="+", type=int, default=[5000, 10000, 20000])
    args = parser.parse_args()
    rows = {r: {int(m["step"]): m for m in read_metrics(r)} for r in args.runs}
    print(f"runs: {', '.join(str(r) for r in args.runs)}\n")
    print("| step | " + " | ".join(KEYS) + " |")
    print("|---:|" + "---:|" * len(KEYS))
    for step in args.steps:
        vals = {k: [rows[r][step][k] for r in args.runs if step in rows[r]] for k in KEYS}
        n = len(vals["cr"])
        cells = [f"{np.mean(v):.3f} ± {np.std(v):.3f}" if v else "n/a" for v in vals.values()]
        print(f"| {step} (n={n}) | " + " | ".join(cells) + " |")
    speeds = [json.loads((r / "summary.json").read_text())["s_per_1k_steps"] for r in args.runs
              if (r / "summary.json").exists()]
    if speeds:
        print(f"\nseconds per 1k training steps (incl. evaluations): {np.mean(speeds):.1f} ± {np.std(speeds):.1f}")


if __name__ == "__main__":
    main()
