"""Time one evaluation on the Robot Confrontation Game: 100 preferences x 5 episodes, batched game vs one Python
environment per episode (issue 14's target: <= 5 s).

    .venv/bin/python benchmarks/bench_confrontation_eval.py [--prefs 100] [--episodes 5] [--repeats 3] [--out FILE]

The agent is an untrained MoPE agent of ``mope/RobotConfrontationDiscrete-v0`` (the cost of an evaluation does not
depend on what the weights are, only on how long the games last: an untrained red loses or leaves the arena in
most games, a trained one plays longer, so the time-limit-only case is measured too). Prints the table; with
``--out benchmarks/results/confrontation-eval.md`` it also writes the committed one (a quick run with other settings
no longer overwrites it).
"""

from __future__ import annotations

import argparse
import os
import platform
from pathlib import Path

import mo_gymnasium as mo_gym
import numpy as np
from bench_speed import median_seconds  # benchmarks/, the script's own folder

import mope
import mope.envs.confrontation as conf
from mope.paper.ppo import play_episodes
from mope.preferences import equally_spaced


class _NoBatch:
    """Hides the game from the batched path (the wrapper is not one the batch knows), as before issue 14."""

    def __init__(self, env: object) -> None:
        self.env = env

    @property
    def unwrapped(self) -> _NoBatch:
        return self

    def __getattr__(self, name: str) -> object:
        return getattr(self.env, name)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--prefs", type=int, default=100)
    p.add_argument("--episodes", type=int, default=5)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--out", type=Path, default=None,
                   help="also write the table here (the committed one: benchmarks/results/confrontation-eval.md)")
    a = p.parse_args()
    agent = mope.MoPE(conf.DISCRETE_ID, seed=0)
    w = np.repeat(equally_spaced(2, a.prefs), a.episodes, axis=0)
    seeds = [10_000 + j for _ in range(a.prefs) for j in range(a.episodes)]

    def policy(obs: np.ndarray, idx: np.ndarray) -> np.ndarray:
        return agent.greedy_actions(obs, w[idx])

    def coast(obs: np.ndarray, idx: np.ndarray) -> np.ndarray:  # a = 0, w = 0: games run to the time limit more
        return np.full(len(idx), 7)

    rows = []
    n = len(seeds)

    def batched_env() -> object:
        return mo_gym.make(conf.DISCRETE_ID).unwrapped

    def single_env() -> object:
        return _NoBatch(mo_gym.make(conf.DISCRETE_ID).unwrapped)

    for label, pol in (("untrained MoPE agent", policy), ("coasting red (long games)", coast)):
        batched = median_seconds(lambda pol=pol: play_episodes(pol, batched_env, n, seeds, 150), a.repeats)
        single = median_seconds(lambda pol=pol: play_episodes(pol, single_env, n, seeds, 150), 1)
        eps = play_episodes(pol, batched_env, n, seeds, 150)
        rows.append(f"| {label} | {a.prefs} x {a.episodes} | {np.mean(eps.lengths):.0f} | {batched:.2f} | "
                    f"{single:.2f} | {single / batched:.0f}x |")
    text = "\n".join([
        f"One evaluation on `{conf.DISCRETE_ID}` ({platform.processor() or platform.machine()}, "
        f"{platform.python_version()}, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs): median of "
        f"{a.repeats} for the batched game, one run for the loop over one environment per episode.", "",
        "| policy | prefs x episodes | mean length | batched game, s | one env per episode, s | speed-up |",
        "|---|---|---:|---:|---:|---:|", *rows, "",
        f"Command: `python benchmarks/bench_confrontation_eval.py --prefs {a.prefs} --episodes {a.episodes} "
        f"--repeats {a.repeats}" + (f" --out {a.out}`" if a.out else "`")])
    print(text)
    if a.out:
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
