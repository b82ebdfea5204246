"""Run folders: train with logging and checkpoints, evaluate a run or checkpoint, play one episode.

A run folder written by :func:`train_run` (and ``mope train``) holds::

    config.json          the resolved Config (every field, plus the derived algo)
    metrics.csv          one row per evaluation: step, wall_s, cr, precision, recall, hv, eum, eum_optimal,
                         eum_gap, optimal_share, cardinality, timeout_share, loss, epsilon
    solutions.csv        the final evaluation: preference, discounted and undiscounted return per preference
    summary.json         final metrics, wall time, seconds per 1k steps, versions
    tb/                  TensorBoard scalars (metrics and losses)
    checkpoints/         step_<N>.pt every checkpoint_every steps, and final.pt (``MoPE.load`` reads them)
"""

from __future__ import annotations

import csv
import json
import os
import platform
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mope.agent import MoPE
from mope.checkpoint import mope_version
from mope.config import Config
from mope.envs import make_env
from mope.errors import CheckpointError, MopeError
from mope.evaluation import Evaluator, Solutions, solutions
from mope.metrics import EVALUATE_KEYS
from mope.preferences import validate_preference

METRIC_COLUMNS = ["step", "wall_s", *EVALUATE_KEYS, "timeout_share", "loss", "epsilon"]


class RunFolderError(MopeError):
    """The output folder is unusable (exists with results, or is not writable)."""


@dataclass
class RunResult:
    """What :func:`train_run` returns."""

    out_dir: Path
    agent: MoPE
    records: list[dict[str, float]]
    final: dict[str, float]
    wall_s: float


def prepare_out_dir(out_dir: str | Path, overwrite: bool = False) -> Path:
    """Create the run folder; refuse to clobber finished results unless ``overwrite``."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise RunFolderError(f"output path '{out}' exists and is not a folder")
    if (out / "metrics.csv").exists() and not overwrite:
        raise RunFolderError(f"output folder '{out}' already holds a run; choose another --out or pass --overwrite")
    try:
        (out / "checkpoints").mkdir(parents=True, exist_ok=True)
        probe = out / ".write_test"
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        raise RunFolderError(f"output folder '{out}' is not writable: {exc.strerror or exc}") from None
    return out


def write_solutions(path: str | Path, sols: Solutions) -> None:
    """Write one row per preference: ``w_i..., disc_i..., ret_i..., length, terminated``."""
    m = sols.prefs.shape[1]
    header = ([f"w{i}" for i in range(m)] + [f"disc{i}" for i in range(m)] + [f"ret{i}" for i in range(m)]
              + ["length", "terminated"])
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for row in zip(sols.prefs, sols.discounted, sols.returns, sols.lengths, sols.terminated, strict=True):
            w.writerow([*(f"{x:.6g}" for x in row[0]), *(f"{x:.6g}" for x in row[1]), *(f"{x:.6g}" for x in row[2]),
                        int(row[3]), int(row[4])])


def read_metrics(run_dir: str | Path) -> list[dict[str, float]]:
    """Rows of a run's ``metrics.csv`` as floats."""
    path = Path(run_dir) / "metrics.csv"
    if not path.is_file():
        raise RunFolderError(f"'{run_dir}' has no metrics.csv; is it a mope run folder?")
    with open(path) as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def _environment_info() -> dict[str, Any]:
    return {"mope": mope_version(), "torch": torch.__version__, "numpy": np.__version__,
            "python": platform.python_version(), "machine": platform.machine(), "cpus": os.cpu_count()}


def train_run(config: Config, out_dir: str | Path, progress: bool = True, overwrite: bool = False) -> RunResult:
    """Train one agent and write a complete run folder (see the module docstring).

    Ctrl-C (SIGINT) or SIGTERM stops training at the next step boundary, saves ``checkpoints/interrupted.pt``
    (with the replay buffer) and raises ``KeyboardInterrupt``, so no finished evaluation or trained weights
    are lost.
    """
    from torch.utils.tensorboard import SummaryWriter

    out = prepare_out_dir(out_dir, overwrite)
    config.save(out / "config.json")
    agent = MoPE(config.env_id, config)
    eval_env = make_env(config.env_id, config.max_episode_steps)
    writer = SummaryWriter(str(out / "tb"))
    metrics_file = open(out / "metrics.csv", "w", newline="")  # noqa: SIM115 - closed in finally
    csv_writer = csv.DictWriter(metrics_file, fieldnames=METRIC_COLUMNS, extrasaction="ignore")
    csv_writer.writeheader()
    last_ckpt = [0]

    def on_eval(ag: MoPE, rec: dict[str, float]) -> None:
        rec.update(loss=ag.last_losses.get("loss", float("nan")), epsilon=ag.epsilon)
        csv_writer.writerow({k: rec.get(k, float("nan")) for k in METRIC_COLUMNS})
        metrics_file.flush()
        for k in METRIC_COLUMNS[2:]:
            writer.add_scalar(f"eval/{k}", rec[k], ag.global_step)
        for k, v in ag.last_losses.items():
            writer.add_scalar(f"train/{k}", v, ag.global_step)
        if config.checkpoint_every and ag.global_step - last_ckpt[0] >= config.checkpoint_every:
            ag.save(out / "checkpoints" / f"step_{ag.global_step}.pt")
            last_ckpt[0] = ag.global_step

    # SIGINT/SIGTERM set a flag that the training loop polls at each step boundary, so the interruption never
    # lands inside torch, the CSV writer or TensorBoard's writer thread.
    received: list[int] = []
    handlers = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            handlers[sig] = signal.signal(sig, lambda signum, frame: received.append(signum))
    t0 = time.perf_counter()
    try:
        records = agent.train(config.total_steps, eval_env=eval_env, callback=on_eval, progress=progress,
                              stop=lambda: bool(received))
    finally:
        for sig, old_handler in handlers.items():
            signal.signal(sig, old_handler)
        metrics_file.close()
        writer.close()
    if received:
        agent.save(out / "checkpoints" / "interrupted.pt", include_buffer=True)
        raise KeyboardInterrupt(f"stopped by signal {received[0]} at step {agent.global_step}")
    wall = time.perf_counter() - t0
    agent.save(out / "checkpoints" / "final.pt")
    final = records[-1] if records else {}
    write_solutions(out / "solutions.csv", agent.last_solutions)  # the final evaluation's solutions
    summary = {"final": final, "wall_s": wall, "s_per_1k_steps": 1000 * wall / config.total_steps,
               "algo": config.algo, "env_id": config.env_id, "seed": config.seed, "versions": _environment_info()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return RunResult(out, agent, records, final, wall)


def resolve_checkpoint(path: str | Path) -> Path:
    """A checkpoint file, or the ``checkpoints/final.pt`` (else the newest ``step_*.pt``) of a run folder."""
    p = Path(path)
    if p.is_dir():
        final = p / "checkpoints" / "final.pt"
        if final.is_file():
            return final
        steps = sorted((p / "checkpoints").glob("step_*.pt"), key=lambda q: int(q.stem.split("_")[1]))
        if steps:
            return steps[-1]
        raise CheckpointError(f"run folder '{p}' has no checkpoint in checkpoints/")
    if not p.exists():
        raise CheckpointError(f"'{p}' is neither a checkpoint file nor a run folder")
    return p


def evaluate_checkpoint(path: str | Path, n_prefs: int = 2000, seed: int | None = None,
                        out: str | Path | None = None) -> tuple[dict[str, float], Solutions]:
    """Evaluate a checkpoint (or a run's final checkpoint) with the CR protocol; optionally write solutions."""
    if n_prefs < 1:
        raise MopeError(f"--prefs {n_prefs} is out of range: must be >= 1")
    agent = MoPE.load(resolve_checkpoint(path))
    c = agent.config
    evaluator = Evaluator(agent.env, c.env_id, c.gamma, n_prefs, c.seed if seed is None else seed,
                          c.max_episode_steps, c.ref_point)
    res, sols = evaluator.evaluate(agent)
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        write_solutions(out, sols)
    return res, sols


def play(path: str | Path, pref: Any) -> Solutions:
    """Play one greedy episode of a checkpoint under ``pref``; return its :class:`Solutions` (one row)."""
    agent = MoPE.load(resolve_checkpoint(path))
    w = validate_preference(pref, agent.m)
    return solutions(agent, agent.env, w[None], agent.config.gamma, agent.config.max_episode_steps)
