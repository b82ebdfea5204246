"""One arm of the robot-game study: train on the discrete game, probe it on the common starts every few steps.

Usage::

    .venv/bin/python scripts/game_study.py --steps 30000 --every 10000 --seed 0 --algo mope \\
        --set n_envs=8 --out docs/results/game-study/ARM-s0.jsonl

Each probe line (JSON): step, wall seconds of training so far, outcome rates at w_catch in {1, 0.9, 0.8, 0.7,
0.5, 0.3, 0} over 100 common starts (greedy play), and the mean discounted EU over 21 preferences beside the
reference policies' upper envelope (:mod:`mope.evaluation.game_probe`). The final weights go beside it (``.pt``).

Forking an arm (two arms that differ only after a step share their run up to it)::

    ... --seed 0 --save-state-at 100000 --out A-s0.jsonl       # also writes A-s0.100000.pt (the whole state)
    ... --seed 0 --resume A-s0.100000.pt --set target_tau_end=0.0001 --out B-s0.jsonl

``--resume`` loads the whole training state (weights, optimizers, replay buffer, episodes in progress, RNGs) with
``--set`` as changes and continues to ``--steps``; its first line is the resumed state's own probe, so the file
holds the same steps as a fresh arm's.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch

from mope import make_agent
from mope.agent.agent import MoPE
from mope.config import parse_overrides
from mope.envs import confrontation as C
from mope.evaluation.game_probe import probe

parser = argparse.ArgumentParser()
parser.add_argument("--steps", type=int, default=30_000)
parser.add_argument("--every", type=int, default=10_000)
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--algo", default="mope")
parser.add_argument("--set", nargs="*", default=[])
parser.add_argument("--out", required=True)
parser.add_argument("--save-state-at", type=int, default=None, help="also save the whole state after this probe")
parser.add_argument("--resume", default=None, help="continue a state saved by --save-state-at (--set: changes)")
args = parser.parse_args()
if args.save_state_at is not None and (args.save_state_at % args.every or not 0 < args.save_state_at <= args.steps):
    parser.error(f"--save-state-at {args.save_state_at} must be a probe step: a multiple of --every {args.every} "
                 f"in (0, --steps {args.steps}]")

torch.set_num_threads(1)
overrides = parse_overrides(args.set)
if args.resume:
    agent = MoPE.load(args.resume, **overrides)
    if agent.config.total_steps != args.steps:
        parser.error(f"--steps {args.steps} must be the saved run's budget, {agent.config.total_steps} (its "
                     "schedules use it)")
else:
    agent = make_agent(args.algo, C.DISCRETE_ID, seed=args.seed, total_steps=args.steps, **overrides)
out = Path(args.out)
out.parent.mkdir(parents=True, exist_ok=True)


def record(f: object, train_s: float) -> None:
    """Probe the agent, write its line, print a summary, and save the whole state at ``--save-state-at``."""
    res = probe(agent)
    line = {"step": agent.global_step, "train_s": round(train_s, 1), "algo": args.algo, "seed": args.seed,
            "set": args.set, **res}
    f.write(json.dumps(line) + "\n")
    f.flush()
    r = res["rates"]
    print(f"step {agent.global_step} {train_s:.0f}s win@1/.9/.8/.7 "
          + "/".join(f"{r[w]['win']:.2f}" for w in (1.0, 0.9, 0.8, 0.7))
          + " out@.5/.3/0 " + "/".join(f"{r[w]['out']:.2f}" for w in (0.5, 0.3, 0.0))
          + f" EU {res['eu']:.3f} (refs {res['eu_references']:.3f})", flush=True)
    if agent.global_step == args.save_state_at:
        agent.save(out.with_suffix(f".{args.save_state_at}.pt"), include_buffer=True)


train_s = 0.0
with out.open("w") as f:
    if args.resume:  # the resumed state's own probe first, so the file holds the same steps as a fresh arm's
        record(f, train_s)
    while agent.global_step < args.steps:
        t0 = time.perf_counter()
        agent.train(min(args.every, args.steps - agent.global_step))
        train_s += time.perf_counter() - t0
        record(f, train_s)
agent.save(out.with_suffix(".pt"))  # the final weights, for later probes (not committed: a few MB)
