"""Speed benchmark: seconds per 1k training steps and seconds per 2,000-preference evaluation on Deep-Sea-Treasure.

Usage::

    .venv/bin/python benchmarks/bench_speed.py [--steps 1000] [--repeats 3] [--out benchmarks/results/speed.md]
        [--variant n_step=5 ...]

It warms each agent up past ``learning_starts`` (so every timed step includes a gradient update), then times
``--steps`` training steps, ``--repeats`` times, and reports the median. The evaluation is timed on the same
agent with the paper's protocol (2,000 uniform preferences plus 100 equally spaced ones for EUM). Each
``--variant KEY=VALUE[,KEY=VALUE]`` times mope with those settings in the same run, reported as a ratio to the
default mope. The machine
(CPU model, cores, torch threads, versions) is printed with the table. Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import torch

import mope
from mope import Evaluator, MoPE, make_env
from mope.config import parse_overrides


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo, else the platform string."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def median_seconds(fn, repeats: int) -> float:
    """Median wall seconds of ``repeats`` calls of ``fn``."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def time_training(algo: str, steps: int, repeats: int, **overrides) -> float:
    """Median seconds per ``steps`` training steps (after a warm-up that fills the buffer)."""
    agent = mope.make_agent(algo, "deep-sea-treasure-v0", seed=0, **overrides)
    agent.train(agent.config.learning_starts + 100)
    return median_seconds(lambda: agent.train(steps), repeats)


def time_evaluation(repeats: int) -> float:
    """Median seconds for one 2,000-preference evaluation."""
    agent = mope.make_agent("eql", "deep-sea-treasure-v0", seed=0)
    agent.train(500)
    evaluator = Evaluator(make_env("deep-sea-treasure-v0"), "deep-sea-treasure-v0", n_prefs=2000)
    evaluator.evaluate(agent)  # warm-up
    return median_seconds(lambda: evaluator.evaluate(agent), repeats)


def time_checkpoint_evaluation(path: str, repeats: int) -> tuple[float, float, float]:
    """(seconds with loops closed, seconds with loops stepped, time-out share) of a trained agent's evaluation."""
    agent = MoPE.load(path)
    evaluator = Evaluator(agent.env, agent.config.env_id, n_prefs=2000)
    res, _ = evaluator.evaluate(agent)  # warm-up
    closed = median_seconds(lambda: evaluator.evaluate(agent), repeats)
    evaluator.close_loops = False
    stepped = median_seconds(lambda: evaluator.evaluate(agent), repeats)
    return closed, stepped, res["timeout_share"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--checkpoint", default=None,
                        help="also time the evaluation of this trained agent (loops closed and stepped)")
    parser.add_argument("--eval-only", action="store_true", help="skip the training timings")
    parser.add_argument("--variant", action="append", default=[],
                        help="KEY=VALUE[,KEY=VALUE]: also time mope with these settings (repeatable)")
    args = parser.parse_args()

    rows = []
    ratio = None
    if not args.eval_only:
        for algo in ("eql", "mope"):
            s = time_training(algo, args.steps, args.repeats)
            rows.append((f"`{algo}` training, the defaults", s * 1000 / args.steps, "s / 1k steps"))
        ratio = rows[1][1] / rows[0][1]
        for spec in args.variant:
            overrides = parse_overrides(spec.split(","))
            s = time_training("mope", args.steps, args.repeats, **overrides) * 1000 / args.steps
            rows.append((f"`mope` training, {spec}", s, "s / 1k steps"))
            rows.append((f"ratio `mope` {spec} / `mope` defaults per step", s / rows[1][1], ""))
    ev = time_evaluation(args.repeats)
    rows.append(("one evaluation, 2,000 uniform + 100 equally spaced preferences (agent after 500 steps)", ev, "s"))
    if args.checkpoint:
        closed, stepped, timeouts = time_checkpoint_evaluation(args.checkpoint, args.repeats)
        rows.append((f"one evaluation of `{args.checkpoint}` ({timeouts:.0%} of preferences loop), loops closed",
                     closed, "s"))
        rows.append(("the same, loops stepped to the time limit (before the change)", stepped, "s"))

    lines = [
        f"Machine: {cpu_model()}, {os.cpu_count()} cores, torch {torch.__version__} "
        f"({torch.get_num_threads()} threads), Python {platform.python_version()}",
        "",
        "| what | value | unit |",
        "|---|---:|---|",
        *[f"| {name} | {value:.3f} | {unit} |" for name, value, unit in rows],
    ]
    if ratio is not None:
        lines.append(f"| ratio mope / eql per step | {ratio:.2f} | |")
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
