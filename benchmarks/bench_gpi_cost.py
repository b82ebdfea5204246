"""What morl-baselines' GPI-LS would cost in ``mope benchmark``, against its Envelope in the same run.

The benchmark issue asks for GPI-LS (Alegre et al. 2023) beside Envelope "only if its measured cost fits". This
script times both at their constructor defaults (``gamma=0.99``, ``log=False``) on Deep-Sea-Treasure, one torch
thread, in this process, one after the other: each trains ``--warmup`` steps, then ``--steps`` timed steps.
GPI-LS makes one gradient update per step until ``dynamics_rollout_starts`` (5,000 steps, also without a
model), then ``gradient_updates`` (20), so its warm-up must pass 5,000 steps to time the rate of the rest of a
run. It trains through ``train_iteration`` under a support of two weights, the extremes (with more than one it
trains on each batch twice, once under a support weight); the linear-support search between iterations and its
evaluations are left out: they only add time. It prints seconds per 1k env steps, the ratio, and what the
benchmark's budgets (``BENCH_ENVS``: 220k env steps per seed) would take for 3 seeds at that rate on this
machine. Run from the ``bench`` environment::

    WANDB_MODE=disabled .venv-bench/bin/python benchmarks/bench_gpi_cost.py --steps 200 \\
        --out benchmarks/results/gpi-cost.md
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np
import torch


def _env():  # noqa: ANN202 - a Gymnasium env
    import mo_gymnasium as mo_gym
    from mo_gymnasium.wrappers import MORecordEpisodeStatistics

    return MORecordEpisodeStatistics(mo_gym.make("deep-sea-treasure-v0"), gamma=0.99)


def time_gpi_ls(warmup: int, steps: int, seed: int) -> float:
    """Seconds per env step of GPI-LS's training loop (its default 20 gradient updates per step)."""
    from morl_baselines.multi_policy.gpi_pd.gpi_pd import GPILS

    agent = GPILS(_env(), gamma=0.99, log=False, seed=seed)
    support = [np.array([1.0, 0.0], dtype=np.float32), np.array([0.0, 1.0], dtype=np.float32)]
    w = np.array([0.5, 0.5], dtype=np.float32)
    agent.train_iteration(warmup, weight=w, weight_support=support, reset_num_timesteps=True)
    start = time.perf_counter()
    agent.train_iteration(steps, weight=w, weight_support=support, reset_num_timesteps=False)
    return (time.perf_counter() - start) / steps


def time_envelope(warmup: int, steps: int, seed: int) -> float:
    """Seconds per env step of Envelope's training loop at its constructor defaults."""
    from morl_baselines.multi_policy.envelope.envelope import Envelope

    env = _env()
    agent = Envelope(env, gamma=0.99, log=False, seed=seed)
    agent.train(total_timesteps=warmup, eval_env=_env(), ref_point=np.array([0.0, -25.0]), eval_freq=10**9,
                reset_num_timesteps=True)
    start = time.perf_counter()
    agent.train(total_timesteps=steps, eval_env=_env(), ref_point=np.array([0.0, -25.0]), eval_freq=10**9,
                reset_num_timesteps=False)
    return (time.perf_counter() - start) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--warmup", type=int, default=5_100)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    envelope = time_envelope(min(args.warmup, 300), args.steps, args.seed)
    gpi = time_gpi_ls(args.warmup, args.steps, args.seed)
    budget = 220_000 * 3  # BENCH_ENVS' budgets (20k + 50k + 100k + 50k) x 3 seeds
    lines = [
        f"Machine: {platform.processor() or platform.machine()}, torch {torch.__version__}, one thread. Command: "
        f"`WANDB_MODE=disabled .venv-bench/bin/python benchmarks/bench_gpi_cost.py --warmup {args.warmup} "
        f"--steps {args.steps}`",
        "",
        "| method (constructor defaults, deep-sea-treasure-v0) | s per 1k env steps | ratio to Envelope | "
        "3 seeds x 220k env steps (hours) |",
        "|---|---:|---:|---:|",
        f"| Envelope | {1000 * envelope:.1f} | 1.00x | {budget * envelope / 3600:.1f} |",
        f"| GPI-LS (after its first 5,000 steps: 20 gradient updates per step, 2 networks) | {1000 * gpi:.1f} | "
        f"{gpi / envelope:.1f}x | {budget * gpi / 3600:.1f} |",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
