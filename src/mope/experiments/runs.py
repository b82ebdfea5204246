"""Run folders: train with logging and checkpoints, evaluate a run or checkpoint, play one episode.

A run folder written by :func:`train_run` (and ``mope train``) holds::

    config.json          the resolved Config (every field, plus the derived algo)
    metrics.csv          one row per evaluation: step, wall_s, cr, precision, recall, hv, eum, eum_optimal,
                         eum_gap, optimal_share, cardinality, timeout_share, path_error, state_error,
                         overestimation (against the exact Q* where the dynamics are known, else NaN), loss, epsilon,
                         win_share, loss_share, out_share (episode outcomes where the environment reports them:
                         the confrontation game), train_s (wall_s without the evaluations)
    train_stats.csv      every log_every steps: the mean of each update statistic over those steps (loss,
                         loss_a, loss_b, td_abs, q_mean, q_max, mi_bonus, disc_loss), epsilon, and the training
                         episodes ended in them: episodes, ep_len, ep_end_share (ended in a terminal state, not
                         at the time limit), ep_return_<i> (mean undiscounted return of objective i)
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

import contextlib
import csv
import json
import math
import os
import platform
import resource
import shutil
import signal
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from mope.agent.agent import MoPE, TrainingDivergedError, agent_class, without_inert_reward_norm
from mope.agent.checkpoint import mope_version
from mope.agent.runner import Callback, EvalCallback, IntervalStats, ProgressBar, StopWhen, crossed_now, train
from mope.config import Config, buffer_capacity, epsilon_decay_steps_of
from mope.envs import make_env
from mope.errors import CheckpointError, MopeError, RunFolderError, is_disk_full, one_line, short_repr
from mope.evaluation.evaluator import OUTCOME_KEYS, TRUTH_KEYS, Evaluator, Solutions, solutions
from mope.experiments.locks import FolderLock
from mope.metrics import EVALUATE_KEYS
from mope.preferences import validate_preference

METRIC_COLUMNS = ["step", "wall_s", *EVALUATE_KEYS, "timeout_share", *TRUTH_KEYS, *OUTCOME_KEYS, "loss", "epsilon",
                  "train_s"]
#: Interval averages of the update statistics (``IntervalStats``), every ``log_every`` steps.
TRAIN_STATS = "train_stats.csv"
STATS_COLUMNS = ["step", "updates", "epsilon", "loss", "loss_a", "loss_b", "td_abs", "q_mean", "q_max", "mi_bonus",
                 "disc_loss", "episodes", "ep_len", "ep_end_share"]


def stats_columns(n_objectives: int) -> list[str]:
    """train_stats.csv's columns: :data:`STATS_COLUMNS` and each objective's mean training-episode return."""
    return [*STATS_COLUMNS, *(f"ep_return_{i}" for i in range(n_objectives))]


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
    _refuse_clobber(out, overwrite)
    try:
        if overwrite:  # nothing of the old run may pass for the new one's (status, report, resume)
            for name in ("summary.json", "solutions.csv", "metrics.csv", TRAIN_STATS, "config.json", "error.txt"):
                (out / name).unlink(missing_ok=True)
            for old in (out / "checkpoints").glob("*.pt"):
                old.unlink()
            shutil.rmtree(out / "tb", ignore_errors=True)
        (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunFolderError(f"output folder '{out}' is not writable: {exc.strerror or exc}") from None
    _probe_write(out)
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


def parse_number(text: str | None, path: str | Path, line: int, column: str) -> float | int:
    """A cell of a numeric CSV log: an int where it was written as one (``100``), else a float (``0.5``, ``nan``),
    so a row read back and written again keeps its text (``100`` stays ``100``, not ``100.0``); an empty cell is NaN.

    Raises:
        RunFolderError: naming the file, the line and the column of a cell that is not a number.
    """
    if text in ("", None):
        return math.nan
    try:
        return int(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        pass
    try:
        return float(text)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise RunFolderError(f"'{path}' line {line}, column {column}: {short_repr(text)} is not a number; fix or "
                             "delete that row") from None


def _read_numeric_csv(path: Path) -> list[dict[str, float]]:
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            rows = []
            for row in reader:
                rec = {k: parse_number(v, path, reader.line_num, str(k)) for k, v in row.items() if k is not None}
                rec["step"] = int(rec["step"]) if "step" in rec and math.isfinite(rec["step"]) else rec.get("step")
                rows.append(rec)
            return rows
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise RunFolderError(f"'{path}' could not be read: {reason}") from None


def read_csv_rows(path: str | Path) -> list[dict[str, float]]:
    """Rows of a numeric CSV log (``step`` as an int); no rows if the file does not exist."""
    path = Path(path)
    if not path.is_file():
        return []
    return _read_numeric_csv(path)


def read_metrics(run_dir: str | Path) -> list[dict[str, float]]:
    """Rows of a run's ``metrics.csv`` (``step`` as an int)."""
    path = Path(run_dir) / "metrics.csv"
    if not path.is_file():
        raise RunFolderError(f"'{run_dir}' has no metrics.csv; is it a mope run folder?")
    return _read_numeric_csv(path)


def cpu_description() -> str:
    """The CPU as runs depend on it: its name, family and model (Linux), and the vector kernels torch dispatches to.

    Runs are deterministic on one machine but not across machines: two hosts that both call themselves "AMD EPYC"
    can differ in generation and in the kernels torch picks (AVX2 or AVX512), and then in every training stream.
    """
    name, ids = platform.processor() or platform.machine(), {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                key = key.strip()
                if key in ("model name", "cpu family", "model") and key not in ids:
                    ids[key] = value.strip()
                if not line.strip() and ids:
                    break
    except OSError:
        pass
    name = ids.get("model name", name)
    family = f"family {ids['cpu family']}, model {ids['model']}; " if "cpu family" in ids and "model" in ids else ""
    return f"{name} ({family}{torch.backends.cpu.get_cpu_capability()} kernels)"


def _environment_info() -> dict[str, Any]:
    return {"mope": mope_version(), "torch": torch.__version__, "numpy": np.__version__,
            "python": platform.python_version(), "machine": platform.machine(), "cpu": cpu_description(),
            "cpus": os.cpu_count()}


#: Settings that do not change a run's results: where it ran, and how often it logged and saved (a resumed run equals
#: an uninterrupted one step for step whatever its checkpoint interval). A finished run whose saved config differs
#: only in these is reused.
NON_RESULT_FIELDS = ("device", "torch_threads", "log_every", "checkpoint_every")


def result_differences(saved: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    """Fields that change results (not :data:`NON_RESULT_FIELDS`) in which two configs' dicts differ, in
    ``wanted``'s order; a ``reward_norm`` that cannot act on the run's environment is not a difference
    (:func:`~mope.agent.agent.without_inert_reward_norm`). The one test of "the same run" for resuming a folder
    and for a batch's job folders (:func:`mope.experiments.jobs.check_job_folders`)."""
    a, b = without_inert_reward_norm(saved), without_inert_reward_norm(wanted)
    return [k for k in b if k not in NON_RESULT_FIELDS and a.get(k) != b[k]]


def _same_run(saved: Config, wanted: Config) -> list[str]:
    return result_differences(saved.to_dict(), wanted.to_dict())


def _finished_result(out: Path) -> RunResult:
    summary = json.loads((out / "summary.json").read_text())
    agent = MoPE.load(out / "checkpoints" / "final.pt")
    return RunResult(out, agent, read_metrics(out), summary.get("final", {}), float(summary.get("wall_s", 0.0)))


def _resume_or_start(config: Config, out: Path, overwrite: bool, resume: bool
                     ) -> tuple[MoPE, list[dict], str, _Aside | None]:
    """The agent to train, the metrics rows to keep, the run's status before this call, and the old run set aside
    (an overwritten run, or a resumed run that had no checkpoint yet), to restore if the new one fails to start."""
    status = run_status(out) if resume else "new"
    if status != "new":
        saved = Config.load(out / "config.json")
        differ = _same_run(saved, config)
        if differ:
            raise RunFolderError(
                f"cannot resume '{out}': its config differs in {', '.join(differ)} "
                f"(saved {', '.join(f'{k}={short_repr(saved.to_dict()[k])}' for k in differ)})")
    if status == "resumable":
        agent = MoPE.load(out / "checkpoints" / RESUME_CHECKPOINT, device=config.run.device,
                          torch_threads=config.run.torch_threads)
        stale = _same_run(agent.config, config)
        if stale:
            raise RunFolderError(f"cannot resume '{out}': checkpoints/{RESUME_CHECKPOINT} was written by another "
                                 f"config (it differs in {', '.join(stale)}); start it over with: "
                                 f"mope train --resume {out} --overwrite")
        kept = [r for r in read_metrics(out) if r["step"] <= agent.global_step] if (out / "metrics.csv").is_file() \
            else []
        kept_stats = [r for r in read_csv_rows(out / TRAIN_STATS) if r["step"] <= agent.global_step]
        return agent, [kept, kept_stats], status, None
    # with resume, a folder that has nothing to resume from (killed before its first checkpoint) restarts
    check_out_dir(out, overwrite or resume)
    agent = build_agent(config)  # everything that can refuse the new run does so before the old one is touched
    aside = _Aside.set_aside(out)
    try:
        prepare_out_dir(out)
        config.save(out / "config.json")
    except BaseException:
        aside.restore()
        raise
    return agent, [[], []], status, aside


#: What a run writes in its folder; an overwritten run's are set aside (:class:`_Aside`), anything else stays.
RUN_ENTRIES = ("summary.json", "solutions.csv", "metrics.csv", TRAIN_STATS, "config.json", "error.txt", "tb",
               "checkpoints")
RUN_FOLDERS = ("tb", "checkpoints")
#: Where an overwritten run waits, inside its folder, until the new run has written its first checkpoint.
ASIDE_NAME = ".overwritten"


class _Aside:
    """The old run of a folder, moved into ``<folder>/.overwritten`` (renames: nothing is copied or rewritten).

    :meth:`commit` deletes it once the new run has written a checkpoint of its own; :meth:`restore` deletes what the
    new run wrote and moves the old run back, byte for byte, when the new one fails before that. A process killed in
    between leaves ``.overwritten`` behind; :func:`recover_aside` deals with it on the next start.
    """

    def __init__(self, out: Path, moved: list[str], left: tuple[str, ...] = ()) -> None:
        self.out, self.moved, self.done = out, moved, False
        #: Entries of run names that were no run's (a file named ``checkpoints``): left in place, never removed.
        self.left = left
        self.path = out / ASIDE_NAME

    @classmethod
    def set_aside(cls, out: Path) -> _Aside:
        moved = []
        aside = out / ASIDE_NAME
        try:
            for name in RUN_ENTRIES:
                # only what a run writes: a file where its checkpoints folder should be is no run's and stays
                if (out / name).is_dir() if name in RUN_FOLDERS else (out / name).is_file():
                    aside.mkdir(exist_ok=True)
                    os.rename(out / name, aside / name)
                    moved.append(name)
        except OSError as exc:
            cls(out, moved).restore(remove_new=False)
            raise RunFolderError(f"cannot set the old run in '{out}' aside: {exc.strerror or exc}; nothing was "
                                 "deleted") from None
        return cls(out, moved, tuple(n for n in RUN_ENTRIES if n not in moved and os.path.lexists(out / n)))

    def commit(self) -> None:
        """The new run has a checkpoint: the old one goes."""
        if not self.done:
            self.done = True
            shutil.rmtree(self.path, ignore_errors=True)

    def restore(self, remove_new: bool = True) -> None:
        """The new run failed before its first checkpoint: remove what it wrote, put the old run back."""
        if self.done:
            return
        self.done = True
        if remove_new:
            _remove_run_entries(self.out, self.left)
        for name in self.moved:
            os.rename(self.path / name, self.out / name)
        with contextlib.suppress(OSError):
            self.path.rmdir()


def _remove_run_entries(out: Path, keep: tuple[str, ...] = ()) -> None:
    for name in RUN_ENTRIES:
        if name in keep:
            continue
        p = out / name
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        elif os.path.lexists(p):
            p.unlink()


def recover_aside(out: Path) -> None:
    """A run set aside by an ``--overwrite`` that was killed (SIGKILL, a power cut) before the new run's first
    checkpoint: restore it (the new run had nothing worth keeping); if the new run did get a checkpoint, delete it.
    Called with the folder locked."""
    aside = out / ASIDE_NAME
    if not aside.is_dir():
        return
    if run_status(out) != "new":
        shutil.rmtree(aside, ignore_errors=True)
        return
    moved = [name for name in RUN_ENTRIES if os.path.lexists(aside / name)]
    try:
        _Aside(out, moved).restore()
    except OSError as exc:
        raise RunFolderError(f"'{aside}' holds a run that an interrupted --overwrite set aside, and it could not be "
                             f"moved back ({exc.strerror or exc}); move it back by hand") from None
    print(f"note: restored the run in '{out}' that an interrupted --overwrite had set aside", file=sys.stderr)


def remove_stale_temporaries(out: Path) -> None:
    """Delete the temporary files of checkpoint writes cut short by a kill (``checkpoints/.resume.pt.*.tmp``);
    called with the folder locked, so no write of another process is in progress."""
    for tmp in (out / "checkpoints").glob(".*.pt.*.tmp"):
        with contextlib.suppress(OSError):
            tmp.unlink()


def check_out_dir(out: Path, overwrite: bool) -> None:
    """Refuse an output path that is a file, or a folder holding a run when ``overwrite`` is not given; touches
    nothing."""
    _refuse_clobber(out, overwrite)
    _probe_write(out)


def _refuse_clobber(out: Path, overwrite: bool) -> None:
    if out.exists() and not out.is_dir():
        raise RunFolderError(f"output path '{out}' exists and is not a folder")
    if (out / "metrics.csv").exists() and not overwrite:
        hint = " or --resume to continue it" if run_status(out) == "resumable" else ""
        raise RunFolderError(
            f"output folder '{out}' already holds a run; choose another --out, pass --overwrite{hint}")


def _probe_write(out: Path) -> None:
    probe = out / ".write_test"
    try:
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        raise RunFolderError(f"output folder '{out}' is not writable: {exc.strerror or exc}") from None


def available_memory() -> int | None:
    """Bytes of memory this process can still get (MemAvailable plus free swap, capped by a cgroup limit), or None."""
    avail = None
    try:
        info = dict(line.split(":", 1) for line in Path("/proc/meminfo").read_text().splitlines() if ":" in line)
        avail = (int(info["MemAvailable"].split()[0]) + int(info.get("SwapFree", "0 kB").split()[0])) * 1024
    except (OSError, KeyError, ValueError):
        with contextlib.suppress(ValueError, OSError, AttributeError):
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    with contextlib.suppress(OSError, ValueError):
        cg = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if cg != "max":
            used = int(Path("/sys/fs/cgroup/memory.current").read_text().strip())
            free = max(0, int(cg) - used)
            avail = free if avail is None else min(avail, free)
    return avail


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 else f"{n / 2**20:.0f} MiB"


def estimate_memory(config: Config, env: Any) -> tuple[int, int]:
    """``(bytes of the replay buffer, bytes per transition)`` of ``config`` on ``env``, plus the networks, Adam's
    state and the evaluation's environment copies in the first figure: what the agent allocates before it trains."""
    import gymnasium as gym

    obs_space = env.observation_space
    m = int(env.unwrapped.reward_space.shape[0])
    if isinstance(obs_space, gym.spaces.Discrete):
        obs_bytes, obs_in = 8, int(obs_space.n)
    else:
        size = int(np.prod(obs_space.shape or (1,)))
        obs_bytes, obs_in = 4 * size, size
    n_actions = int(getattr(env.action_space, "n", 1))
    # obs and next_obs, preference, action, reward, terminated, done, return, return step, sum tree (two float64
    # per leaf, capacity rounded up to a power of two)
    per = 2 * obs_bytes + 3 * 4 * m + 8 + 4 + 1 + 8 + (32 if config.per else 0)
    widths = [obs_in + m, *config.hidden_sizes, n_actions * m * max(1, config.n_components)]
    params = sum(a * b + b for a, b in zip(widths, widths[1:], strict=False)) * max(1, config.n_critics)
    nets = params * 4 * 6  # q and target networks, gradients, Adam's two moments, one spare copy when saving
    return buffer_capacity(config) * per + nets, per


def check_resources(config: Config) -> None:
    """Refuse, before anything is allocated or touched, a run that cannot start: an unknown or unsupported
    environment, a device that is not there, more evaluation preferences than :data:`MAX_EVAL_PREFS`, or a replay
    buffer and networks larger than the memory available."""
    from mope.agent.agent_state import resolve_device
    from mope.evaluation.evaluator import check_eval_prefs

    check_eval_prefs(config.run.eval_prefs, "eval_prefs")
    resolve_device(config.run.device)
    env = make_env(config.env_id, config.max_episode_steps)
    try:
        need, per = estimate_memory(config, env)
    finally:
        with contextlib.suppress(Exception):
            env.close()
    avail = available_memory()
    if avail is not None and need > 0.9 * avail:
        fit = max(0, int((0.8 * avail - (need - buffer_capacity(config) * per)) // per))
        raise MopeError(f"buffer_size={buffer_capacity(config)} needs about {_gib(need)} of memory ({per} bytes per "
                        f"transition, networks included) but {_gib(avail)} is available; lower buffer_size (about "
                        f"{fit} fits here) or hidden_sizes")


def build_agent(config: Config) -> MoPE:
    """The agent of a new run, after :func:`check_resources`; an allocation that still fails is one line."""
    check_resources(config)
    try:
        return agent_class(config.algo)(config.env_id, config)
    except MemoryError:
        raise MopeError(f"out of memory building the agent (buffer_size={buffer_capacity(config)}, hidden_sizes="
                        f"{list(config.hidden_sizes)}); lower them") from None
    except RuntimeError as exc:  # torch: "can't allocate memory", CUDA out of memory
        if "alloc" not in str(exc).lower() and "out of memory" not in str(exc).lower():
            raise
        raise MopeError(f"out of memory building the agent ({one_line(str(exc), 120)}); lower buffer_size or "
                        "hidden_sizes") from None


class _RunLogs:
    """The run folder's logs: metrics.csv (one row per evaluation), train_stats.csv (interval averages of the
    update statistics) and TensorBoard scalars of both."""

    def __init__(self, out: Path, kept: list[dict], kept_stats: list[dict], n_objectives: int) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.tb = SummaryWriter(str(out / "tb"))
        self.metrics = CsvLog(out / "metrics.csv", METRIC_COLUMNS, kept)
        self.stats = CsvLog(out / TRAIN_STATS, stats_columns(n_objectives), kept_stats)

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


class CsvLog:
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

    def __init__(self, out: Path, every: int, aside: _Aside | None = None) -> None:
        self.out, self.every, self.aside = out, every, aside

    def on_step(self, agent: MoPE, stats: dict[str, float] | None) -> bool:
        if self.every and crossed_now(agent, self.every):
            # resume.pt first: once step_N.pt is there, the resumable state of step N is too
            agent.save(self.out / "checkpoints" / RESUME_CHECKPOINT, include_buffer=True)
            agent.save(self.out / "checkpoints" / f"step_{agent.global_step}.pt")
            if self.aside is not None:
                self.aside.commit()  # the new run has its first checkpoint: the one it overwrites goes
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

    The folder is locked while the run writes it (:class:`~mope.experiments.locks.FolderLock`): a second writer is
    refused.
    Ctrl-C (SIGINT) or SIGTERM stops training at the next step boundary, saves ``checkpoints/resume.pt``
    (the whole training state) and raises ``KeyboardInterrupt``; no finished evaluation or trained weights are
    lost. A NaN or inf raises :class:`~mope.agent.agent.TrainingDivergedError` naming the step and the quantity and
    leaves the last good checkpoints untouched.
    """
    out = Path(out_dir)
    created = not _exists(out)
    try:
        with FolderLock(out, what="run folder"):
            recover_aside(out)
            remove_stale_temporaries(out)
            if resume and run_status(out) == "finished":
                saved = Config.load(out / "config.json")
                differ = _same_run(saved, config)
                if differ:
                    raise RunFolderError(f"cannot resume '{out}': its config differs in {', '.join(differ)}")
                return _finished_result(out)
            agent, (kept, kept_stats), status, aside = _resume_or_start(config, out, overwrite, resume)
            try:
                records = _train_logged(agent, config, out, kept, kept_stats, progress, aside)
                result = _finish_run(agent, config, out, kept + records, status)
            except BaseException:
                if aside is not None:
                    aside.restore()  # no checkpoint of the new run yet (else the old run is gone already)
                raise
            if aside is not None:
                aside.commit()
            return result
    except BaseException as exc:
        if created:  # a folder this call made and left empty (a refused run) is removed again
            with contextlib.suppress(OSError):
                out.rmdir()
        if isinstance(exc, (OSError, CheckpointError)) and _disk_full(exc, out):
            raise RunFolderError(
                f"the disk holding '{out}' is full; free some space, then continue with: mope train --resume {out} "
                "(the last checkpoint in it is intact)") from None
        if isinstance(exc, OSError):
            raise RunFolderError(f"run folder '{out}' could not be written: {exc.strerror or exc}; continue with: "
                                 f"mope train --resume {out}") from None
        raise


def _exists(path: Path) -> bool:
    try:
        return path.exists()
    except OSError as exc:  # a name longer than the file system allows, a loop of links
        raise RunFolderError(f"output path '{path}' cannot be used: {exc.strerror or exc}") from None


def _disk_full(exc: BaseException, out: Path) -> bool:
    """Whether a failed write in ``out`` was for want of space: ENOSPC, or a checkpoint write (torch reports a full
    disk as a RuntimeError of its zip writer) on a file system with (almost) nothing left."""
    if is_disk_full(exc) or "no space left" in str(exc).lower() or "disk is full" in str(exc):
        return True
    if isinstance(exc, CheckpointError) and "cannot write checkpoint" in str(exc):
        try:
            return shutil.disk_usage(next(p for p in (out, *out.parents) if p.exists())).free < 16 * 2**20
        except (OSError, StopIteration):
            return False
    return False


def _train_logged(agent: MoPE, config: Config, out: Path, kept: list[dict], kept_stats: list[dict],
                  progress: bool, aside: _Aside | None = None) -> list[dict[str, float]]:
    """Train the rest of the run with evaluation, logs, checkpoints and signal handling as callbacks."""
    eval_env = make_env(config.env_id, config.max_episode_steps)
    logs = _RunLogs(out, kept, kept_stats, agent.m)
    evaluator = Evaluator.from_config(eval_env, config)
    evaluating = EvalCallback(evaluator, config.run.eval_every, on_record=logs.on_record)
    # SIGINT/SIGTERM set a flag that the training loop polls at each step boundary, so the interruption never
    # lands inside torch, the CSV writer or TensorBoard's writer thread.
    received: list[int] = []
    handlers = {}
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            handlers[sig] = signal.signal(sig, lambda signum, frame: received.append(signum))
    interval = IntervalStats(config.run.log_every, logs.on_stats)
    callbacks: list[Callback] = [evaluating, _Checkpoints(out, config.run.checkpoint_every, aside), interval,
                                 StopWhen(lambda: bool(received))]
    if progress:
        callbacks.insert(0, ProgressBar(evaluating))
    remaining = config.total_steps - agent.global_step
    try:
        try:
            if remaining > 0:
                train(agent, remaining, callbacks)
                if received:  # stopped between two rows: the part of the interval made so far is a row of its own
                    interval.flush(agent)
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
            if aside is not None:
                aside.commit()  # the new run is resumable: the one it overwrites goes
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
    eval_s, per_1k = agent.eval_seconds, 1000 / config.total_steps
    write_summary(out, {"final": final, "wall_s": agent.wall_s, "s_per_1k_steps": per_1k * agent.wall_s,
                        "eval_s": eval_s, "train_s_per_1k_steps": per_1k * (agent.wall_s - eval_s),
                        "algo": config.algo, "env_id": config.env_id, "seed": config.seed,
                        "resumed": status == "resumable",
                        "resolved": {"epsilon_decay_steps": epsilon_decay_steps_of(config),  # None in config.json
                                     "buffer_size": buffer_capacity(config)}})
    return RunResult(out, agent, all_records, final, agent.wall_s)


def write_summary(out: Path, summary: dict[str, Any]) -> None:
    """Write ``out/summary.json`` (it marks a run folder finished), adding this process's peak memory and the
    package versions."""
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux: this process's peak so far
    summary = {**summary, "peak_rss_mb": peak_mb, "versions": _environment_info()}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n")


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
    from mope.evaluation.evaluator import check_eval_prefs

    if n_prefs < 1:
        raise MopeError(f"--prefs {n_prefs} is out of range: must be >= 1")
    check_eval_prefs(n_prefs, "--prefs")
    if out is not None:
        check_output_file(out)
    agent = load_agent(path, device)
    c = agent.config
    evaluator = Evaluator.from_config(agent.env, c, n_prefs, seed)
    res, sols = evaluator.evaluate(agent)
    if out is not None:
        try:
            write_solutions(out, sols)
        except OSError as exc:
            what = "the disk is full" if is_disk_full(exc) else exc.strerror or str(exc)
            raise MopeError(f"cannot write the solutions to '{out}': {what}") from None
    return res, sols


def check_output_file(path: str | Path, flag: str = "--out") -> Path:
    """Make sure a result file can be written at ``path`` before the work that makes it starts: not a folder, in a
    folder that exists or can be made, and that is writable (probed with a temporary file, which is removed).

    Raises:
        MopeError: naming the path and what to pass instead.
    """
    p = Path(path)
    try:
        if p.is_dir():
            raise MopeError(f"{flag} '{p}' is a folder; give a file name, e.g. {p / 'solutions.csv'}")
        blocker = next((a for a in p.parents if a.exists() and not a.is_dir()), None)
        if blocker is not None:
            raise MopeError(f"{flag} '{p}' cannot be written: '{blocker}' is a file, not a folder")
        p.parent.mkdir(parents=True, exist_ok=True)
        probe = p.parent / f".mope-write-test-{os.getpid()}"
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        raise MopeError(f"cannot write '{p}': {exc.strerror or exc}; pass {flag} with a path in a writable "
                        "folder") from None
    return p


def play(path: str | Path | MoPE, pref: Any, device: str | None = None, seed: int = 0) -> Solutions:
    """Play one greedy episode of a checkpoint (or a loaded agent) under ``pref`` from reset seed ``seed``; one-row
    :class:`Solutions`."""
    agent = path if isinstance(path, MoPE) else load_agent(path, device)
    w = validate_preference(pref, agent.m)
    return solutions(agent, agent.env, w[None], agent.config.gamma, agent.config.max_episode_steps, seed=seed)
