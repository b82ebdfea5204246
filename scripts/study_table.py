"""A compact markdown table of a `mope report` (report.json): the columns the learning study is read by.

    python scripts/study_table.py docs/results/learning-study/report.json [--order default,paper,...]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path


def cell(stats: dict, fmt: str) -> str:
    if not stats or stats.get("n", 0) == 0 or stats.get("mean") is None:
        return "n/a"
    return f"{stats['mean']:{fmt}} [{stats['ci_low']:{fmt}}, {stats['ci_high']:{fmt}}]"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("report", type=Path)
    p.add_argument("--order", default=None, help="comma-separated group labels, in the order to show")
    a = p.parse_args()
    doc = json.loads(a.report.read_text())
    groups = {g["label"]: g for g in doc["groups"]}
    order = a.order.split(",") if a.order else list(groups)
    print("| arm | seeds | CR | optimal share | path error | overestimate at s0 | time-outs | seeds at CR = 1 | "
          "first step at CR = 1 (median) | best CR - final CR |")
    print("|---|---:|---|---|---|---|---|---:|---:|---|")
    for label in order:
        g = groups[label]
        s = g["stats"]
        cov = g.get("coverage", {})
        firsts = cov.get("first_cr1", [])
        med = cov.get("median_first_cr1")
        reached = sum(f is not None for f in firsts)
        first = "never" if med is None or (isinstance(med, float) and math.isinf(med)) else f"{med:,.0f}"
        print(f"| {label} | {len(g['runs'])} | {cell(s.get('cr'), '.3f')} | {cell(s.get('optimal_share'), '.3f')} | "
              f"{cell(s.get('path_error'), '.4f')} | "
              f"{cell(s.get('overestimation'), '.3f')} | {cell(s.get('timeout_share'), '.3f')} | "
              f"{reached}/{len(firsts)} | "
              f"{first} | {cell(cov.get('cr_drop'), '.3f')} |")


if __name__ == "__main__":
    main()
