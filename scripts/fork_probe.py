"""Train a Deep-Sea-Treasure-family run to a step, then continue copies of it under setting changes.

Which lever stops a late loss of coverage? The same state (weights, optimizer, replay buffer, RNGs) continued
under each change isolates the lever on one seed, where a fresh run per change would differ from the first Polyak
step on (docs/results/target-tau/README.md):

    python scripts/fork_probe.py prep --seed 13 --step 13000 --out runs/fork      # runs/fork/resume-s13-13000.pt
    python scripts/fork_probe.py run runs/fork/resume-s13-13000.pt '{"target_tau": 0.001}' --eval-every 2000

``prep`` trains mope's defaults (``--set KEY=VALUE``, repeated, for others) with ``total_steps`` 20k, so every
schedule is the full run's, and prints the largest Q of a batch so far; ``run`` loads the state with the changes
(any config field) and trains to 20k, printing CR / time-out share at each evaluation and the largest Q of a
batch after the fork (``q_max``, environment units).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from mope.agent.agent import MoPE
from mope.agent.runner import Callback
from mope.config import Config, parse_overrides
from mope.envs import make_env


class LargestQ(Callback):
    """The largest ``q_max`` of the updates seen."""

    def __init__(self) -> None:
        self.value = float("-inf")

    def on_step(self, agent: object, stats: dict[str, float] | None) -> bool:
        if stats and "q_max" in stats:
            self.value = max(self.value, stats["q_max"])
        return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("prep")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--step", type=int, required=True)
    p.add_argument("--out", default="runs/fork")
    p.add_argument("--env", default="deep-sea-treasure-mirrored-v0")
    p.add_argument("--set", action="append", default=[])
    r = sub.add_parser("run")
    r.add_argument("state")
    r.add_argument("changes", nargs="?", default="{}")
    r.add_argument("--eval-every", type=int, default=2000)
    args = ap.parse_args()
    if args.cmd == "prep":
        sets = parse_overrides(args.set)
        config = Config.for_algo("mope", **{"env_id": args.env, "seed": args.seed, "total_steps": 20_000, **sets})
        agent, largest = MoPE(args.env, config), LargestQ()
        agent.train(args.step, callback=largest)
        path = Path(args.out) / f"resume-s{args.seed}-{args.step}.pt"
        agent.save(path, include_buffer=True)
        print(f"saved {path} at step {agent.global_step}; largest q_max so far {largest.value:.1f}")
        return
    changes = json.loads(args.changes)
    agent = MoPE.load(args.state, **changes)
    largest, t0 = LargestQ(), time.perf_counter()
    records = agent.train(agent.config.total_steps - agent.global_step, eval_env=make_env(agent.config.env_id),
                          eval_every=args.eval_every, callback=largest)
    evals = " ".join(f"{int(x['step']) // 1000}k:{x['cr']:.2f}/{x['timeout_share']:.2f}" for x in records)
    print(f"{json.dumps(changes)} {evals} q_max {largest.value:.1f} ({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
