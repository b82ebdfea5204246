"""The update's cost before and after a change: ms per training step (DST defaults, one env) and per bare update,
for two source trees measured alternately in the same run, with the dense layers' FLOP floor (issue: fast training).

Usage::

    .venv/bin/python benchmarks/bench_update.py --before /path/to/old/checkout [--rounds 3] [--steps 1000] \\
        [--out benchmarks/results/update.md]

``--before`` is another checkout of mope (for example ``git worktree add /tmp/old <commit>``); its ``src`` is put
first on ``PYTHONPATH`` of a child process. Each round times the old tree, then this one, each in a fresh process
(one torch thread): ``agent.train(1500)`` to warm up past ``learning_starts``, then ``--steps`` training steps
without evaluation (ms per step), then 300 bare ``update()`` calls (ms per update). The table gives the median
over rounds and the ratio of the two trees, so a loaded machine moves both alike.

The FLOP floor: the Q-network's dense layers for one update are one forward pass with gradient over the batch
(B = 128), its backward (twice the forward's FLOPs), and two forward passes without gradient (online and target
network at the next states): 5 forward passes. Divided by this machine's measured single-thread matmul rate on
the same layer shapes, that is the time no implementation of this update can go below on one core.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

CHILD = r"""
import json, resource, time, torch
from mope import make_agent
torch.set_num_threads(1)
agent = make_agent("mope", "deep-sea-treasure-v0", seed=0, eval_every=0, checkpoint_every=0, total_steps=100_000)
agent.train(1500)
t0 = time.perf_counter(); agent.train(STEPS); step = (time.perf_counter() - t0) / STEPS * 1e3
t0 = time.perf_counter()
for _ in range(300):
    agent.update()
upd = (time.perf_counter() - t0) / 300 * 1e3
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"step_ms": step, "update_ms": upd, "peak_mib": peak}))
"""


def child(src: Path, steps: int) -> dict[str, float]:
    env = {**os.environ, "PYTHONPATH": str(src)}
    out = subprocess.run([sys.executable, "-c", CHILD.replace("STEPS", str(steps))], env=env, check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def flop_floor_ms(batch: int = 128, hidden: int = 256, n_in: int = 24, n_out: int = 96,
                  repeats: int = 300) -> tuple[float, float]:
    """(GFLOP/s of single-thread matmuls on the Q-network's layer shapes, the update's floor in ms)."""
    import torch

    torch.set_num_threads(1)
    dims = [(n_in, hidden), (hidden, hidden), (hidden, hidden), (hidden, n_out)]
    xs = [torch.randn(batch, i) for i, _ in dims]
    ws = [torch.randn(i, o) for i, o in dims]
    flops = sum(2 * batch * i * o for i, o in dims)
    for x, w in zip(xs, ws, strict=True):
        x @ w
    t0 = time.perf_counter()
    for _ in range(repeats):
        for x, w in zip(xs, ws, strict=True):
            x @ w
    per_pass = (time.perf_counter() - t0) / repeats
    return flops / per_pass / 1e9, 5 * flops / (flops / per_pass) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", type=Path, required=True)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    here = Path(__file__).resolve().parents[1] / "src"
    res: dict[str, list[dict[str, float]]] = {"before": [], "after": []}
    for _ in range(args.rounds):
        res["before"].append(child(args.before / "src", args.steps))
        res["after"].append(child(here, args.steps))
    med = {k: {m: statistics.median(r.get(m, float("nan")) for r in v) for m in ("step_ms", "update_ms", "peak_mib")}
           for k, v in res.items()}
    rate, floor = flop_floor_ms()
    lines = [f"Command: `.venv/bin/python benchmarks/bench_update.py --before {args.before} --rounds {args.rounds} "
             f"--steps {args.steps}`", "",
             "| tree | ms per training step (DST defaults) | ms per bare update | step / floor | update / floor "
             "| peak MiB (process) |",
             "|---|---:|---:|---:|---:|---:|"]
    for k in ("before", "after"):
        lines.append(f"| {k} | {med[k]['step_ms']:.2f} | {med[k]['update_ms']:.2f} | "
                     f"{med[k]['step_ms'] / floor:.1f}x | {med[k]['update_ms'] / floor:.1f}x | "
                     f"{med[k]['peak_mib']:.0f} |")
    lines += ["", f"after / before: {med['after']['step_ms'] / med['before']['step_ms']:.2f}x per step, "
              f"{med['after']['update_ms'] / med['before']['update_ms']:.2f}x per update (median of {args.rounds} "
              f"alternating rounds). Dense-layer floor: {floor:.2f} ms per update (5 passes of B = 128 at "
              f"{rate:.0f} GFLOP/s, one thread).",
              "", "Every round: " + "; ".join(f"{k} {[round(r['step_ms'], 2) for r in v]} ms/step "
                                              f"{[round(r['update_ms'], 2) for r in v]} ms/update"
                                              for k, v in res.items())]
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
