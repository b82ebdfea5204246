"""``mope sweep SPEC``: many training runs from one YAML spec, on local processes or on a Ray cluster.

A spec lists fixed settings (``base``), a grid whose every combination is one configuration, and the seeds::

    name: dst-eql-vs-mope          # optional; the default output folder is runs/<name>
    base:                          # any Config field, fixed for every trial
      env_id: deep-sea-treasure-v0
      total_steps: 2000
    grid:                          # every combination; keys: algo and any Config field
      algo: [eql, mope]
      sigma_omega: [0.02, 0.04]
    seeds: 3                       # seeds 0, 1, 2; or a list: seeds: [0, 5] (also accepted: seed: [0, 5])

Each trial trains into its own run folder ``<out>/<env>-<algo>-<field>=<value>-s<seed>``, exactly as
``mope train`` does. Re-running a sweep skips finished trials and resumes interrupted ones from their
``checkpoints/resume.pt``. A failed trial leaves its traceback in ``<trial>/error.txt`` and does not stop the
others. ``<out>/sweep.json`` records the spec, the grid, every trial and its status; ``mope report`` reads it.

Backends: ``local`` (default) runs trials in a process pool on this machine; ``ray`` runs the same trials as
Ray tasks, on a local Ray instance or on a cluster (``address``). Every trial's config is validated, and every
environment created once, before anything is launched.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import multiprocessing
import os
import re
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mope.config import Config
from mope.errors import ConfigError, MopeError, suggest

SPEC_KEYS = ("name", "base", "grid", "seeds", "seed")
BACKENDS = ("local", "ray")
#: Fields that do not change a run's results; a finished trial whose saved config differs only in these is reused.
NON_RESULT_FIELDS = ("device", "torch_threads")
RAY_MISSING = "the ray backend needs Ray: pip install 'mope[ray]'"


class SweepError(MopeError):
    """A sweep spec is malformed, or a sweep cannot be run as asked."""


@dataclass
class SweepSpec:
    """A parsed and validated sweep spec.

    Attributes:
        name: Name of the sweep (the default output folder is ``runs/<name>``).
        base: Fixed Config fields (``algo`` allowed).
        grid: Axis name -> list of values; axes are ``algo`` and Config fields, never ``seed``.
        seeds: Seeds, run for every grid point.
    """

    name: str
    base: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, list[Any]] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=lambda: [0])

    def to_dict(self) -> dict[str, Any]:
        """Plain dict in the spec file's layout."""
        return {"name": self.name, "base": self.base, "grid": self.grid, "seeds": self.seeds}


@dataclass
class Trial:
    """One (grid point, seed): its folder name, the swept values and the resolved config."""

    name: str
    params: dict[str, Any]
    config: Config


@dataclass
class TrialResult:
    """Outcome of one trial.

    Attributes:
        name: Trial folder name.
        out_dir: The trial's run folder.
        status: ``finished`` or ``failed``.
        action: ``trained`` (from scratch), ``resumed``, ``skipped`` (was already finished) or ``failed``.
        final: Final metrics (``summary.json``'s ``final``); empty if the trial failed.
        wall_s: Seconds this sweep spent on the trial (0 for a skipped one).
        error: ``"ExceptionType: message"`` of a failed trial, else ``None``.
    """

    name: str
    out_dir: Path
    status: str
    action: str
    final: dict[str, float] = field(default_factory=dict)
    wall_s: float = 0.0
    error: str | None = None


# ------------------------------------------------------------------------------------------------------------
# spec
# ------------------------------------------------------------------------------------------------------------
def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _seed_list(value: Any, where: str) -> list[int]:
    if _is_int(value):
        if value < 1:
            raise SweepError(f"{where}={value} is out of range: give a count >= 1 or a list of seeds")
        return list(range(value))
    if isinstance(value, list) and value and all(_is_int(s) and s >= 0 for s in value):
        if len(set(value)) != len(value):
            raise SweepError(f"{where}={value} lists a seed twice")
        return list(value)
    raise SweepError(f"{where}={value!r} is not a seed count or a non-empty list of seeds >= 0")


def parse_spec(data: Any, name: str = "sweep") -> SweepSpec:
    """Validate a spec mapping (as read from YAML) and return a :class:`SweepSpec`.

    Raises:
        SweepError: naming the first unknown key or malformed value.
    """
    if not isinstance(data, dict):
        raise SweepError(f"a sweep spec must be a mapping with keys {', '.join(SPEC_KEYS)}; got {type(data).__name__}")
    for key in data:
        if key not in SPEC_KEYS:
            raise SweepError(f"unknown spec key '{key}'{suggest(str(key), SPEC_KEYS)}; "
                             f"a spec has {', '.join(SPEC_KEYS)}")
    fields = Config.field_names()
    axes_names = ["algo", *fields]
    base = data.get("base") or {}
    grid_in = data.get("grid") or {}
    for what, mapping in (("base", base), ("grid", grid_in)):
        if not isinstance(mapping, dict):
            raise SweepError(f"'{what}' must be a mapping of config fields; got {type(mapping).__name__}")
        for key in mapping:
            if key not in axes_names:
                raise SweepError(f"unknown config key '{key}' in {what}{suggest(str(key), axes_names)}")
    seed_sources = {k: v for k, v in (("seeds", data.get("seeds")), ("seed", data.get("seed")),
                                      ("grid.seed", grid_in.get("seed")), ("base.seed", base.get("seed")))
                    if v is not None}
    if len(seed_sources) > 1:
        raise SweepError(f"seeds are given twice ({', '.join(seed_sources)}); keep one")
    seeds = [0]
    if seed_sources:
        where, value = next(iter(seed_sources.items()))
        seeds = _seed_list([value] if where == "base.seed" and _is_int(value) else value, where)
    base = {k: v for k, v in base.items() if k != "seed"}
    list_fields = {"hidden_sizes", "disc_hidden", "ref_point"}
    grid: dict[str, list[Any]] = {}
    for key, values in grid_in.items():
        if key == "seed":
            continue
        if key in base:
            raise SweepError(f"'{key}' is both in base and in grid; keep one")
        values = values if isinstance(values, list) else [values]
        if not values:
            raise SweepError(f"grid.{key} is an empty list; give at least one value")
        if key in list_fields and not all(isinstance(v, list) or v is None for v in values):
            raise SweepError(f"grid.{key}={values!r} must be a list of lists, e.g. [[64, 64], [128, 128]]")
        if any(isinstance(v, (dict, set)) for v in values):
            raise SweepError(f"grid.{key}={values!r} holds a mapping; give plain values")
        if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
            raise SweepError(f"grid.{key}={values!r} lists a value twice")
        grid[key] = values
    spec_name = data.get("name", name)
    if not isinstance(spec_name, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", spec_name):
        raise SweepError(f"name={spec_name!r} must be a folder-safe name (letters, digits, '.', '_', '-')")
    return SweepSpec(spec_name, dict(base), grid, seeds)


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a YAML (or JSON) sweep spec; the default name is the file's stem."""
    import yaml

    p = Path(path)
    if not p.is_file():
        raise SweepError(f"sweep spec '{p}' does not exist")
    try:
        data = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise SweepError(f"sweep spec '{p}' could not be parsed: {str(exc).splitlines()[0]}") from None
    try:
        return parse_spec(data, name=re.sub(r"[^A-Za-z0-9._-]", "_", p.stem) or "sweep")
    except SweepError as exc:
        raise SweepError(f"sweep spec '{p}': {exc}") from None


def apply_overrides(spec: SweepSpec, overrides: dict[str, Any] | None = None, seeds: int | None = None) -> SweepSpec:
    """Return a copy of ``spec`` with command-line overrides.

    Args:
        spec: The spec.
        overrides: ``--set KEY=VALUE`` pairs; each goes into ``base``, and a key that is a grid axis pins that
            axis to the one value (``--set algo=mope`` runs only the MoPE half of the grid).
        seeds: ``--seeds N``: run seeds ``0..N-1`` instead of the spec's.
    """
    base, grid = dict(spec.base), {k: list(v) for k, v in spec.grid.items()}
    names = ["algo", *Config.field_names()]
    new_seeds = list(spec.seeds)
    for key, value in (overrides or {}).items():
        if key == "seed":
            new_seeds = _seed_list(value if isinstance(value, list) else [value], "--set seed")
            continue
        if key not in names:
            raise SweepError(f"unknown config key '{key}'{suggest(key, names)}")
        grid.pop(key, None)
        base[key] = value
    if seeds is not None:
        new_seeds = _seed_list(seeds, "--seeds")
    return SweepSpec(spec.name, base, grid, new_seeds)


def _fmt_value(v: Any) -> str:
    if isinstance(v, bool):
        return str(v).lower()
    if v is None:
        return "none"
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (list, tuple)):
        return ",".join(_fmt_value(x) for x in v)
    return str(v)


def trial_name(config: Config, params: dict[str, Any]) -> str:
    """Folder name ``<env>-<algo>-<field>=<value>-...-s<seed>`` (swept fields other than env and algo, in order)."""
    parts = [config.env_id, config.algo]
    parts += [f"{k}={_fmt_value(v)}" for k, v in params.items() if k not in ("env_id", "algo", "seed")]
    parts.append(f"s{config.seed}")
    return re.sub(r"[^A-Za-z0-9._=,+-]", "_", "-".join(parts))


def expand(spec: SweepSpec) -> list[Trial]:
    """All trials of a spec, seed-major (every grid point's seed 0 comes before any seed 1), each validated.

    Raises:
        SweepError: naming the trial whose config is invalid, or two trials that would share a folder.
    """
    axes = list(spec.grid)
    points = [dict(zip(axes, combo, strict=True)) for combo in itertools.product(*(spec.grid[a] for a in axes))]
    trials: list[Trial] = []
    seen: dict[str, dict[str, Any]] = {}
    for seed in spec.seeds:
        for point in points:
            params = {**point, "seed": seed}
            try:
                config = Config.from_dict({**spec.base, **point, "seed": seed})
            except ConfigError as exc:
                where = ", ".join(f"{k}={_fmt_value(v)}" for k, v in params.items())
                raise SweepError(f"trial ({where}): {exc}") from None
            name = trial_name(config, params)
            if name in seen:
                raise SweepError(f"trials {seen[name]} and {params} would share the folder '{name}'")
            seen[name] = params
            trials.append(Trial(name, params, config))
    return trials


def check_environments(trials: Iterable[Trial]) -> None:
    """Create each distinct environment once, so an unknown or unsupported id fails before any training."""
    from mope.envs import make_env

    for env_id in dict.fromkeys(t.config.env_id for t in trials):
        make_env(env_id).close()


def _config_differences(saved: dict[str, Any], wanted: dict[str, Any]) -> list[str]:
    return [k for k in wanted if k not in NON_RESULT_FIELDS and saved.get(k) != wanted[k]]


def check_existing(trials: Iterable[Trial], out: Path) -> None:
    """Refuse to reuse a trial folder that holds a run of a different config (the spec changed since).

    Raises:
        SweepError: naming the folder and the differing fields with both values.
    """
    for t in trials:
        path = out / t.name / "config.json"
        if not path.is_file():
            continue
        try:
            saved = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            continue  # an unreadable config belongs to a run that never got going; it is started afresh
        wanted = t.config.to_dict()
        differ = _config_differences(saved, wanted)
        if differ:
            what = ", ".join(f"{k} ({saved.get(k)!r} there, {wanted[k]!r} now)" for k in differ[:4])
            raise SweepError(f"trial folder '{out / t.name}' holds a run of another config: {what}; "
                             "use another --out or delete that folder")


# ------------------------------------------------------------------------------------------------------------
# running
# ------------------------------------------------------------------------------------------------------------
def _run_trial(name: str, config_dict: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Worker: train, resume or skip one trial; never raises for a failed training (it is recorded instead)."""
    import torch

    torch.set_num_threads(max(1, int(config_dict.get("torch_threads") or 1)))
    from mope.experiments import run_status, train_run

    out = Path(out_dir)
    t0 = time.perf_counter()
    status = run_status(out)
    action = {"finished": "skipped", "resumable": "resumed"}.get(status, "trained")
    try:
        if status != "finished":
            (out / "error.txt").unlink(missing_ok=True)
            train_run(Config.from_dict(config_dict), out, progress=False, overwrite=True, resume=True)
        final = json.loads((out / "summary.json").read_text()).get("final", {})
        return {"name": name, "status": "finished", "action": action, "final": final,
                "wall_s": time.perf_counter() - t0, "error": None}
    except Exception as exc:  # noqa: BLE001 - any failure of one trial is recorded, the sweep goes on
        with contextlib.suppress(OSError):  # the folder itself may be what failed; sweep.json keeps the error
            out.mkdir(parents=True, exist_ok=True)
            (out / "error.txt").write_text(traceback.format_exc())
        return {"name": name, "status": "failed", "action": "failed", "final": {},
                "wall_s": time.perf_counter() - t0, "error": f"{type(exc).__name__}: {exc}"}


def _run_trial_remote(name: str, config_dict: dict[str, Any], out_dir: str) -> dict[str, Any]:
    """Ray task: :func:`_run_trial`, in place when this node sees the sweep folder (a shared filesystem).

    Otherwise (a worker node or Ray Client cluster without the driver's filesystem) the trial trains into a
    temporary folder and comes back packed in ``rec["archive"]`` (a gzipped tar, without the resume checkpoint),
    for the driver to unpack into the sweep folder.
    """
    import io
    import tarfile
    import tempfile

    if (Path(out_dir).parent / "sweep.json").is_file():
        return _run_trial(name, config_dict, out_dir)
    with tempfile.TemporaryDirectory(prefix="mope-trial-") as tmp:
        rec = _run_trial(name, config_dict, str(Path(tmp) / name))
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w:gz") as tar:
            tar.add(Path(tmp) / name, arcname=name,
                    filter=lambda info: None if info.name.endswith(("resume.pt", "interrupted.pt")) else info)
        rec["archive"] = buf.getvalue()
    return rec


def unpack_trial(rec: dict[str, Any], out: Path) -> None:
    """Unpack a trial folder that a Ray task sent back (see :func:`_run_trial_remote`) into the sweep folder."""
    import io
    import tarfile

    archive = rec.pop("archive", None)
    if archive is None:
        return
    with tarfile.open(fileobj=io.BytesIO(archive), mode="r:gz") as tar:
        names = tar.getnames()
        if any((n != rec["name"] and not n.startswith(rec["name"] + "/")) or ".." in Path(n).parts for n in names):
            raise SweepError(f"the archive of trial '{rec['name']}' holds files outside its folder")
        safe = {"filter": "data"} if hasattr(tarfile, "data_filter") else {}  # Python >= 3.11.4
        tar.extractall(out, **safe)


def _init_worker() -> None:
    import torch

    torch.set_num_threads(1)


class _Summary:
    """The live line: a bar over trials with done / running / failed / skipped counts."""

    def __init__(self, total: int, done: int, enabled: bool) -> None:
        from tqdm.auto import tqdm

        self.done, self.failed, self.skipped, self.running = done, 0, done, 0
        self.bar = tqdm(total=total, initial=done, desc="sweep", unit="trial", disable=not enabled)
        self.refresh()

    def refresh(self, redraw: bool = True) -> None:
        self.bar.set_postfix_str(f"done {self.done}, running {self.running}, failed {self.failed}, "
                                 f"skipped {self.skipped}", refresh=redraw)

    def finished(self, rec: dict[str, Any]) -> None:
        if rec["status"] == "failed":
            self.failed += 1
            self.bar.write(f"trial {rec['name']} failed: {rec['error']}")
        else:
            self.done += 1
            self.skipped += rec["action"] == "skipped"
        self.running = max(0, self.running - 1)
        self.refresh(redraw=False)
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def _local_backend(jobs: list[tuple[str, dict[str, Any], str]], workers: int,
                   on_done: Callable[[dict[str, Any]], None], on_running: Callable[[int], None]) -> None:
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker)
    try:
        pending: set[Future] = {pool.submit(_run_trial, *job) for job in jobs}
        while pending:
            finished, pending = wait(pending, timeout=1.0, return_when=FIRST_COMPLETED)
            for fut in finished:
                try:
                    on_done(fut.result())
                except BrokenProcessPool as exc:  # a worker was killed (OOM killer, signal): not a trial error
                    raise SweepError(f"a trial process died ({exc}); run the sweep again to resume "
                                     "the unfinished trials") from None
            on_running(min(workers, sum(f.running() for f in pending)))
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _ray_backend(jobs: list[tuple[str, dict[str, Any], str]], out: Path, workers: int | None, address: str | None,
                 on_done: Callable[[dict[str, Any]], None], on_running: Callable[[int], None]) -> None:
    try:
        import ray
    except ImportError:
        raise SweepError(RAY_MISSING) from None
    started = False
    if not ray.is_initialized():
        # a local instance sized to --workers; a cluster (or Ray Client, ray://) takes only its address
        kwargs: dict[str, Any] = {"address": address} if address is not None else \
            {"include_dashboard": False, "log_to_driver": False, "num_cpus": workers}
        try:
            ray.init(**kwargs)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise SweepError(f"could not connect to Ray at address={address!r}: {exc}") from None
        started = True
    try:
        slots = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        remote = ray.remote(num_cpus=1, max_retries=0)(_run_trial_remote)
        queue = list(jobs)
        pending: list[Any] = []
        while queue or pending:
            while queue and len(pending) < slots:  # keep at most `slots` trials in flight
                pending.append(remote.remote(*queue.pop(0)))
            ready, pending = ray.wait(pending, num_returns=1, timeout=1.0)
            for ref in ready:
                rec = ray.get(ref)
                unpack_trial(rec, out)
                on_done(rec)
            on_running(len(pending))
    finally:
        if started:
            ray.shutdown()


def run_sweep(spec: SweepSpec | str | Path, out_dir: str | Path | None = None, backend: str = "local",
              address: str | None = None, workers: int | None = None, progress: bool = True) -> list[TrialResult]:
    """Run every trial of a sweep; skip finished trials, resume interrupted ones.

    Args:
        spec: A :class:`SweepSpec` or the path of a YAML spec.
        out_dir: Sweep folder (default ``runs/<spec name>``); trials go into sub-folders.
        backend: ``local`` (a process pool on this machine) or ``ray`` (Ray tasks).
        address: Ray cluster address (``auto``, ``ray://host:10001``); ``None`` starts a local Ray instance.
            Only for the ray backend.
        workers: Trials at once (default: every core for local, every cluster CPU for Ray).
        progress: Show the live summary.

    Returns:
        One :class:`TrialResult` per trial, in the spec's order.

    Raises:
        SweepError: for a bad spec, backend or worker count, before anything is launched.
    """
    if backend not in BACKENDS:
        raise SweepError(f"unknown backend '{backend}'{suggest(backend, BACKENDS)}; "
                         f"choose one of {', '.join(BACKENDS)}")
    if address is not None and backend != "ray":
        raise SweepError(f"--address {address} needs --backend ray")
    if workers is not None and (not _is_int(workers) or workers < 1):
        raise SweepError(f"workers={workers!r} is out of range: must be >= 1")
    if not isinstance(spec, SweepSpec):
        spec = load_spec(spec)
    if backend == "ray":
        try:
            import ray  # noqa: F401
        except ImportError:
            raise SweepError(RAY_MISSING) from None
    trials = expand(spec)
    check_environments(trials)
    out = Path(out_dir) if out_dir is not None else Path("runs") / spec.name
    check_existing(trials, out)
    out.mkdir(parents=True, exist_ok=True)

    from mope.experiments import run_status

    records: dict[str, dict[str, Any]] = {}
    for t in trials:
        if run_status(out / t.name) == "finished":
            summary = json.loads((out / t.name / "summary.json").read_text())
            records[t.name] = {"name": t.name, "status": "finished", "action": "skipped",
                               "final": summary.get("final", {}), "wall_s": 0.0, "error": None}
    jobs = [(t.name, t.config.to_dict(), str(out / t.name)) for t in trials if t.name not in records]
    state: dict[str, Any] = {"backend": backend, "address": address, "started": time.time()}
    _write_sweep_json(out, spec, trials, records, state)

    summary_line = _Summary(len(trials), len(records), progress)

    def on_done(rec: dict[str, Any]) -> None:
        records[rec["name"]] = rec
        summary_line.finished(rec)
        _write_sweep_json(out, spec, trials, records, state)

    def on_running(n: int) -> None:
        if n != summary_line.running:
            summary_line.running = n
            summary_line.refresh()

    t0 = time.perf_counter()
    try:
        if jobs and backend == "local":
            _local_backend(jobs, min(workers or os.cpu_count() or 1, len(jobs)), on_done, on_running)
        elif jobs:
            _ray_backend(jobs, out, workers, address, on_done, on_running)
    finally:
        summary_line.close()
        state["wall_s"] = time.perf_counter() - t0
        _write_sweep_json(out, spec, trials, records, state)
    return [_result(out, t, records[t.name]) for t in trials]


def _result(out: Path, trial: Trial, rec: dict[str, Any]) -> TrialResult:
    return TrialResult(trial.name, out / trial.name, rec["status"], rec["action"], rec.get("final") or {},
                       float(rec.get("wall_s", 0.0)), rec.get("error"))


def _write_sweep_json(out: Path, spec: SweepSpec, trials: Sequence[Trial], records: dict[str, dict[str, Any]],
                      state: dict[str, Any]) -> None:
    rows = []
    for t in trials:
        rec = records.get(t.name, {})
        rows.append({"name": t.name, "params": t.params, "status": rec.get("status", "pending"),
                     "action": rec.get("action"), "wall_s": rec.get("wall_s"), "error": rec.get("error")})
    doc = {"spec": spec.to_dict(), "swept": [*spec.grid, "seed"], **state, "trials": rows}
    tmp = out / "sweep.json.tmp"
    tmp.write_text(json.dumps(doc, indent=2, default=_json_default) + "\n")
    tmp.replace(out / "sweep.json")


def _json_default(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return str(x)


# ------------------------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------------------------
def parse_set(items: Sequence[str] | None) -> dict[str, Any]:
    """``KEY=VALUE`` pairs; VALUE is read as YAML (numbers, lists, true/false, null), else kept as a string."""
    import yaml

    out: dict[str, Any] = {}
    for item in items or ():
        if "=" not in item:
            raise SweepError(f"--set '{item}' is not KEY=VALUE")
        key, raw = item.split("=", 1)
        key = key.strip().replace("-", "_")
        try:
            out[key] = yaml.safe_load(raw)
        except yaml.YAMLError:
            out[key] = raw
    return out


def sweep_command(spec_path: str | Path, out: str | Path | None = None, backend: str = "local",
                  address: str | None = None, workers: int | None = None, sets: Sequence[str] | None = None,
                  seeds: int | None = None, progress: bool = True) -> list[TrialResult]:
    """What ``mope sweep SPEC`` does: load the spec, apply ``--set``/``--seeds``, run, print one line per trial.

    Raises:
        MopeError: for bad input (the CLI prints it as ``error: ...``).
    """
    spec = apply_overrides(load_spec(spec_path), parse_set(sets), seeds)
    out_dir = Path(out) if out is not None else Path("runs") / spec.name
    t0 = time.perf_counter()
    results = run_sweep(spec, out_dir, backend=backend, address=address, workers=workers, progress=progress)
    for r in results:
        f = r.final
        metrics = "  ".join(f"{k} {f[k]:.3f}" for k in ("cr", "hv", "eum") if isinstance(f.get(k), (int, float))
                            and math.isfinite(f[k]))
        print(f"{r.action:8s} {r.name}  {metrics if r.status == 'finished' else r.error}")
    failed = sum(r.status == "failed" for r in results)
    print(f"{len(results) - failed} of {len(results)} trials finished, {failed} failed "
          f"[{time.perf_counter() - t0:.0f} s]; sweep folder: {out_dir}")
    if failed:
        with contextlib.suppress(StopIteration):
            first = next(r for r in results if r.status == "failed")
            print(f"see {first.out_dir / 'error.txt'} for the first failure")
    return results


__all__ = ["SweepError", "SweepSpec", "Trial", "TrialResult", "apply_overrides", "expand", "load_spec",
           "parse_spec", "run_sweep", "sweep_command", "trial_name"]
