"""Speed of vectorised collection: seconds per 1k env steps and steps per second, defaults beside vectorised
settings, on Deep-Sea-Treasure and the robot game, with peak memory (issue: fast training).

Usage::

    .venv/bin/python benchmarks/bench_vector.py [--steps 4000] [--out benchmarks/results/vector.md]

Each setting is one fresh process-local agent (one torch thread) warmed up for 2,000 env steps (past
``learning_starts``), then timed over ``--steps`` env steps without evaluation. Every row is measured in the same
run on the same machine, and each is reported as a ratio to the defaults (``n_envs = 1, train_freq = 1``) of its
environment. The bare update (one ``MoPE.update`` call: sample, relabel, target, loss, backward, Adam, priorities,
discriminator) is timed too, so the per-step overhead over it is visible. Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import torch

from mope import MoPE
from mope.envs import confrontation as C

#: The first setting of each env is its one-env baseline (the game's per-environment defaults already set 4 envs and
#: demonstrations, so its baseline names one env and no demonstrations).
ONE_ENV_GAME = {"n_envs": 1, "demos": "", "demo_batch_share": 0.0}
SETTINGS: dict[str, list[dict[str, object]]] = {
    "deep-sea-treasure-v0": [{}, {"n_envs": 4}, {"n_envs": 8, "train_freq": 1}, {"n_envs": 8, "train_freq": 4}],
    C.DISCRETE_ID: [ONE_ENV_GAME, {**ONE_ENV_GAME, "n_envs": 8}, {}, {**ONE_ENV_GAME, "n_envs": 16}],
}


def time_setting(env_id: str, overrides: dict[str, object], steps: int) -> tuple[float, float]:
    """Seconds per 1k env steps of training, and seconds per bare update."""
    agent = MoPE(env_id, seed=0, total_steps=100_000, **overrides)
    agent.train(2_000)
    t0 = time.perf_counter()
    agent.train(steps)
    per_1k = (time.perf_counter() - t0) / steps * 1000
    t0 = time.perf_counter()
    for _ in range(200):
        agent.update()
    return per_1k, (time.perf_counter() - t0) / 200


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4_000)
    parser.add_argument("--out", default="benchmarks/results/vector.md")
    args = parser.parse_args()
    torch.set_num_threads(1)
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), "unknown CPU")
    lines = [f"Machine: {cpu}, torch {torch.__version__} (1 thread). Command: "
             f"`.venv/bin/python benchmarks/bench_vector.py --steps {args.steps}`", "",
             "| environment | setting | s / 1k env steps | env steps / s | ratio to the defaults | bare update (ms) "
             "| 200k env steps (min) |", "|---|---|---:|---:|---:|---:|---:|"]
    for env_id, settings in SETTINGS.items():
        base = None
        for overrides in settings:
            per_1k, update_s = time_setting(env_id, overrides, args.steps)
            base = base or per_1k
            name = ", ".join(f"{k}={v!r}" for k, v in overrides.items()) or "the env's defaults"
            lines.append(f"| {env_id} | {name} | {per_1k:.2f} | {1000 / per_1k:.0f} | {base / per_1k:.2f}x "
                         f"| {update_s * 1000:.2f} | {per_1k * 200 / 60:.1f} |")
            print(lines[-1], flush=True)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    lines += ["", f"Peak resident memory of the whole benchmark process: {peak:.0f} MiB."]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
