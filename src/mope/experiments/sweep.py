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
import re
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mope.config import Config, _parse_problem, load_yaml, read_text_file
from mope.config import parse_set as parse_set_items
from mope.errors import ConfigError, short_repr, suggest
from mope.experiments.jobs import Job, JobError, check_backend, check_job_folders, run_jobs
from mope.experiments.locks import FolderLock

SPEC_KEYS = ("name", "base", "grid", "arms", "seeds", "seed")
#: A sweep may hold this many trials at most (each is validated before any runs, and sweep.json lists them all).
MAX_TRIALS = 100_000
#: From this many trials on, the sweep says how many before it starts.
LARGE_SWEEP = 1_000
#: sweep.json is rewritten as trials finish, at most once per this many seconds (and at the end), so a sweep of
#: many short trials does not spend its time rewriting a file that grows with the trial count.
SWEEP_JSON_EVERY_S = 2.0


class SweepError(ConfigError):
    """A sweep spec is malformed, or a sweep cannot be run as asked (a :class:`ConfigError`, so a bad ``--seeds``
    is one for every command that takes it)."""


@dataclass
class SweepSpec:
    """A parsed and validated sweep spec.

    Attributes:
        name: Name of the sweep (the default output folder is ``runs/<name>``).
        base: Fixed Config fields (``algo`` allowed).
        grid: Axis name -> list of values; axes are ``algo`` and Config fields, never ``seed``.
        arms: Arm name -> settings: named one-off changes (an ablation's arms), each crossed with the grid.
        seeds: Seeds, run for every grid point.
    """

    name: str
    base: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, list[Any]] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=lambda: [0])
    arms: dict[str, dict[str, Any]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict in the spec file's layout."""
        return {"name": self.name, "base": self.base, "grid": self.grid, "arms": self.arms, "seeds": self.seeds}


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
        if value < 1 or value > MAX_TRIALS:
            raise SweepError(f"{where}={value} is out of range: give a count in [1, {MAX_TRIALS}] or a list of seeds")
        return list(range(value))
    if isinstance(value, list) and value and all(_is_int(s) and s >= 0 for s in value):
        if len(set(value)) != len(value):
            raise SweepError(f"{where}={short_repr(value)} lists a seed twice")
        return list(value)
    raise SweepError(f"{where}={short_repr(value)} is not a seed count or a non-empty list of seeds >= 0")


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
    axes_names = ["algo", "preset", *fields]
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
            raise SweepError(f"grid.{key}={short_repr(values)} must be a list of lists, e.g. [[64, 64], [128, 128]]")
        if any(isinstance(v, (dict, set)) for v in values):
            raise SweepError(f"grid.{key}={short_repr(values)} holds a mapping; give plain values")
        if len({json.dumps(v, sort_keys=True) for v in values}) != len(values):
            raise SweepError(f"grid.{key}={short_repr(values)} lists a value twice")
        grid[key] = values
    spec_name = data.get("name", name)
    if not isinstance(spec_name, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._-]*", spec_name):
        raise SweepError(f"name={short_repr(spec_name)} must be a folder-safe name (letters, digits, '.', '_', '-')")
    return SweepSpec(spec_name, dict(base), grid, seeds, _parse_arms(data.get("arms") or {}, axes_names, grid))


def _parse_arms(arms: Any, axes_names: list[str], grid: dict[str, list[Any]]) -> dict[str, dict[str, Any]]:
    """Validate ``arms``: a mapping of folder-safe names to mappings of config keys not on the grid."""
    if not isinstance(arms, dict):
        raise SweepError(f"'arms' must map arm names to settings; got {type(arms).__name__}")
    for arm, settings in arms.items():
        if not isinstance(arm, str) or not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._+-]*", arm):
            raise SweepError(f"arm name {arm!r} must be folder-safe (letters, digits, '.', '_', '+', '-')")
        if not isinstance(settings, dict):
            raise SweepError(f"arms.{arm} must be a mapping of config fields (use {{}} for none)")
        for key in settings:
            if key not in axes_names or key == "seed":
                raise SweepError(f"unknown config key '{key}' in arms.{arm}{suggest(str(key), axes_names)}")
            if key in grid:
                raise SweepError(f"'{key}' is both a grid axis and set by arms.{arm}; keep one")
    return {str(a): dict(v) for a, v in arms.items()}


def load_spec(path: str | Path) -> SweepSpec:
    """Read and validate a YAML (or JSON) sweep spec; the default name is the file's stem."""
    p = Path(path)
    text = read_text_file(p, "sweep spec", SweepError)
    try:
        data = load_yaml(text)
    except Exception as exc:  # noqa: BLE001 - any parse failure (an alias bomb, a recursion) is the user's file
        raise SweepError(f"sweep spec '{p}' could not be parsed: {_parse_problem(exc)}") from None
    try:
        return parse_spec(data, name=re.sub(r"[^A-Za-z0-9._-]", "_", p.stem) or "sweep")
    except SweepError as exc:
        raise SweepError(f"sweep spec '{p}': {exc}") from None


def parse_seeds(text: str | int | list[int]) -> int | list[int]:
    """``--seeds``: a count ``N`` (seeds ``0..N-1``), a range ``A-B`` (``A..B``, both included) or a list ``a,b,c``
    (a count or a list passes through).

    Raises:
        SweepError: naming the text, if it is none of these (the range or list is checked by the spec's rules).
    """
    if isinstance(text, (int, list)):
        return text
    raw = str(text).strip()
    try:
        if "," in raw:
            return [int(part) for part in raw.split(",")]
        if "-" not in raw.lstrip("-"):
            return int(raw)
        lo, hi = (int(part) for part in raw.split("-", 1))
    except ValueError:
        raise SweepError(f"--seeds={raw!r} is not a count (5), a range (5-9) or a list of seeds (0,5,7)") from None
    if hi < lo:
        raise SweepError(f"--seeds={raw!r}: the range ends before it starts")
    return list(range(lo, hi + 1))


def seed_list(seeds: int | str | Sequence[int], where: str = "--seeds") -> list[int]:
    """The seeds a ``--seeds`` value names: a count ``N`` (``0..N-1``), a range ``"5-9"``, a list ``"0,5,7"`` or
    ``[0, 5, 7]``; the one parser of ``mope sweep``, ``mope reproduce`` and ``mope benchmark``.

    Raises:
        SweepError: naming the value, for anything else, a count below 1, a negative or repeated seed.
    """
    return _seed_list(parse_seeds(list(seeds) if isinstance(seeds, (list, tuple)) else seeds), where)


def apply_overrides(spec: SweepSpec, overrides: dict[str, Any] | None = None,
                    seeds: int | str | list[int] | None = None) -> SweepSpec:
    """Return a copy of ``spec`` with command-line overrides.

    Args:
        spec: The spec.
        overrides: ``--set KEY=VALUE`` pairs; each goes into ``base``, and a key that is a grid axis pins that
            axis to the one value (``--set algo=mope`` runs only the MoPE half of the grid).
        seeds: ``--seeds``: run these seeds instead of the spec's: a count ``N`` (``0..N-1``), a range ``"5-9"``,
            a list ``"0,5,7"`` or ``[0, 5, 7]`` (:func:`parse_seeds`).
    """
    base, grid = dict(spec.base), {k: list(v) for k, v in spec.grid.items()}
    names = ["algo", "preset", *Config.field_names()]
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
        new_seeds = seed_list(seeds)
    return SweepSpec(spec.name, base, grid, new_seeds, dict(spec.arms))


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
    parts += [str(params["arm"])] if "arm" in params else []
    parts += [f"{k}={_fmt_value(v)}" for k, v in params.items() if k not in ("env_id", "algo", "seed", "arm")]
    parts.append(f"s{config.seed}")
    return re.sub(r"[^A-Za-z0-9._=,+-]", "_", "-".join(parts))


def expand(spec: SweepSpec) -> list[Trial]:
    """All trials of a spec, seed-major (every grid point's seed 0 comes before any seed 1), each validated.

    Raises:
        SweepError: naming the trial whose config is invalid, or two trials that would share a folder.
    """
    count = trial_count(spec)
    if count > MAX_TRIALS:
        raise SweepError(f"the sweep has {count} trials ({_count_terms(spec)}); a sweep may hold {MAX_TRIALS} at most: "
                         "shorten the grid or the seeds, or split it into several sweeps")
    axes = list(spec.grid)
    points = [dict(zip(axes, combo, strict=True)) for combo in itertools.product(*(spec.grid[a] for a in axes))]
    arms: dict[str | None, dict[str, Any]] = dict(spec.arms) or {None: {}}
    trials: list[Trial] = []
    seen: dict[str, dict[str, Any]] = {}
    for seed, point, arm in itertools.product(spec.seeds, points, arms):
        params = {**point, **({"arm": arm} if arm is not None else {}), "seed": seed}
        try:
            config = Config.from_dict({**spec.base, **arms[arm], **point, "seed": seed})
        except ConfigError as exc:
            where = ", ".join(f"{k}={_fmt_value(v)}" for k, v in params.items())
            raise SweepError(f"trial ({where}): {exc}") from None
        name = trial_name(config, params)
        if name in seen:
            raise SweepError(f"trials {seen[name]} and {params} would share the folder '{name}'")
        seen[name] = params
        trials.append(Trial(name, params, config))
    return trials


def trial_count(spec: SweepSpec) -> int:
    """The number of trials: grid points x arms x seeds (computed without listing them)."""
    return math.prod(len(v) for v in spec.grid.values()) * max(1, len(spec.arms)) * len(spec.seeds)


def _count_terms(spec: SweepSpec) -> str:
    terms = [f"{len(v)} {k}" for k, v in spec.grid.items()] + ([f"{len(spec.arms)} arms"] if spec.arms else [])
    return " x ".join([*terms, f"{len(spec.seeds)} seeds"])


def check_environments(trials: Iterable[Trial]) -> None:
    """Create each distinct environment once, so an unknown or unsupported id fails before any training."""
    from mope.envs import make_env

    for env_id in dict.fromkeys(t.config.env_id for t in trials):
        make_env(env_id).close()


def check_existing(trials: Iterable[Trial], out: Path) -> None:
    """Refuse to reuse a trial folder that holds a run of a different config (the spec changed since).

    Raises:
        SweepError: naming the folder and the differing fields with both values.
    """
    try:
        check_job_folders([Job(t.name, "train", t.config.to_dict()) for t in trials], out)
    except JobError as exc:
        raise SweepError(str(exc).replace("folder '", "trial folder '", 1)) from None


# ------------------------------------------------------------------------------------------------------------
# running
# ------------------------------------------------------------------------------------------------------------
def run_sweep(spec: SweepSpec | str | Path, out_dir: str | Path | None = None, backend: str = "local",
              address: str | None = None, workers: int | None = None, progress: bool = True) -> list[TrialResult]:
    """Run every trial of a sweep through :func:`mope.experiments.jobs.run_jobs`; skip finished trials, resume
    interrupted ones.

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
        SweepError: for a bad spec, backend or worker count, before anything is launched; FolderLockedError when
            another process is running a sweep in the same folder.
    """
    try:
        check_backend(backend, address, workers)
    except JobError as exc:
        raise SweepError(str(exc)) from None
    if not isinstance(spec, SweepSpec):
        spec = load_spec(spec)
    count = trial_count(spec)
    if LARGE_SWEEP <= count <= MAX_TRIALS:
        print(f"note: this sweep has {count} trials ({_count_terms(spec)}); each trains a run folder of its own, so "
              "it will take a while; stop it at any time (Ctrl-C) and run the same command again to go on",
              file=sys.stderr, flush=True)
    trials = expand(spec)
    check_environments(trials)
    out = Path(out_dir) if out_dir is not None else Path("runs") / spec.name
    check_existing(trials, out)
    with FolderLock(out, what="sweep folder"):
        records: dict[str, dict[str, Any]] = {}
        state: dict[str, Any] = {"backend": backend, "address": address, "started": time.time()}
        writer = _SweepJson(out, spec, trials, records, state)
        writer.write()

        def on_done(rec: dict[str, Any]) -> None:
            records[rec["name"]] = rec
            writer.write(soon=True)

        t0 = time.perf_counter()
        jobs = [Job(t.name, "train", t.config.to_dict()) for t in trials]
        try:
            run_jobs(jobs, out, backend, workers, address, progress, desc="sweep", on_done=on_done)
        except JobError as exc:
            raise SweepError(str(exc)) from None
        finally:
            state["wall_s"] = time.perf_counter() - t0
            writer.write()
    return [_result(out, t, records[t.name]) for t in trials]


def _result(out: Path, trial: Trial, rec: dict[str, Any]) -> TrialResult:
    return TrialResult(trial.name, out / trial.name, rec["status"], rec["action"], rec.get("final") or {},
                       float(rec.get("wall_s", 0.0)), rec.get("error"))


class _SweepJson:
    """Writes ``sweep.json``; ``write(soon=True)`` (a trial finished) skips the write when the last one was less than
    :data:`SWEEP_JSON_EVERY_S` ago (the next one, or the final one, has it), so writing stays a small share of the
    sweep's time however many trials it has."""

    def __init__(self, out: Path, spec: SweepSpec, trials: Sequence[Trial], records: dict[str, dict[str, Any]],
                 state: dict[str, Any]) -> None:
        self.out, self.spec, self.trials, self.records, self.state = out, spec, trials, records, state
        self.arm_fields = _arm_fields(spec, trials)
        self.last = -math.inf
        self.cost = 0.0

    def write(self, soon: bool = False) -> None:
        now = time.monotonic()
        if soon and now - self.last < max(SWEEP_JSON_EVERY_S, 20 * self.cost):
            return
        _write_sweep_json(self.out, self.spec, self.trials, self.records, self.state, self.arm_fields)
        self.last = time.monotonic()
        self.cost = self.last - now


def _write_sweep_json(out: Path, spec: SweepSpec, trials: Sequence[Trial], records: dict[str, dict[str, Any]],
                      state: dict[str, Any], arm_fields: list[str] | None = None) -> None:
    rows = []
    for t in trials:
        rec = records.get(t.name, {})
        rows.append({"name": t.name, "params": t.params, "status": rec.get("status", "pending"),
                     "action": rec.get("action"), "wall_s": rec.get("wall_s"), "error": rec.get("error")})
    arm_fields = _arm_fields(spec, trials) if arm_fields is None else arm_fields
    doc = {"spec": spec.to_dict(), "swept": [*spec.grid, *(["arm"] if spec.arms else []), "seed"],
           "arm_fields": arm_fields, **state, "trials": rows}
    tmp = out / "sweep.json.tmp"
    tmp.write_text(json.dumps(doc, indent=2, default=_json_default) + "\n")
    tmp.replace(out / "sweep.json")


def _arm_fields(spec: SweepSpec, trials: Sequence[Trial]) -> list[str]:
    """The config fields the arms change (a preset resolves to many): those that differ across the trials beyond the
    seed and the grid's axes."""
    if not spec.arms:
        return []
    configs = [t.config.to_dict() for t in trials]
    return [k for k in configs[0] if k not in ("seed", "algo", *spec.grid)
            and len({json.dumps(c[k], sort_keys=True) for c in configs}) > 1]


def _json_default(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return str(x)


# ------------------------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------------------------
def parse_set(items: Sequence[str] | None) -> dict[str, Any]:
    """A sweep's ``--set`` pairs: :func:`mope.config.parse_set` (keys are checked by :func:`apply_overrides`)."""
    return parse_set_items(items, error=SweepError)


def sweep_command(spec_path: str | Path, out: str | Path | None = None, backend: str = "local",
                  address: str | None = None, workers: int | None = None, sets: Sequence[str] | None = None,
                  seeds: int | str | None = None, progress: bool = True) -> list[TrialResult]:
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


__all__ = ["SweepError", "SweepSpec", "Trial", "TrialResult", "apply_overrides", "expand", "load_spec", "seed_list",
           "parse_spec", "run_sweep", "sweep_command", "trial_name"]
