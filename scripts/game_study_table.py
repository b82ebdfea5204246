"""Tabulate the robot-game study: every arm's probes (``scripts/game_study.py`` JSON lines), mean over its seeds.

Usage::

    .venv/bin/python scripts/game_study_table.py docs/results/game-study > docs/results/game-study/table.md

An arm is a file name without its ``-sN.jsonl`` tail. Per arm and probe step: seeds, training seconds, red's win
share at w_catch = 1, 0.9, 0.8 (each, and their mean with a bootstrap 95 % CI over seeds), the out-of-arena share
at w_catch <= 0.5 (pooled over the six weights 0, 0.1, ..., 0.5: mean over seeds with a CI; each seed's worst single
weight, mean over seeds; the largest of any seed), and the mean discounted EU over 11 preferences beside the
reference policies' upper envelope.
"""

from __future__ import annotations

import json
import re
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np


def ci(values: list[float], n_boot: int = 2000) -> tuple[float, float]:
    """Bootstrap 95 % CI of the mean (the value itself for one seed)."""
    v = np.asarray(values, dtype=float)
    if len(v) < 2:
        return float(v.mean()), float(v.mean())
    rng = np.random.default_rng(0)
    means = v[rng.integers(0, len(v), (n_boot, len(v)))].mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def main(folder: str) -> None:
    runs: dict[str, dict[int, list[dict]]] = defaultdict(lambda: defaultdict(list))
    for path in sorted(Path(folder).glob("*.jsonl")):
        match = re.match(r"(.+)-s(\d+)\.jsonl$", path.name)
        if not match:
            continue
        for line in path.read_text().splitlines():
            rec = json.loads(line)
            runs[match.group(1)][rec["step"]].append(rec)
    print("| arm | step | seeds | train s | win @1 / .9 / .8 | win >= .8, mean [95 % CI] "
          "| out @ <= .5 pooled, mean [95 % CI] | worst weight (mean of seeds) | max out @ <= .5 | EU (references) |")
    print("|---|---:|---:|---:|---|---|---|---:|---:|---|")
    for arm, steps in runs.items():
        for step, recs in sorted(steps.items()):
            def rate(rec: dict, w: float, key: str) -> float:
                return rec["rates"][str(w)][key] if str(w) in rec["rates"] else rec["rates"][repr(w)][key]

            wins = {w: [rate(r, w, "win") for r in recs] for w in (1.0, 0.9, 0.8)}
            high = [float(np.mean([rate(r, w, "win") for w in (1.0, 0.9, 0.8)])) for r in recs]
            lo, hi = ci(high)
            outs = np.array([[rate(r, w, "out") for w in (0.5, 0.4, 0.3, 0.2, 0.1, 0.0)] for r in recs])
            out, pooled, (p_lo, p_hi) = outs.max(), outs.mean(axis=1), ci(list(outs.mean(axis=1)))
            print(f"| {arm} | {step} | {len(recs)} | {np.mean([r['train_s'] for r in recs]):.0f} | "
                  + " / ".join(f"{np.mean(v):.2f}" for v in wins.values())
                  + f" | {np.mean(high):.3f} [{lo:.3f}, {hi:.3f}] | {pooled.mean():.3f} [{p_lo:.3f}, {p_hi:.3f}] | "
                  f"{outs.max(axis=1).mean():.3f} | {out:.2f} | "
                  f"{np.mean([r['eu'] for r in recs]):.3f} ({recs[0]['eu_references']:.3f}) |")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "docs/results/game-study")
