"""The one runner for batches of training jobs: local processes or Ray, resumable, errors kept per job.

A :class:`Job` is a named unit of work with a folder of its own (``<out>/<name>``): ``train`` (one mope run,
from a config; it resumes from ``checkpoints/resume.pt``), ``ppo`` (one PPO policy of the outer-loop
baseline) or ``envelope`` (what each does: :mod:`mope.experiments.job_kinds`). :func:`run_jobs` runs a list of
them and reports each outcome; ``mope sweep``, ``mope reproduce dst``, ``mope reproduce confrontation`` and
``mope benchmark`` all go through it, so they share resumption, the Ray backend, the handling of a crashed worker
and ``error.txt`` per failed job.

Backends: ``local`` runs jobs in a process pool (forkserver); ``ray`` runs them as Ray tasks on a local
instance or a cluster (``address``).
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mope.errors import MopeError, suggest
from mope.experiments.job_kinds import JOB_KINDS
from mope.experiments.locks import pid_alive

BACKENDS = ("local", "ray")
RAY_MISSING = "the ray backend needs Ray: pip install 'mope[ray]'"
#: Written into every batch folder; a Ray task that sees it runs its job in place (a shared filesystem).
BATCH_MARKER = ".mope-batch"


class JobError(MopeError):
    """A batch of jobs cannot be run as asked."""


@dataclass
class Job:
    """One unit of work: ``kind`` (``train`` or ``ppo``), its settings, and its folder name under the batch folder."""

    name: str
    kind: str
    payload: dict[str, Any]


def check_job_folders(jobs: list[Job], out: Path) -> None:
    """Refuse a batch whose training job's folder holds a run of another config (the batch changed since).

    Raises:
        JobError: naming the folder and the differing fields with both values.
    """
    from mope.config import Config
    from mope.experiments.runs import NON_RESULT_FIELDS, result_differences

    for job in jobs:
        name = {"train": "config.json", "envelope": "peer.json"}.get(job.kind)
        path = out / job.name / (name or "")
        if name is None or not path.is_file():
            continue
        try:
            saved = json.loads(path.read_text())
            if job.kind == "train":
                saved, wanted = (Config.from_dict(d).to_dict() for d in (saved, job.payload))
                differ = result_differences(saved, wanted)
            else:
                wanted = json.loads(json.dumps({"method": "envelope", **job.payload}))
                differ = [k for k in wanted if k not in NON_RESULT_FIELDS and saved.get(k) != wanted[k]]
        except (OSError, json.JSONDecodeError, MopeError):
            continue  # an unreadable config belongs to a run that never got going; it is started afresh
        if differ:
            what = ", ".join(f"{k} ({saved.get(k)!r} there, {wanted[k]!r} now)" for k in differ[:4])
            raise JobError(f"folder '{out / job.name}' holds a run of another config: {what}; "
                           "use another --out or delete that folder")


def job_done(job: Job, out: Path) -> bool:
    """True when the job's folder holds its finished result (``summary.json``)."""
    return (out / job.name / "summary.json").is_file()


def run_job(name: str, kind: str, payload: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Worker: run, resume or skip one job; never raises for a failed job (the failure is recorded instead)."""
    import torch

    torch.set_num_threads(max(1, int(payload.get("torch_threads") or 1)))
    out = Path(out_dir)
    t0 = time.perf_counter()
    done = (out / "summary.json").is_file()
    resumable = (out / "checkpoints" / "resume.pt").is_file()
    action = "skipped" if done else "resumed" if resumable else "trained"
    try:
        (out / "error.txt").unlink(missing_ok=True)
        final = JOB_KINDS[kind](payload, out)
        return {"name": name, "status": "finished", "action": action, "final": final,
                "wall_s": time.perf_counter() - t0, "error": None}
    except Exception as exc:  # noqa: BLE001 - any failure of one job is recorded, the batch goes on
        with contextlib.suppress(OSError):  # the folder itself may be what failed; the record keeps the error
            out.mkdir(parents=True, exist_ok=True)
            (out / "error.txt").write_text(traceback.format_exc())
        return {"name": name, "status": "failed", "action": "failed", "final": {},
                "wall_s": time.perf_counter() - t0, "error": f"{type(exc).__name__}: {exc}"}


def run_job_remote(name: str, kind: str, payload: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Ray task: :func:`run_job`, in place when this node sees the batch folder (a shared filesystem).

    Otherwise (a worker node or Ray Client cluster without the driver's filesystem) the job runs in a temporary
    folder and comes back packed in ``rec["archive"]`` (a gzipped tar, without the resume checkpoint), for the
    driver to unpack into the batch folder.
    """
    import io
    import tarfile
    import tempfile

    if (Path(out_dir).parent / BATCH_MARKER).is_file():
        return run_job(name, kind, payload, out_dir)
    with tempfile.TemporaryDirectory(prefix="mope-job-") as tmp:
        rec = run_job(name, kind, payload, str(Path(tmp) / name))
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w:gz") as tar:
            tar.add(Path(tmp) / name, arcname=name,
                    filter=lambda info: None if info.name.endswith(("resume.pt", "interrupted.pt")) else info)
        rec["archive"] = buf.getvalue()
    return rec


def unpack_job(rec: dict[str, Any], out: Path) -> None:
    """Unpack a job folder that a Ray task sent back (see :func:`run_job_remote`) into the batch folder."""
    import io
    import tarfile

    archive = rec.pop("archive", None)
    if archive is None:
        return
    with tarfile.open(fileobj=io.BytesIO(archive), mode="r:gz") as tar:
        names = tar.getnames()
        if any((n != rec["name"] and not n.startswith(rec["name"] + "/")) or ".." in Path(n).parts for n in names):
            raise JobError(f"the archive of job '{rec['name']}' holds files outside its folder")
        safe = {"filter": "data"} if hasattr(tarfile, "data_filter") else {}  # Python >= 3.11.4
        tar.extractall(out, **safe)


# ------------------------------------------------------------------------------------------------------------
# backends
# ------------------------------------------------------------------------------------------------------------
#: Set in a worker whose parent (the batch's main process) is gone.
_ORPHANED = threading.Event()
#: Seconds an orphaned worker gives its job to save its resumable state before it exits.
ORPHAN_GRACE_S = 5.0


def _init_worker(parent_pid: int | None = None) -> None:
    import torch

    torch.set_num_threads(1)
    if parent_pid is not None:
        threading.Thread(target=_watch_parent, args=(parent_pid,), name="mope-parent-watch", daemon=True).start()


def _watch_parent(parent_pid: int, poll_s: float = 0.25) -> None:
    """In a pool worker: once the process that started the batch is gone (SIGKILLed: it could not stop its
    workers), interrupt the job as Ctrl-C would (a training saves its resumable state at the next step), then exit
    within :data:`ORPHAN_GRACE_S` seconds, instead of training the queued jobs with nobody to report to."""
    import signal

    while pid_alive(parent_pid):
        time.sleep(poll_s)
    _ORPHANED.set()
    with contextlib.suppress(OSError):
        os.kill(os.getpid(), signal.SIGINT)
    time.sleep(ORPHAN_GRACE_S)
    os._exit(1)


def _pool_job(name: str, kind: str, payload: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """:func:`run_job` in a pool worker; an orphaned worker exits as soon as its job has stopped."""
    try:
        return run_job(name, kind, payload, out_dir)
    finally:
        if _ORPHANED.is_set():
            os._exit(1)


class _Summary:
    """The live line: a bar over jobs with done / running / failed / skipped counts."""

    def __init__(self, total: int, done: int, enabled: bool, desc: str) -> None:
        from tqdm.auto import tqdm

        self.done, self.failed, self.skipped, self.running = done, 0, done, 0
        self.bar = tqdm(total=total, initial=done, desc=desc, unit="job", disable=not enabled)
        self.refresh()

    def refresh(self, redraw: bool = True) -> None:
        self.bar.set_postfix_str(f"done {self.done}, running {self.running}, failed {self.failed}, "
                                 f"skipped {self.skipped}", refresh=redraw)

    def finished(self, rec: dict[str, Any]) -> None:
        if rec["status"] == "failed":
            self.failed += 1
            self.bar.write(f"job {rec['name']} failed: {rec['error']}")
        else:
            self.done += 1
            self.skipped += rec["action"] == "skipped"
        self.running = max(0, self.running - 1)
        self.refresh(redraw=False)
        self.bar.update(1)

    def set_running(self, n: int) -> None:
        if n != self.running:
            self.running = n
            self.refresh()

    def close(self) -> None:
        self.bar.close()


def _local_backend(jobs: list[tuple[str, str, dict[str, Any], str]], workers: int,
                   on_done: Callable[[dict[str, Any]], None], on_running: Callable[[int], None],
                   fresh: bool = False) -> None:
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context(method),
                               initializer=_init_worker, initargs=(os.getpid(),),
                               max_tasks_per_child=1 if fresh else None)
    try:
        pending: set[Future] = {pool.submit(_pool_job, *job) for job in jobs}
        while pending:
            finished, pending = wait(pending, timeout=1.0, return_when=FIRST_COMPLETED)
            for fut in finished:
                try:
                    on_done(fut.result())
                except BrokenProcessPool as exc:  # a worker was killed (OOM killer, signal): not a job error
                    raise JobError(f"a job process died ({exc}); run the same command again to resume "
                                   "the unfinished jobs") from None
            on_running(min(workers, sum(f.running() for f in pending)))
    except BaseException:
        _stop_workers(pool)
        raise
    pool.shutdown(wait=True)


def _stop_workers(pool: ProcessPoolExecutor, grace_s: float = 120.0) -> None:
    """Cancel the queued jobs and interrupt the running ones with SIGINT, as Ctrl-C in a terminal would: each
    saves its resumable state and exits. A worker may already hold the next job (the pool feeds ahead), so the
    interruption is repeated every second until the workers are gone; after ``grace_s``, what is left is killed."""
    import signal

    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline:
        alive = [p for p in processes if p.is_alive()]
        if not alive:
            return
        for proc in alive:
            with contextlib.suppress(ProcessLookupError, OSError, ValueError):
                os.kill(proc.pid, signal.SIGINT)
        for proc in alive:
            with contextlib.suppress(ValueError, OSError):
                proc.join(1.0 / len(alive))
    for proc in processes:
        with contextlib.suppress(ValueError, OSError):
            if proc.is_alive():
                proc.kill()


def _ray_backend(jobs: list[tuple[str, str, dict[str, Any], str]], out: Path, workers: int | None,
                 address: str | None, on_done: Callable[[dict[str, Any]], None],
                 on_running: Callable[[int], None]) -> None:
    import ray

    started = False
    if not ray.is_initialized():
        # a local instance sized to --workers; a cluster (or Ray Client, ray://) takes only its address
        kwargs: dict[str, Any] = {"address": address} if address is not None else \
            {"include_dashboard": False, "log_to_driver": False, "num_cpus": workers}
        try:
            ray.init(**kwargs)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise JobError(f"could not connect to Ray at address={address!r}: {exc}") from None
        started = True
    try:
        slots = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        remote = ray.remote(num_cpus=1, max_retries=0)(run_job_remote)
        queue, pending = list(jobs), []
        while queue or pending:
            while queue and len(pending) < slots:  # keep at most `slots` jobs in flight
                pending.append(remote.remote(*queue.pop(0)))
            ready, pending = ray.wait(pending, num_returns=1, timeout=1.0)
            for ref in ready:
                try:
                    rec = ray.get(ref)
                except Exception as exc:  # noqa: BLE001 - a worker crashed or was killed: not the job's error
                    raise JobError(f"a Ray task died ({type(exc).__name__}: {str(exc).splitlines()[0][:200]}); "
                                   "run the same command again to resume the unfinished jobs") from None
                unpack_job(rec, out)
                on_done(rec)
            on_running(len(pending))
    finally:
        if started:
            ray.shutdown()


def check_backend(backend: str, address: str | None, workers: int | None) -> None:
    """Raise :class:`JobError` for an unknown backend, an address without Ray, a bad worker count or no Ray."""
    if backend not in BACKENDS:
        raise JobError(f"unknown backend '{backend}'{suggest(backend, BACKENDS)}; choose one of {', '.join(BACKENDS)}")
    if address is not None and backend != "ray":
        raise JobError(f"--address {address} needs --backend ray")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise JobError(f"workers={workers!r} is out of range: must be >= 1")
    if backend == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            raise JobError(RAY_MISSING) from None


def run_jobs(jobs: list[Job], out: Path, backend: str = "local", workers: int | None = None,
             address: str | None = None, progress: bool = True, desc: str = "jobs",
             on_done: Callable[[dict[str, Any]], None] | None = None, fresh_processes: bool = False
             ) -> dict[str, dict[str, Any]]:
    """Run every job into ``out/<job.name>``; finished ones are skipped, interrupted ones resumed.

    Args:
        jobs: The jobs (unique names).
        out: The batch folder.
        backend: ``local`` or ``ray``.
        workers: Jobs at once (default: every core, or every cluster CPU for Ray).
        address: Ray cluster address (``auto``, ``ray://host:10001``); only for the ray backend.
        progress: Show the live line.
        desc: Its label.
        on_done: Called with each job's record as it finishes (skipped ones included).
        fresh_processes: Run every job in a new process (local backend), so each job's peak memory is its own.

    Returns:
        Job name -> ``{"name", "status", "action", "final", "wall_s", "error"}``.
    """
    check_backend(backend, address, workers)
    for job in jobs:
        if job.kind not in JOB_KINDS:
            raise JobError(f"job '{job.name}' has unknown kind '{job.kind}'")
    check_job_folders(jobs, out)
    out.mkdir(parents=True, exist_ok=True)
    (out / BATCH_MARKER).write_text("a folder of mope jobs\n")
    records: dict[str, dict[str, Any]] = {}
    for job in jobs:
        if job_done(job, out) and job.kind in ("train", "envelope"):
            final = json.loads((out / job.name / "summary.json").read_text()).get("final", {})
            records[job.name] = {"name": job.name, "status": "finished", "action": "skipped", "final": final,
                                 "wall_s": 0.0, "error": None}
            with contextlib.suppress(OSError):  # a failure recorded before the job finished is stale now
                (out / job.name / "error.txt").unlink(missing_ok=True)
            if on_done is not None:
                on_done(records[job.name])
    todo = [(j.name, j.kind, j.payload, str(out / j.name)) for j in jobs if j.name not in records]
    summary = _Summary(len(jobs), len(records), progress, desc)

    def done(rec: dict[str, Any]) -> None:
        records[rec["name"]] = rec
        summary.finished(rec)
        if on_done is not None:
            on_done(rec)

    try:
        with _sigterm_as_interrupt():
            if todo and backend == "local":
                _local_backend(todo, min(workers or os.cpu_count() or 1, len(todo)), done, summary.set_running,
                               fresh_processes)
            elif todo:
                _ray_backend(todo, out, workers, address, done, summary.set_running)
    finally:
        summary.close()
    return records


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Any:
    """In the main thread, turn SIGTERM into KeyboardInterrupt for the block, so a killed batch stops its workers
    (they save their resumable state) instead of leaving them running."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(f"stopped by signal {signum}")

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


__all__ = ["BACKENDS", "JOB_KINDS", "Job", "JobError", "check_backend", "run_job", "run_jobs", "unpack_job"]


def run_all_or_raise(jobs: list[Job], out: Path, backend: str = "local", workers: int | None = None,
                     address: str | None = None, progress: bool = True) -> dict[str, dict[str, Any]]:
    """:func:`run_jobs` for a reproduction, whose tables need every run: raise a :class:`MopeError` naming the
    first failed run (and its ``error.txt``) if any failed; else the records."""
    records = run_jobs(jobs, out, backend, workers, address, progress, desc="runs")
    failed = [r for r in records.values() if r["status"] == "failed"]
    if failed:
        raise MopeError(f"{len(failed)} of {len(jobs)} runs failed, the first: {failed[0]['name']} "
                        f"({failed[0]['error']}); see {out / failed[0]['name'] / 'error.txt'}")
    return records
