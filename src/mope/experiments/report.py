"""``mope report RUNS_DIR``: aggregate run folders across seeds into a table and plots.

Every folder under ``RUNS_DIR`` that holds ``config.json`` and ``metrics.csv`` is a run. Runs are grouped by
their config minus the seed: with a ``sweep.json`` at the root, by the sweep's grid axes; without one, by
every field whose value differs between runs. Runs in one group must agree on every other field (fields
that do not change results, device and thread count, aside); otherwise :class:`ReportError` lists the
differing fields, or, with ``split_mismatched=True``, those fields split the groups too.

Per group and metric, over the final evaluation of each seed: mean, sample standard deviation, a bootstrap
95% confidence interval of the mean (percentile method, seeded) and the interquartile mean (IQM, the mean of
the middle 50%; equal to the mean below 4 seeds, so the table shows it only from 4 seeds on). Metrics that
are NaN for every run (CR and optimal share of an environment without a known front) are left out.

Outputs in ``out_dir`` (default ``RUNS_DIR/report``): ``report.md`` (the table), ``report.json`` (every
number), ``curves.png`` (learning curves, mean and bootstrap 95% band) and ``fronts.png`` (the distinct final
solutions of each group, pooled over seeds, with the true CCS where the environment publishes one).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mope.errors import MopeError, is_disk_full
from mope.experiments.stats import MetricStats, aggregate, bootstrap_ci, iqm  # noqa: F401 - iqm: read here before

DEFAULT_METRICS = ("cr", "igd", "hv", "eum", "optimal_share", "timeout_share", "path_error", "overestimation",
                   "win_share", "out_share")
METRIC_LABELS = {"cr": "CR", "hv": "HV", "eum": "EUM", "optimal_share": "optimal share",
                 "timeout_share": "time-outs", "eum_gap": "EUM gap", "precision": "precision", "recall": "recall",
                 "cardinality": "cardinality", "eum_optimal": "EUM optimum", "igd": "IGD", "path_error": "path error",
                 "overestimation": "overestimate at s0",
                 "win_share": "wins", "out_share": "out of arena", "loss_share": "losses"}
#: Number formats per metric in report.md (report.json keeps full precision).
FORMATS = {"overestimation": ".3f", "igd": ".2f", "hv": ".1f", "eum": ".2f", "eum_gap": ".2f", "eum_optimal": ".2f",
           "cardinality": ".1f"}
#: Config fields that never split groups: the seed, and settings that do not change a run's results.
IGNORED_FIELDS = ("seed", "device", "torch_threads", "checkpoint_every", "log_every")
#: Fields named first in group labels.
LEAD_FIELDS = ("env_id", "algo", "arm")


class ReportError(MopeError):
    """The runs folder holds no runs, or runs that cannot be compared."""


@dataclass
class Run:
    """One run folder: its config and its evaluations."""

    path: Path
    config: dict[str, Any]
    rows: list[dict[str, float]]

    @property
    def final(self) -> dict[str, float]:
        """The last evaluation."""
        return self.rows[-1]


@dataclass
class Group:
    """Runs that differ only in the seed."""

    label: str
    key: dict[str, Any]
    runs: list[Run]
    stats: dict[str, MetricStats] = field(default_factory=dict)


@dataclass
class ReportResult:
    """What :func:`report` returns."""

    out_dir: Path
    groups: list[Group]
    metrics: list[str]
    table: str
    notes: list[str]
    files: dict[str, Path]


# ------------------------------------------------------------------------------------------------------------
# finding and grouping runs
# ------------------------------------------------------------------------------------------------------------
def _read_rows(path: Path) -> list[dict[str, float]]:
    """The rows of a numeric CSV file (:func:`mope.experiments.runs.read_csv_rows`; an empty cell is NaN).

    Raises:
        ReportError: naming the file, the line and the column of a cell that is not a number, or why the file
            cannot be read.
    """
    from mope.experiments.runs import RunFolderError, read_csv_rows

    try:
        return read_csv_rows(path)
    except RunFolderError as exc:
        raise ReportError(str(exc)) from None


def find_runs(runs_dir: str | Path) -> tuple[list[Run], list[str]]:
    """Every run folder under ``runs_dir`` (sorted by path), and notes on folders left out.

    A run is left out when its ``metrics.csv`` has no rows, or when it is unfinished: no ``summary.json`` and
    a last evaluation before ``total_steps``.
    """
    root = Path(runs_dir)
    if root.exists() and not root.is_dir():
        raise ReportError(f"runs folder '{root}' is a file; give the folder that holds the runs (or a sweep folder)")
    if not root.is_dir():
        raise ReportError(f"runs folder '{root}' does not exist")
    from mope.agent.agent import without_inert_reward_norm  # saved before reward_norm existed: the same runs
    from mope.config import migrate  # a config saved before a field existed reads the value it ran with

    runs, notes = [], []
    for cfg_path in sorted(root.rglob("config.json")):
        folder = cfg_path.parent
        if not (folder / "metrics.csv").is_file():
            continue
        try:
            config = json.loads(cfg_path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ReportError(f"'{cfg_path}' is not valid JSON: {exc}") from None
        except OSError as exc:
            raise ReportError(f"'{cfg_path}' could not be read: {exc.strerror or exc}") from None
        if not isinstance(config, dict):
            raise ReportError(f"'{cfg_path}' does not hold a mope config (a JSON mapping)")
        rows = _read_rows(folder / "metrics.csv")
        rel = folder.relative_to(root)
        if not rows:
            notes.append(f"left out {rel}: no evaluations in metrics.csv")
            continue
        if not (folder / "summary.json").is_file() and rows[-1].get("step", 0) < config.get("total_steps", 0):
            notes.append(f"left out {rel}: unfinished (last evaluation at step {rows[-1]['step']:.0f} of "
                         f"{config.get('total_steps')})")
            continue
        runs.append(Run(folder, without_inert_reward_norm(migrate(config)), rows))
    if not runs:
        raise ReportError(f"no finished run folders (config.json + metrics.csv) under '{root}'")
    return runs, notes


def _canon(v: Any) -> str:
    """A setting's value as compared between runs: 25 and 25.0 are the same (a float field given an integer by
    ``--set`` is saved as one; integer fields never hold floats)."""
    return json.dumps(_as_float(v), sort_keys=True)


def _as_float(v: Any) -> Any:
    if isinstance(v, bool):
        return v
    if isinstance(v, int):
        return float(v)
    if isinstance(v, (list, tuple)):
        return [_as_float(x) for x in v]
    if isinstance(v, dict):
        return {k: _as_float(x) for k, x in v.items()}
    return v


def _varying(runs: Sequence[Run], ignore: Sequence[str]) -> list[str]:
    keys = list(dict.fromkeys(k for r in runs for k in r.config))
    return [k for k in keys if k not in ignore and len({_canon(r.config.get(k)) for r in runs}) > 1]


def _sweep_doc(runs_dir: Path) -> dict[str, Any] | None:
    path = runs_dir / "sweep.json"
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError:
        return None


def _swept_fields(runs_dir: Path) -> list[str] | None:
    doc = _sweep_doc(runs_dir)
    return None if doc is None else [k for k in doc.get("swept", []) if k != "seed"]


def _label_arms(runs: Sequence[Run], runs_dir: Path) -> list[str]:
    """Give each run of a sweep with arms its arm (as a pseudo-field ``arm``); return the fields the arms set."""
    doc = _sweep_doc(runs_dir) or {}
    arms = {t["name"]: t.get("params", {}).get("arm") for t in doc.get("trials", []) if "name" in t}
    for r in runs:
        arm = arms.get(r.path.name)
        if arm is not None:
            r.config = {**r.config, "arm": arm}
    return list(doc.get("arm_fields", []))


def _label(key: dict[str, Any]) -> str:
    if not key:
        return "all runs"
    parts = [str(key[k]) for k in LEAD_FIELDS if k in key]
    parts += [f"{k}={_short(v)}" for k, v in key.items() if k not in LEAD_FIELDS]
    return " ".join(parts)


def _short(v: Any) -> str:
    if isinstance(v, list):
        return ",".join(_short(x) for x in v)
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def group_runs(runs: Sequence[Run], swept: Sequence[str] | None = None,
               split_mismatched: bool = False, arm_fields: Sequence[str] = ()) -> tuple[list[Group], list[str]]:
    """Group runs by config minus seed.

    Args:
        runs: The runs.
        swept: The fields a sweep varied (its grid axes); ``None`` groups by every field that varies.
        split_mismatched: When runs of one group differ in fields beyond ``swept``, split by them too (with a
            note) instead of raising.
        arm_fields: The fields a sweep's arms set; the pseudo-field ``arm`` stands for them.

    Returns:
        The groups, in order of first appearance, and notes.

    Raises:
        ReportError: listing the fields, and their values, in which runs that should be comparable differ.
    """
    notes: list[str] = []
    varying = _varying(runs, IGNORED_FIELDS)
    if swept is None:
        by = varying
        extra = [k for k in varying if k not in (*LEAD_FIELDS, "experience_exploration", "preference_exploration")]
        if extra:
            notes.append(f"no sweep.json: runs are grouped by every field that differs, including "
                         f"{', '.join(extra)}")
    else:
        by = [k for k in swept if k in varying or k in LEAD_FIELDS]
        derived = {"algo": ("experience_exploration", "preference_exploration"), "arm": tuple(arm_fields)}
        covered = set(by) | {d for k in by for d in derived.get(k, ())}
        extra = [k for k in varying if k not in covered]
        if extra:
            detail = "; ".join(f"{k}: " + ", ".join(sorted({_short(r.config.get(k)) for r in runs})) for k in extra)
            if not split_mismatched:
                raise ReportError(f"runs differ in config beyond the seed and the swept fields "
                                  f"({', '.join(swept) or 'none'}): {detail}; report them separately, or pass "
                                  "--split-mismatched to group by these fields too")
            notes.append(f"runs differ beyond the swept fields; also grouped by {detail}")
            by = by + extra
    by = [k for k in by if k not in ("experience_exploration", "preference_exploration") or "algo" not in by]
    by = sorted(by, key=lambda k: (LEAD_FIELDS.index(k) if k in LEAD_FIELDS else len(LEAD_FIELDS)))
    groups: dict[str, Group] = {}
    for r in runs:
        key = {k: r.config.get(k) for k in by}
        g = groups.setdefault(_canon(key), Group(_label(key), key, []))
        g.runs.append(r)
    for g in groups.values():
        seeds = [r.config.get("seed") for r in g.runs]
        if len(set(map(_canon, seeds))) != len(seeds):
            raise ReportError(f"group '{g.label}' holds seed {_dupe(seeds)} twice "
                              f"({', '.join(str(r.path) for r in g.runs if r.config.get('seed') == _dupe(seeds))}); "
                              "report the folders separately")
    return list(groups.values()), notes


def _dupe(xs: Sequence[Any]) -> Any:
    seen = set()
    for x in xs:
        if _canon(x) in seen:
            return x
        seen.add(_canon(x))
    return None


# ------------------------------------------------------------------------------------------------------------
# outputs
# ------------------------------------------------------------------------------------------------------------
def _fmt(x: float, metric: str) -> str:
    return "n/a" if not math.isfinite(x) else f"{x:{FORMATS.get(metric, '.3f')}}"


def render_table(groups: Sequence[Group], metrics: Sequence[str]) -> str:
    """Markdown: one row per group; each metric as ``mean ± std [CI low, CI high]``, IQM columns from 4 seeds."""
    from mope.experiments.plots import markdown_table

    show_iqm = max(len(g.runs) for g in groups) >= 4
    header = ["group", "seeds", "steps"] + [METRIC_LABELS.get(m, m) for m in metrics]
    if show_iqm:
        header += [f"{METRIC_LABELS.get(m, m)} IQM" for m in metrics]
    rows = []
    for g in groups:
        steps = sorted({int(r.final.get("step", 0)) for r in g.runs})
        row = [g.label, str(len(g.runs)), "/".join(map(str, steps))]
        for m in metrics:
            s = g.stats[m]
            row.append("n/a" if s.n == 0 else
                       f"{_fmt(s.mean, m)} ± {_fmt(s.std, m)} [{_fmt(s.ci_low, m)}, {_fmt(s.ci_high, m)}]")
        if show_iqm:
            row += [_fmt(g.stats[m].iqm, m) for m in metrics]
        rows.append(row)
    return markdown_table(header, rows)


def coverage_over_time(groups: Sequence[Group]) -> dict[str, dict[str, Any]]:
    """Per group: the first step with CR = 1 of each run (None: never), its median (never = infinite), and how far
    each run's final CR is below the best it reached (learning that collapses shows here)."""
    out = {}
    for g in groups:
        firsts = [next((r["step"] for r in run.rows if r.get("cr", 0.0) >= 1.0 - 1e-9), None) for run in g.runs]
        ranked = sorted(math.inf if f is None else f for f in firsts)
        drops = [max(r.get("cr", math.nan) for r in run.rows) - run.final.get("cr", math.nan) for run in g.runs]
        out[g.label] = {"first_cr1": firsts, "median_first_cr1": float(np.median(ranked)),
                        "reached": sum(f is not None for f in firsts), "cr_drop": aggregate(drops)}
    return out


def render_coverage(groups: Sequence[Group], cov: dict[str, dict[str, Any]]) -> str:
    """Markdown: seeds that reached CR = 1, the median first step, and the drop from the best CR to the final one."""
    from mope.experiments.plots import markdown_table

    rows = []
    for g in groups:
        c = cov[g.label]
        med = c["median_first_cr1"]
        first = "never" if math.isinf(med) else f"{med:.0f}"
        d = c["cr_drop"]
        rows.append([g.label, f"{c['reached']}/{len(g.runs)}", first,
                     ", ".join("never" if f is None else f"{f:.0f}" for f in c["first_cr1"]),
                     "n/a" if d.n == 0 else f"{d.mean:.3f} [{d.ci_low:.3f}, {d.ci_high:.3f}]"])
    return markdown_table(["group", "seeds at CR = 1", "median first step at CR = 1 (never = infinite)",
                           "first step at CR = 1, per seed", "best CR - final CR"], rows)


def plot_learning_curves(groups: Sequence[Group], metrics: Sequence[str], path: str | Path, n_boot: int = 2000,
                         seed: int = 0) -> Path:
    """One panel per metric: each group's mean over seeds against steps, with a bootstrap 95% band."""
    from mope.experiments.plots import plt, save_figure  # pyplot with the Agg backend

    fig, axes = plt.subplots(1, len(metrics), figsize=(4.6 * len(metrics), 3.8), squeeze=False)
    colors = _colors(groups)
    for g, color in zip(groups, colors, strict=True):
        n = min(len(r.rows) for r in g.runs)
        steps = np.array([row["step"] for row in g.runs[0].rows[:n]])
        for ax, m in zip(axes[0], metrics, strict=True):
            vals = np.array([[row.get(m, math.nan) for row in r.rows[:n]] for r in g.runs])
            mean = np.nanmean(vals, axis=0) if np.isfinite(vals).any() else np.full(n, np.nan)
            band = np.array([bootstrap_ci(col[np.isfinite(col)], n_boot, seed) for col in vals.T])
            ax.plot(steps, mean, color=color, lw=2, label=f"{g.label} (n={len(g.runs)})")
            ax.fill_between(steps, band[:, 0], band[:, 1], color=color, alpha=0.2)
    for ax, m in zip(axes[0], metrics, strict=True):
        ax.set_xlabel("environment steps")
        ax.set_title(f"{METRIC_LABELS.get(m, m)} (mean, bootstrap 95% CI)", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    save_figure(fig, path, dpi=110)
    return Path(path)


def _colors(groups: Sequence[Group]) -> list[str]:
    """The paper's colour per algorithm when each group is one algorithm; else matplotlib's cycle."""
    from mope.experiments.plots import COLORS, plt

    algos = [str(g.key.get("algo")) for g in groups]
    if len(set(algos)) == len(groups) and all(a in COLORS for a in algos):
        return [COLORS[a] for a in algos]
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return [cycle[i % len(cycle)] for i in range(len(groups))]


def _read_solutions(folder: Path) -> np.ndarray | None:
    path = folder / "solutions.csv"
    if not path.is_file():
        return None
    rows = _read_rows(path)
    if not rows:
        return None
    cols = sorted((k for k in rows[0] if k.startswith("disc") and k[4:].isdigit()), key=lambda k: int(k[4:]))
    return np.array([[r[c] for c in cols] for r in rows])


def _true_ccs(config: dict[str, Any]) -> np.ndarray | None:
    """The environment's discounted CCS, if mope has a front for it (None when it does not or cannot be made)."""
    try:
        from mope.envs import make_env
        from mope.evaluation.diagnose import reference_front
        from mope.metrics import convex_coverage_set

        env = make_env(config["env_id"])
        front = reference_front(env, float(config.get("gamma", 0.99)))
        env.close()
        return None if front is None else convex_coverage_set(front)
    except Exception:  # noqa: BLE001 - the plot then shows the solutions alone
        return None


def plot_final_fronts(groups: Sequence[Group], path: str | Path) -> Path | None:
    """Distinct final solutions (discounted returns, objectives 0 and 1) per group, pooled over seeds.

    Returns ``None`` (and writes nothing) when no run has a ``solutions.csv``.
    """
    from mope.experiments.plots import plt, save_figure  # pyplot with the Agg backend
    from mope.metrics import unique_solutions

    found = {}
    for g in groups:
        sols = [s for s in (_read_solutions(r.path) for r in g.runs) if s is not None and len(s)]
        if sols:
            found[g.label] = unique_solutions(np.concatenate(sols))
    if not found:
        return None
    envs = list(dict.fromkeys(g.runs[0].config.get("env_id") for g in groups))
    fig, axes = plt.subplots(1, len(envs), figsize=(5.6 * len(envs), 4.2), squeeze=False)
    markers = ["o", "s", "^", "D", "v", "P", "X", "*"]
    color_of = dict(zip((g.label for g in groups), _colors(groups), strict=True))
    for ax, env_id in zip(axes[0], envs, strict=True):
        members = [g for g in groups if g.runs[0].config.get("env_id") == env_id and g.label in found]
        ccs = _true_ccs(members[0].runs[0].config) if members else None
        if ccs is not None and ccs.shape[1] >= 2:
            ax.scatter(ccs[:, 0], ccs[:, 1], s=150, facecolors="none", edgecolors="k", lw=1.3, label="true CCS")
        for i, g in enumerate(members):
            pts = found[g.label]
            if pts.shape[1] < 2:
                continue
            ax.scatter(pts[:, 0], pts[:, 1], s=max(12, 120 // 2**i), marker=markers[i % len(markers)], alpha=0.8,
                       color=color_of[g.label],
                       label=f"{g.label} ({len(pts)} distinct)")
        ax.set_xlabel("objective 0 (discounted return)")
        ax.set_ylabel("objective 1 (discounted return)")
        ax.set_title(f"{env_id}: final solutions, pooled over seeds", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    save_figure(fig, path, dpi=110)
    return Path(path)


def report(runs_dir: str | Path, out_dir: str | Path | None = None, metrics: Sequence[str] = DEFAULT_METRICS,
           n_boot: int = 10_000, seed: int = 0, split_mismatched: bool = False, plots: bool = True) -> ReportResult:
    """Aggregate the runs under ``runs_dir`` across seeds; write report.md, report.json, curves.png, fronts.png.

    Args:
        runs_dir: Folder searched recursively for run folders (a sweep folder, or any folder of runs).
        out_dir: Where the report goes (default ``runs_dir/report``).
        metrics: Columns of ``metrics.csv`` to aggregate; those NaN in every run are left out.
        n_boot: Bootstrap resamples for the confidence intervals.
        seed: Seed of the bootstrap.
        split_mismatched: Group runs that differ beyond the swept fields separately instead of raising.
        plots: Also write the two figures.

    Raises:
        ReportError: for no runs, an unknown metric, or runs that differ beyond the swept fields.
    """
    from mope.experiments.runs import METRIC_COLUMNS

    for m in metrics:
        if m not in METRIC_COLUMNS or m in ("step", "wall_s"):
            from mope.errors import suggest

            raise ReportError(f"unknown metric '{m}'{suggest(m, METRIC_COLUMNS)}; choose from "
                              f"{', '.join(METRIC_COLUMNS[2:])}")
    if n_boot < 1:
        raise ReportError(f"n_boot={n_boot} is out of range: must be >= 1")
    root = Path(runs_dir)
    runs, notes = find_runs(root)
    out = check_report_folder(Path(out_dir) if out_dir is not None else root / "report",
                              "--out" if out_dir is not None else "the report folder")
    arm_fields = _label_arms(runs, root)
    groups, group_notes = group_runs(runs, _swept_fields(root), split_mismatched, arm_fields)
    notes += group_notes
    for g in groups:
        for m in metrics:
            g.stats[m] = aggregate([r.final.get(m, math.nan) for r in g.runs], n_boot, seed)
    shown = [m for m in metrics if any(g.stats[m].n for g in groups)]
    dropped = [m for m in metrics if m not in shown]
    if dropped:
        notes.append(f"left out {', '.join(dropped)}: NaN or missing in every run "
                     "(no known Pareto front, or runs older than the metric)")
    if not shown:
        raise ReportError(f"every metric of {', '.join(metrics)} is NaN in every run")
    steps = {int(r.final.get("step", 0)) for r in runs}
    if len(steps) > 1:
        notes.append(f"runs end at different steps ({', '.join(map(str, sorted(steps)))})")

    try:
        return _write_report(root, out, runs, groups, shown, notes, n_boot, seed, plots)
    except OSError as exc:
        what = "the disk is full" if is_disk_full(exc) else exc.strerror or str(exc)
        raise ReportError(f"cannot write the report into '{out}': {what}") from None


def check_report_folder(out: Path, what: str) -> Path:
    """Make sure the report can be written into ``out`` before anything is computed: not a file, a folder that
    exists or can be made, writable (probed with a temporary file, which is removed)."""
    try:
        if out.exists() and not out.is_dir():
            raise ReportError(f"{what} '{out}' is a file; the report is a folder of files: give a folder")
        base = next(p for p in (out, *out.parents) if p.exists())  # made later, when the report is written
        if not base.is_dir():
            raise ReportError(f"cannot write the report into '{out}': '{base}' is a file, not a folder")
        probe = base / f".mope-write-test-{os.getpid()}"
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        raise ReportError(f"cannot write the report into '{out}': {exc.strerror or exc}; pass --out with a "
                          "writable folder") from None
    return out


def _write_report(root: Path, out: Path, runs: Sequence[Run], groups: Sequence[Group], shown: list[str],
                  notes: list[str], n_boot: int, seed: int, plots: bool) -> ReportResult:
    """Write report.md, report.json and (with ``plots``) curves.png and fronts.png."""
    out.mkdir(parents=True, exist_ok=True)
    table = render_table(groups, shown)
    files = {"report.md": out / "report.md", "report.json": out / "report.json"}
    if plots:
        files["curves.png"] = plot_learning_curves(groups, [m for m in shown if m in ("cr", "hv", "eum")] or shown[:3],
                                                   out / "curves.png", seed=seed)
        fronts = plot_final_fronts(groups, out / "fronts.png")
        if fronts is not None:
            files["fronts.png"] = fronts
    md = [f"# Report: {root}", "", f"{len(runs)} runs in {len(groups)} groups. Each cell: mean ± sample std "
          f"[bootstrap 95% CI of the mean, {n_boot} resamples] of the final evaluation over seeds.", "", table]
    coverage = coverage_over_time(groups) if "cr" in shown else {}
    if coverage:
        md += ["", "Coverage over the run (evaluations every `eval_every` steps):", "",
               render_coverage(groups, coverage)]
    if notes:
        md += ["", *[f"* {n}" for n in notes]]
    files["report.md"].write_text("\n".join(md) + "\n")
    doc = {"runs_dir": str(root), "n_boot": n_boot, "seed": seed, "metrics": shown, "notes": notes,
           "groups": [{"label": g.label, "key": g.key, "runs": [str(r.path.relative_to(root)) for r in g.runs],
                       "stats": {m: {k: _nan_none(v) for k, v in vars(g.stats[m]).items()} for m in shown},
                       **({"coverage": {"first_cr1": coverage[g.label]["first_cr1"],
                                        "median_first_cr1": _nan_none(coverage[g.label]["median_first_cr1"]),
                                        "cr_drop": {k: _nan_none(v) for k, v in
                                                    vars(coverage[g.label]["cr_drop"]).items()}}}
                          if coverage else {})}
                      for g in groups]}
    files["report.json"].write_text(json.dumps(doc, indent=2) + "\n")
    return ReportResult(out, groups, shown, table, notes, files)


def _nan_none(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, list):
        return [_nan_none(x) for x in v]
    return v


def report_command(runs_dir: str | Path, out: str | Path | None = None, split_mismatched: bool = False) -> ReportResult:
    """What ``mope report RUNS_DIR`` does: write the report, print the table, notes and file paths.

    Raises:
        MopeError: for bad input (the CLI prints it as ``error: ...``).
    """
    res = report(runs_dir, out, split_mismatched=split_mismatched)
    print(res.table)
    for n in res.notes:
        print(f"note: {n}")
    print("wrote " + ", ".join(str(p) for p in res.files.values()))
    return res
