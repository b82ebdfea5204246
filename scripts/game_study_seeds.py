"""Pool the robot-game study's 200k probes of chosen seeds into one row per arm, with bootstrap 95 % CIs.

Usage::

    .venv/bin/python scripts/game_study_seeds.py \\
        "defaults 0-9=docs/results/game-study/levers7/defaults-*" \\
        "pretrain5k 0-9=docs/results/game-study/levers7/pretrain5k-200k-s*.jsonl"

Each argument is ``NAME=GLOB``; a name may take several globs (repeat it). The files are ``scripts/game_study.py``
probe lines (their 200k-step line is used) or the per-seed lines of a reproduction's checkpoints probed the same
way (``defaults-probe-200k.jsonl``: seed, win_hi, out_pooled, out_worst, eu11). Per arm: wins at w_catch 0.8-1,
the out-of-arena share pooled over w_catch 0-0.5, each seed's worst single weight, and the EU over 11 preferences,
each a mean over seeds with a bootstrap 95 % CI (10,000 resamples), then the seed values.
"""

from __future__ import annotations

import glob
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np


def ci(values: np.ndarray, rng: np.random.Generator) -> str:
    means = rng.choice(values, (10_000, len(values))).mean(axis=1)
    return f"{values.mean():.3f} [{np.quantile(means, 0.025):.3f}, {np.quantile(means, 0.975):.3f}]"


def seed_row(rec: dict) -> tuple[int, tuple[float, float, float, float]] | None:
    if "win_hi" in rec:  # a reproduction checkpoint's probe
        return rec["seed"], (rec["win_hi"], rec["out_pooled"], rec["out_worst"], rec["eu11"])
    if rec["step"] != 200_000:
        return None
    rates = rec["rates"]
    low = [rates[k]["out"] for k in rates if float(k) <= 0.5 + 1e-9]
    high = [rates[k]["win"] for k in rates if float(k) >= 0.8 - 1e-9]
    return rec["seed"], (float(np.mean(high)), float(np.mean(low)), max(low), rec["eu"])


def main(args: list[str]) -> None:
    arms: dict[str, dict[int, tuple]] = defaultdict(dict)
    for arg in args:
        name, pattern = arg.split("=", 1)
        for path in sorted(glob.glob(pattern)):
            for line in Path(path).read_text().splitlines():
                row = seed_row(json.loads(line))
                if row:
                    arms[name][row[0]] = row[1]
    for name, by_seed in arms.items():
        seeds = sorted(by_seed)
        v = np.array([by_seed[s] for s in seeds])
        rng = np.random.default_rng(0)
        print(f"{name}: seeds {seeds}")
        for k, label in enumerate(("wins, w_catch 0.8-1", "out pooled, w_catch 0-0.5", "worst weight", "EU, 11 prefs")):
            print(f"  {label}: {ci(v[:, k], rng)}  seeds {np.round(v[:, k], 3).tolist()}")


if __name__ == "__main__":
    main(sys.argv[1:])
