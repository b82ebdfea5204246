"""Four-room: which part of MoPE costs EUM? EUM per seed of eql, ee, pe and mope (today's defaults), at the final
evaluation and as the mean of the last 5, the means with bootstrap 95 % CIs, and each variant's paired difference to
eql.

usage: python scripts/four_room_ablation.py [ROOT]   (ROOT: docs/results, the default)

eql and mope are the benchmark's runs (ROOT/benchmark/four-room-v0-{eql,mope}-sN); the others are folders
ROOT/four-room-ablation/VARIANT-sN, trained with eql's config and another variant, for example

    mope train --config docs/results/benchmark/four-room-v0-eql-s0/config.json --algo ee --out RUN

A variant shows once it has a seed; seeds missing from a pair are left out of that pair.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from mope.experiments.stats import aggregate

SEEDS = range(5)
LAST = 5  # as the benchmark's "EUM, mean of the last 5 evaluations"


def final_eum(run: Path, last: int = 1) -> float | None:
    """The mean EUM of a finished run folder's last ``last`` evaluations (None where it has not finished)."""
    if not (run / "summary.json").is_file():
        return None
    with open(run / "metrics.csv") as fh:
        eums = [float(row["eum"]) for row in csv.DictReader(fh)]
    return float(np.mean(eums[-last:]))


def variant_runs(root: Path, last: int = 1) -> dict[str, dict[int, float]]:
    """EUM per seed (the mean of the last ``last`` evaluations) of each variant found under ``root``."""
    found: dict[str, dict[int, float]] = {}
    for name in ("eql", "mope"):
        found[name] = {s: e for s in SEEDS
                       if (e := final_eum(root / "benchmark" / f"four-room-v0-{name}-s{s}", last)) is not None}
    for run in sorted((root / "four-room-ablation").glob("*-s*")):
        name, _, seed = run.name.rpartition("-s")
        if (e := final_eum(run, last)) is not None:
            found.setdefault(name, {})[int(seed)] = e
    return found


def table(found: dict[str, dict[int, float]]) -> str:
    """A markdown table: EUM per seed, mean [95 % CI], and the paired difference to eql."""
    lines = ["| variant | " + " | ".join(f"seed {s}" for s in SEEDS) + " | mean [95 % CI] | minus eql, paired |",
             "|---|" + "---|" * len(SEEDS) + "---|---|"]
    for name, eums in found.items():
        if not eums:
            continue
        stats = aggregate(list(eums.values()))
        common = sorted(set(eums) & set(found["eql"]))
        diff = aggregate([eums[s] - found["eql"][s] for s in common]) if name != "eql" and common else None
        cells = [f"{eums[s]:.3f}" if s in eums else "-" for s in SEEDS]
        paired = "-"
        if diff:
            above = int(np.sum(np.array(diff.values) > 0))
            paired = f"{diff.mean:+.3f} [{diff.ci_low:+.3f}, {diff.ci_high:+.3f}], {above} of {diff.n} above"
        lines.append(f"| {name} | " + " | ".join(cells) +
                     f" | {stats.mean:.3f} [{stats.ci_low:.3f}, {stats.ci_high:.3f}] (n={stats.n}) | {paired} |")
    return "\n".join(lines)


if __name__ == "__main__":
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/results")
    print("Final evaluation's EUM:\n")
    print(table(variant_runs(root)))
    print(f"\nEUM, mean of the last {LAST} evaluations (each evaluation is one greedy episode per preference):\n")
    print(table(variant_runs(root, LAST)))
