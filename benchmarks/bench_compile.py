"""Does ``torch.compile`` make the update cheaper? The bare update (DST defaults, one env) in eager torch against two
compiled variants, each in a fresh process, alternated over rounds (issue: fast training).

Usage::

    .venv/bin/python benchmarks/bench_compile.py [--rounds 3] [--updates 300] [--out benchmarks/results/compile.md]
    .venv/bin/python benchmarks/bench_compile.py --ops     # where an eager update's time goes, by aten operator

Variants:

* ``eager``: mope as it is;
* ``target``: the envelope target's arithmetic (:meth:`ConvexQNetwork.double_q_values`) compiled by
  ``torch.compile(dynamic=False)``;
* ``target+mlp``: that, and both Q-networks' MLPs compiled too (forward and, for the online one, backward).

Each process warms up the agent with ``agent.train(1500)``, then runs 30 untimed updates (the compilation happens
there, and its seconds are reported), then ``--updates`` timed ``agent.update()`` calls. The loss and the priorities
are not compared: a compiled kernel may round differently, so a compiled update would change the training stream.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
from pathlib import Path

CHILD = r"""
import json, time, torch
torch.set_num_threads(1)
from mope import make_agent
from mope.agent.networks import ConvexQNetwork
agent = make_agent("mope", "deep-sea-treasure-v0", seed=0, eval_every=0, checkpoint_every=0, total_steps=100_000)
agent.train(1500)
if "VARIANT" != "eager":
    ConvexQNetwork.double_q_values = staticmethod(torch.compile(ConvexQNetwork.double_q_values, dynamic=False))
if "VARIANT" == "target+mlp":
    agent.q_net.net = torch.compile(agent.q_net.net, dynamic=False)
    agent.target_net.net = torch.compile(agent.target_net.net, dynamic=False)
t0 = time.perf_counter()
for _ in range(30):
    agent.update()
warm = time.perf_counter() - t0
t0 = time.perf_counter()
for _ in range(UPDATES):
    agent.update()
print(json.dumps({"update_ms": (time.perf_counter() - t0) / UPDATES * 1e3, "warm_s": warm}))
"""
VARIANTS = ("eager", "target", "target+mlp")

OPS = r"""
import torch
from torch.profiler import ProfilerActivity, profile
torch.set_num_threads(1)
from mope import make_agent
agent = make_agent("mope", "deep-sea-treasure-v0", seed=0, eval_every=0, checkpoint_every=0, total_steps=100_000)
agent.train(1500)
with profile(activities=[ProfilerActivity.CPU]) as prof:
    for _ in range(50):
        agent.update()
ev = prof.key_averages()
calls = sum(e.count for e in ev if e.key.startswith("aten::")) / 50
dense = sum(e.self_cpu_time_total for e in ev if e.key in ("aten::addmm", "aten::mm", "aten::bmm")) / 50
total = sum(e.self_cpu_time_total for e in ev) / 50
print(f"aten calls per update: {calls:.0f}; matmuls (addmm, mm, bmm): {dense:.0f} of {total:.0f} us self time")
for e in sorted(ev, key=lambda e: -e.self_cpu_time_total)[:12]:
    print(f"  {e.key:50s} {e.count / 50:6.1f} calls {e.self_cpu_time_total / 50:8.1f} us")
"""


def child(variant: str, updates: int) -> dict[str, float]:
    code = CHILD.replace("VARIANT", variant).replace("UPDATES", str(updates))
    out = subprocess.run([sys.executable, "-c", code], env=dict(os.environ), check=True, capture_output=True,
                         text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--updates", type=int, default=300)
    parser.add_argument("--out", type=Path, default=None, help="append the table to this markdown file")
    parser.add_argument("--ops", action="store_true", help="profile 50 eager updates by operator instead")
    args = parser.parse_args()
    if args.ops:
        subprocess.run([sys.executable, "-c", OPS], check=True)
        return
    runs: dict[str, list[dict[str, float]]] = {v: [] for v in VARIANTS}
    for r in range(args.rounds):
        for v in VARIANTS:
            runs[v].append(child(v, args.updates))
            print(f"round {r}: {v} {runs[v][-1]['update_ms']:.2f} ms per update", flush=True)
    eager = statistics.median(x["update_ms"] for x in runs["eager"])
    lines = [f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, one torch thread. "
             f"Command: `.venv/bin/python benchmarks/bench_compile.py --rounds {args.rounds} --updates "
             f"{args.updates}`", "",
             "| variant | ms per update (median) | every round | x eager | compile s (first 30 updates) |",
             "|---|---:|---|---:|---:|"]
    for v in VARIANTS:
        ms = [x["update_ms"] for x in runs[v]]
        med = statistics.median(ms)
        lines.append(f"| {v} | {med:.2f} | {', '.join(f'{x:.2f}' for x in ms)} | {med / eager:.2f}x | "
                     f"{statistics.median(x['warm_s'] for x in runs[v]):.1f} |")
    text = "\n".join(lines)
    print(text)
    if args.out:
        with args.out.open("a") as f:
            f.write("\n" + text + "\n")


if __name__ == "__main__":
    main()
