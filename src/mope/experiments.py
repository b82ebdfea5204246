"""Run folders: train with logging and checkpoints, evaluate a run or checkpoint, play one episode.

A run folder written by :func:`train_run` (and ``mope train``) holds::

    config.json          the resolved Config (every field, plus the derived algo)
    metrics.csv          one row per evaluation: step, wall_s, cr, precision, recall, hv, eum, eum_optimal,
                         eum_gap, optimal_share, cardinality, timeout_share, path_error, state_error,
                         overestimation (against the exact Q* where the dynamics are known, else NaN), loss, epsilon,
                         win_share, loss_share, out_share (episode outcomes where the environment reports them:
                         the confrontation game), train_s (wall_s without the evaluations)
    train_stats.csv      every log_every steps: the mean of each update statistic over those steps (loss,
                         loss_a, loss_b, td_abs, q_mean, q_max, mi_bonus, disc_loss) and epsilon
    solutions.csv        the final evaluation: preference, discounted and undiscounted return per preference
    summary.json         final metrics, wall time, seconds per 1k steps, versions
    tb/                  TensorBoard scalars (metrics and losses)
    checkpoints/         step_<N>.pt (weights) and resume.pt (the whole training state: buffer, priorities,
                         counts, optimizers, RNGs, the episode in progress) every checkpoint_every steps;
                         final.pt at the end (``MoPE.load`` reads them all)

``train_run(..., resume=True)`` (``mope train --resume RUN_DIR``) continues from ``resume.pt``: metrics rows
after its step are dropped and re-made, and the continued run equals an uninterrupted one step for step.
"""

from __future__ import annotations

import csv
import json
import os
import platform
import resource
import shutil
import signal
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mope.agent import MoPE, TrainingDivergedError, agent_class
from mope.checkpoint import mope_version
from mope.config import Config
from mope.envs import make_env
from mope.errors import CheckpointError, MopeError
from mope.evaluation import OUTCOME_KEYS, TRUTH_KEYS, Evaluator, Solutions, solutions
from mope.locks import FolderLock
from mope.metrics import EVALUATE_KEYS
from mope.preferences import validate_preference
from mope.runner import Callback, EvalCallback, IntervalStats, ProgressBar, StopWhen, crossed_now, train

METRIC_COLUMNS = ["step", "wall_s", *EVALUATE_KEYS, "timeout_share", *TRUTH_KEYS, *OUTCOME_KEYS, "loss", "epsilon",
                  "train_s"]
#: Interval averages of the update statistics (``IntervalStats``), every ``log_every`` steps.
TRAIN_STATS = "train_stats.csv"
STATS_COLUMNS = ["step", "updates", "epsilon", "loss", "loss_a", "loss_b", "td_abs", "q_mean", "q_max", "mi_bonus",
                 "disc_loss"]


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


RESUME_CHECKPOINT = "resume.pt"


def run_status(out_dir: str | Path) -> str:
    """``finished`` (summary.json written), ``resumable`` (checkpoints/resume.pt exists) or ``new``."""
    out = Path(out_dir)
    if (out / "summary.json").is_file():
        return "finished"
    if (out / "checkpoints" / RESUME_CHECKPOINT).is_file():
        return "resumable"
    return "new"


def prepare_out_dir(out_dir: str | Path, overwrite: bool = False) -> Path:
    """Create the run folder; refuse to clobber finished results unless ``overwrite``."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise RunFolderError(f"output path '{out}' exists and is not a folder")
    if (out / "metrics.csv").exists() and not overwrite:
        hint = " or --resume to continue it" if run_status(out) == "resumable" else ""
        raise RunFolderError(
            f"output folder '{out}' already holds a run; choose another --out, pass --overwrite{hint}")
    try:
        if overwrite:  # nothing of the old run may pass for the new one's (status, report, resume)
            for name in ("summary.json", "solutions.csv", "metrics.csv", TRAIN_STATS, "config.json", "error.txt"):
                (out / name).unlink(missing_ok=True)
            for old in (out / "checkpoints").glob("*.pt"):
                old.unlink()
            shutil.rmtree(out / "tb", ignore_errors=True)
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


def read_csv_rows(path: str | Path) -> list[dict[str, float]]:
    """Rows of a numeric CSV log as floats (``step`` as an int); no rows if the file does not exist."""
    path = Path(path)
    if not path.is_file():
        return []
    with open(path) as f:
        return [{k: int(float(v)) if k == "step" else float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def read_metrics(run_dir: str | Path) -> list[dict[str, float]]:
    """Rows of a run's ``metrics.csv`` as floats (``step`` as an int)."""
    path = Path(run_dir) / "metrics.csv"
    if not path.is_file():
        raise RunFolderError(f"'{run_dir}' has no metrics.csv; is it a mope run folder?")
    with open(path) as f:
        return [{k: int(float(v)) if k == "step" else float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def _environment_info() -> dict[str, Any]:
    return {"mope": mope_version(), "torch": torch.__version__, "numpy": np.__version__,
            "python": platform.python_version(), "machine": platform.machine(), "cpus": os.cpu_count()}


def _same_run(saved: Config, wanted: Config) -> list[str]:
    """Fields that change results (not device, threads or log interval) in which two configs differ."""
    from mope.jobs import NON_RESULT_FIELDS

    a, b = saved.to_dict(), wanted.to_dict()
    return [k for k in a if k not in NON_RESULT_FIELDS and a[k] != b.get(k)]


def _finished_result(out: Path) -> RunResult:
    summary = json.loads((out / "summary.json").read_text())
    agent = MoPE.load(out / "checkpoints" / "final.pt")
    return RunResult(out, agent, read_metrics(out), summary.get("final", {}), float(summary.get("wall_s", 0.0)))


def _resume_or_start(config: Config, out: Path, overwrite: bool, resume: bool) -> tuple[MoPE, list[dict], str]:
    """The agent to train, the metrics rows to keep, and the run's status before this call."""
    status = run_status(out) if resume else "new"
    if status != "new":
        saved = Config.load(out / "config.json")
        differ = _same_run(saved, config)
        if differ:
            raise RunFolderError(
                f"cannot resume '{out}': its config differs in {', '.join(differ)} "
                f"(saved {', '.join(f'{k}={saved.to_dict()[k]!r}' for k in differ)})")
    if status == "resumable":
        agent = MoPE.load(out / "checkpoints" / RESUME_CHECKPOINT, device=config.run.device,
                          torch_threads=config.run.torch_threads)
        stale = _same_run(agent.config, config)
        if stale:
            raise RunFolderError(f"cannot resume '{out}': checkpoints/{RESUME_CHECKPOINT} was written by another "
                                 f"config (it differs in {', '.join(stale)}); pass --overwrite to start again")
        kept = [r for r in read_metrics(out) if r["step"] <= agent.global_step] if (out / "metrics.csv").is_file() \
            else []
        kept_stats = [r for r in read_csv_rows(out / TRAIN_STATS) if r["step"] <= agent.global_step]
        return agent, [kept, kept_stats], status
    # with resume, a folder that has nothing to resume from (killed before its first checkpoint) restarts
    prepare_out_dir(out, overwrite or resume)
    config.save(out / "config.json")
    return agent_class(config.algo)(config.env_id, config), [[], []], status


class _RunLogs:
    """The run folder's logs: metrics.csv (one row per evaluation), train_stats.csv (interval averages of the
    update statistics) and TensorBoard scalars of both."""

    def __init__(self, out: Path, kept: list[dict], kept_stats: list[dict]) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.tb = SummaryWriter(str(out / "tb"))
        self.metrics = _CsvLog(out / "metrics.csv", METRIC_COLUMNS, kept)
        self.stats = _CsvLog(out / TRAIN_STATS, STATS_COLUMNS, kept_stats)

    def on_record(self, agent: MoPE, rec: dict[str, float]) -> None:
        rec.update(loss=agent.last_losses.get("loss", float("nan")), epsilon=agent.epsilon)
        self.metrics.write(rec)
        for k in METRIC_COLUMNS[2:]:
            self.tb.add_scalar(f"eval/{k}", rec[k], agent.global_step)

    def on_stats(self, row: dict[str, float]) -> None:
        self.stats.write(row)
        for k, v in row.items():
            if k != "step":
                self.tb.add_scalar(f"train/{k}", v, int(row["step"]))

    def close(self) -> None:
        self.metrics.close()
        self.stats.close()
        self.tb.close()


class _CsvLog:
    """A CSV file rewritten with the kept rows, then appended to and flushed row by row."""

    def __init__(self, path: Path, columns: list[str], kept: list[dict]) -> None:
        self.file = open(path, "w", newline="")  # noqa: SIM115 - closed by close()
        self.writer = csv.DictWriter(self.file, fieldnames=columns, extrasaction="ignore")
        self.columns = columns
        self.writer.writeheader()
        for row in kept:
            self.write(row)

    def write(self, row: dict[str, float]) -> None:
        self.writer.writerow({k: row.get(k, float("nan")) for k in self.columns})
        self.file.flush()

    def close(self) -> None:
        self.file.close()


class _Checkpoints(Callback):
    """Every ``every`` steps: checkpoints/resume.pt (the whole state), then step_N.pt (weights)."""

    def __init__(self, out: Path, every: int) -> None:
        self.out, self.every = out, every

    def on_step(self, agent: MoPE, stats: dict[str, float] | None) -> bool:
        if self.every and crossed_now(agent, self.every):
            # resume.pt first: once step_N.pt is there, the resumable state of step N is too
            agent.save(self.out / "checkpoints" / RESUME_CHECKPOINT, include_buffer=True)
            agent.save(self.out / "checkpoints" / f"step_{agent.global_step}.pt")
        return True


def train_run(config: Config, out_dir: str | Path, progress: bool = True, overwrite: bool = False,
              resume: bool = False) -> RunResult:
    """Train one agent and write a complete run folder (see the module docstring).

    Args:
        config: The resolved config.
        out_dir: The run folder.
        progress: Show a progress bar.
        overwrite: Replace a run already in ``out_dir``.
        resume: Continue the run in ``out_dir`` from ``checkpoints/resume.pt``; return a finished run as it is;
            start the run over if there is nothing to resume (a run killed before its first checkpoint).

    The folder is locked while the run writes it (:class:`~mope.locks.FolderLock`): a second writer is refused.
    Ctrl-C (SIGINT) or SIGTERM stops training at the next step boundary, saves ``checkpoints/resume.pt``
    (the whole training state) and raises ``KeyboardInterrupt``; no finished evaluation or trained weights are
    lost. A NaN or inf raises :class:`~mope.agent.TrainingDivergedError` naming the step and the quantity and
    leaves the last good checkpoints untouched.
    """
    out = Path(out_dir)
    with FolderLock(out, what="run folder"):
        if resume and run_status(out) == "finished":
            saved = Config.load(out / "config.json")
            differ = _same_run(saved, config)
            if differ:
                raise RunFolderError(f"cannot resume '{out}': its config differs in {', '.join(differ)}")
            return _finished_result(out)
        agent, (kept, kept_stats), status = _resume_or_start(config, out, overwrite, resume)
        records = _train_logged(agent, config, out, kept, kept_stats, progress)
        return _finish_run(agent, config, out, kept + records, status)


def _train_logged(agent: MoPE, config: Config, out: Path, kept: list[dict], kept_stats: list[dict],
                  progress: bool) -> list[dict[str, float]]:
    """Train the rest of the run with evaluation, logs, checkpoints and signal handling as callbacks."""
    eval_env = make_env(config.env_id, config.max_episode_steps)
    logs = _RunLogs(out, kept, kept_stats)
    evaluator = Evaluator.from_config(eval_env, config)
    evaluating = EvalCallback(evaluator, config.run.eval_every, on_record=logs.on_record)
    # SIGINT/SIGTERM set a flag that the training loop polls at each step boundary, so the interruption never
    # lands inside torch, the CSV writer or TensorBoard's writer thread.
    received: list[int] = []
    handlers = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            handlers[sig] = signal.signal(sig, lambda signum, frame: received.append(signum))
    callbacks: list[Callback] = [evaluating, _Checkpoints(out, config.run.checkpoint_every),
                                 IntervalStats(config.run.log_every, logs.on_stats), StopWhen(lambda: bool(received))]
    if progress:
        callbacks.insert(0, ProgressBar(evaluating))
    remaining = config.total_steps - agent.global_step
    try:
        try:
            if remaining > 0:
                train(agent, remaining, callbacks)
            elif kept and kept[-1]["step"] == agent.global_step:  # resumed at the last step, evaluated already:
                _, agent.last_solutions = evaluator.evaluate(agent)  # once more for the final solutions
            else:  # stopped on the last step before its evaluation: make (and log) it now
                evaluating.evaluate(agent)
        except TrainingDivergedError as exc:
            last = out / "checkpoints" / RESUME_CHECKPOINT
            where = f"the last good checkpoint is '{last}'" if last.is_file() else \
                "no checkpoint was written before it"
            raise TrainingDivergedError(f"{exc}; {where}") from None
        finally:
            logs.close()
            eval_env.close()
        if received:  # the handlers stay in place until the state is saved: a second signal cannot cut the save
            agent.save(out / "checkpoints" / RESUME_CHECKPOINT, include_buffer=True)
            raise KeyboardInterrupt(f"stopped by signal {received[0]} at step {agent.global_step}")
    finally:
        for sig, old_handler in handlers.items():
            signal.signal(sig, old_handler)
    return evaluating.records


def _finish_run(agent: MoPE, config: Config, out: Path, all_records: list[dict], status: str) -> RunResult:
    """Write final.pt, solutions.csv and summary.json."""
    agent.save(out / "checkpoints" / "final.pt")
    final = all_records[-1] if all_records else {}
    if agent.last_solutions is not None:
        write_solutions(out / "solutions.csv", agent.last_solutions)  # the final evaluation's solutions
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux: this process's peak so far
    eval_s = agent.eval_seconds
    summary = {"final": final, "wall_s": agent.wall_s, "s_per_1k_steps": 1000 * agent.wall_s / config.total_steps,
               "eval_s": eval_s, "train_s_per_1k_steps": 1000 * (agent.wall_s - eval_s) / config.total_steps,
               "peak_rss_mb": peak_mb,
               "algo": config.algo, "env_id": config.env_id, "seed": config.seed, "resumed": status == "resumable",
               "versions": _environment_info()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return RunResult(out, agent, all_records, final, agent.wall_s)


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


def load_agent(path: str | Path, device: str | None = None) -> MoPE:
    """The agent of a checkpoint file or run folder (see :func:`resolve_checkpoint`), on ``device`` if given."""
    return MoPE.load(resolve_checkpoint(path), **({"device": device} if device else {}))


def evaluate_checkpoint(path: str | Path, n_prefs: int = 2000, seed: int | None = None,
                        out: str | Path | None = None, device: str | None = None) -> tuple[dict[str, float], Solutions]:
    """Evaluate a checkpoint (or a run's final checkpoint) with the CR protocol; optionally write solutions."""
    if n_prefs < 1:
        raise MopeError(f"--prefs {n_prefs} is out of range: must be >= 1")
    agent = load_agent(path, device)
    c = agent.config
    evaluator = Evaluator.from_config(agent.env, c, n_prefs, seed)
    res, sols = evaluator.evaluate(agent)
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        write_solutions(out, sols)
    return res, sols


def play(path: str | Path, pref: Any, device: str | None = None, seed: int = 0) -> Solutions:
    """Play one greedy episode of a checkpoint under ``pref`` from reset seed ``seed``; one-row :class:`Solutions`."""
    agent = load_agent(path, device)
    w = validate_preference(pref, agent.m)
    return solutions(agent, agent.env, w[None], agent.config.gamma, agent.config.max_episode_steps, seed=seed)
