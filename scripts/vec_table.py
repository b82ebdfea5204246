"""Per-seed table of Deep-Sea-Treasure runs: the first CR = 1 (env steps, wall seconds), CR at 20k env steps, the
final CR, optimal share and path error, and the median wall time to the first CR = 1 with a bootstrap CI.

Usage::

    .venv/bin/python scripts/vec_table.py docs/results/dst-vec4-10seeds

``DIR/mope-sS/metrics.csv`` and ``summary.json`` of each seed S (a run folder of ``mope train``, or its compact copy).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from mope.experiments.runs import read_csv_rows


def main(folder: Path) -> None:
    rows = []
    for run in sorted(folder.glob("mope-s*"), key=lambda p: int(p.name.split("-s")[1])):
        metrics = read_csv_rows(run / "metrics.csv")
        first = next((r for r in metrics if r["cr"] >= 0.999), None)
        at20k = next((r["cr"] for r in metrics if r["step"] == 20_000), float("nan"))
        last = metrics[-1]
        wall = json.loads((run / "summary.json").read_text())["wall_s"]
        rows.append((run.name, first, at20k, last, wall))
    print("| run | first CR = 1 (env steps) | wall s to it | CR at 20k env steps | final CR | optimal share | "
          "path error | run wall s |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, first, at20k, last, wall in rows:
        step, sec = (f"{int(first['step']):,}", f"{first['wall_s']:.1f}") if first else ("never", "-")
        print(f"| {name} | {step} | {sec} | {at20k:.3f} | {last['cr']:.3f} | {last['optimal_share']:.3f} | "
              f"{last['path_error']:.4f} | {wall:.0f} |")
    secs = np.array([first["wall_s"] for _, first, *_ in rows if first])
    if len(secs):
        rng = np.random.default_rng(0)
        boot = np.median(rng.choice(secs, (10_000, len(secs))), axis=1)
        lo, hi = np.percentile(boot, [2.5, 97.5])
        print(f"\nmedian wall s to the first CR = 1: {np.median(secs):.1f} [{lo:.1f}, {hi:.1f}] over {len(secs)} of "
              f"{len(rows)} runs; final CR 1 on {sum(r[3]['cr'] >= 0.999 for r in rows)} of {len(rows)}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
