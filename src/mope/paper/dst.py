"""``mope reproduce dst``: the paper's Deep-Sea-Treasure experiment (Fig. 2, Fig. 3) over several seeds.

Trains the four variants (``eql``, ``ee``, ``pe``, ``mope``) for the same number of steps and seeds, each
into its own run folder ``<algo>-s<seed>`` through the job runner (a finished run is reused and an interrupted
one resumes from its last checkpoint),
then writes into the output folder:

* ``fig2a_cr.png`` -- CR against steps, mean and 95% confidence band per variant;
* ``fig2a_optimal_share.png`` and ``fig2a_timeouts.png`` -- the same for the two metrics that keep CR honest;
* ``fig2b_front.png`` -- the true discounted CCS and the solutions each variant recovered (the first seed);
* ``fig3a_preferences.png`` -- weight on treasure against the solution found, beside the optimal one;
* ``fig3b_discriminator.png`` -- the discriminator's predicted preference over the grid (EE and MoPE);
* ``table.md`` and ``results.json`` -- final CR (mean +- std), steps until CR first reaches 1.0, HV, EUM and
  its gap, optimal share, time-outs, and strategy diversity (distinct optimal routes per treasure, I(S; C)).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from mope.config import Config, check_algo
from mope.errors import ConfigError
from mope.experiments.jobs import Job, run_all_or_raise
from mope.experiments.locks import FolderLock

DST = "deep-sea-treasure-v0"
CURVES = ("cr", "optimal_share", "timeout_share")
FINAL_KEYS = ("cr", "hv", "eum", "eum_optimal", "eum_gap", "optimal_share", "timeout_share", "path_error")




def steps_to_full_coverage(rows: list[dict[str, float]]) -> float:
    """First evaluation step with CR = 1, or NaN if never."""
    for r in rows:
        if r["cr"] >= 1.0 - 1e-9:
            return r["step"]
    return float("nan")


def discriminator_map(agent: Any) -> np.ndarray | None:
    """E[w_treasure | s] under the agent's discriminator at every DST cell (NaN on rock)."""
    import torch

    if agent.discriminator is None:
        return None
    sea = np.asarray(agent.env.unwrapped.sea_map)
    rows, cols = np.indices(sea.shape)
    obs = torch.as_tensor(np.stack([rows.ravel(), cols.ravel()], axis=1), dtype=torch.float32)
    centers = (np.arange(agent.pref_sampler.partition.n_cells) + 0.5) / agent.pref_sampler.partition.n_cells
    with torch.no_grad():
        probs = torch.softmax(agent.discriminator(obs), dim=1).numpy()
    grid = (probs @ centers).reshape(sea.shape)
    grid[sea == -10] = np.nan
    return grid


def analyse_run(run_dir: Path, n_prefs: int) -> dict[str, Any]:
    """Final evaluation of a run with recorded paths: metrics, diversity, and what the figures need."""
    from mope.agent.agent import MoPE
    from mope.evaluation.diversity import distinct_paths, state_preference_mi
    from mope.evaluation.evaluator import Evaluator
    from mope.metrics import convex_coverage_set

    agent = MoPE.load(run_dir / "checkpoints" / "final.pt")
    c = agent.config
    ev = Evaluator.from_config(agent.env, c, n_prefs)
    res, sols = ev.evaluate(agent, record_obs=True)
    ccs = convex_coverage_set(ev.front)
    best = ccs[np.argmax(sols.prefs @ ccs.T, axis=1)]
    cells = agent.pref_sampler.partition.cell_of(sols.prefs)
    div = distinct_paths(sols.observations, sols.lengths, sols.discounted, ccs)
    return {"metrics": res, "paths": div, "mi": state_preference_mi(sols.observations, sols.lengths, cells),
            "prefs": sols.prefs, "found": sols.discounted, "best": best, "ccs": ccs,
            "disc_map": discriminator_map(agent), "sea_map": np.asarray(agent.env.unwrapped.sea_map)}


def dst_jobs(seeds: int | str | Sequence[int], steps: int, eval_every: int, algos: Sequence[str], env_id: str = DST,
             **overrides: Any) -> list[Job]:
    """Validate the arguments and build one training job per (seed, variant), seed-major.

    ``seeds`` is a count ``N`` (seeds ``0..N-1``), a range ``"5-9"`` or a list
    (:func:`mope.experiments.sweep.seed_list`).
    Seed-major: every variant's first seed comes before any second one, so a stopped reproduction can be analysed
    with fewer seeds (re-run with a smaller ``--seeds``; finished runs are reused).
    """
    from mope.experiments.sweep import seed_list

    for a in algos:
        check_algo(a)
    seeds = seed_list(seeds)
    if steps < 1:
        raise ConfigError(f"steps={steps} is out of range: must be >= 1")
    from mope.envs import make_env

    if not hasattr(make_env(env_id).unwrapped, "sea_map"):
        raise ConfigError(f"environment '{env_id}' is not a Deep-Sea-Treasure map; mope reproduce dst runs on "
                          "deep-sea-treasure-v0, its -concave/-mirrored maps or mope/deep-sea-treasure-seabed-v0")
    return [Job(run_name(a, s), "train", Config.for_algo(a, env_id=env_id, seed=s, total_steps=steps,
                                                         eval_every=eval_every, **overrides).to_dict())
            for s in seeds for a in algos]


def _median_never_infinite(first_steps: np.ndarray) -> float | None:
    """Median first step at CR = 1 over seeds, a seed that never got there counting as infinite; None if that
    median is infinite (more than half the seeds never covered)."""
    med = float(np.median(np.where(np.isnan(first_steps), np.inf, first_steps)))
    return med if np.isfinite(med) else None


def run_name(algo: str, seed: int) -> str:
    """Folder of one run of a reproduction: ``<algo>-s<seed>``."""
    return f"{algo}-s{seed}"


def summarise_variant(out: Path, algo: str, seeds: Sequence[int], n_prefs: int
                      ) -> tuple[dict[str, Any], dict[str, Any], dict]:
    """Final evaluation of every seed of one variant: its results entry, its first seed's analysis and its
    curves."""
    from mope.experiments.runs import read_metrics

    metric_rows = [read_metrics(out / run_name(algo, s)) for s in seeds]
    n = min(len(r) for r in metric_rows)
    step_axis = np.array([r["step"] for r in metric_rows[0][:n]])
    curves = {key: (step_axis, np.array([[r[key] for r in rows[:n]] for rows in metric_rows]))
              for key in CURVES}
    runs = [analyse_run(out / run_name(algo, s), n_prefs) for s in seeds]
    fin = {k: np.array([r["metrics"][k] for r in runs]) for k in FINAL_KEYS}
    t_full = np.array([steps_to_full_coverage(rows) for rows in metric_rows])
    result = {
        **{k: {"mean": float(v.mean()), "std": float(v.std()), "values": v.tolist()} for k, v in fin.items()},
        "steps_to_cr1": {"median": _median_never_infinite(t_full),
                         "reached": int(np.sum(~np.isnan(t_full))), "seeds": len(seeds),
                         "values": [None if np.isnan(t) else float(t) for t in t_full]},
        "best_cr": [float(max(r["cr"] for r in rows)) for rows in metric_rows],
        "paths_per_solution": _mean_ci([r["paths"]["paths_per_solution"] for r in runs]),
        "mi_state_pref": _mean_ci([r["mi"] for r in runs]),
        "s_per_1k_steps": float(np.mean([json.loads((out / run_name(algo, s) / "summary.json").read_text())
                                         ["s_per_1k_steps"] for s in seeds])),
    }
    return result, runs[0], curves


def _mean_ci(values: Sequence[float]) -> dict[str, Any]:
    """The diversity measures of Fig. 3 over seeds: :func:`mope.experiments.stats.aggregate` (mean, std,
    bootstrap CI)."""
    from dataclasses import asdict

    from mope.experiments.stats import aggregate

    return asdict(aggregate(values))


def render_dst(out: Path, algos: Sequence[str], results: dict[str, Any], analyses: dict[str, Any],
               curves: dict[str, dict[str, Any]]) -> str:
    """Write Fig. 2, Fig. 3 and table.md; return the table."""
    from mope.experiments.plots import plot_curves, plot_discriminator_maps, plot_fronts, plot_preference_solutions

    plot_curves(curves["cr"], out / "fig2a_cr.png")
    plot_curves(curves["optimal_share"], out / "fig2a_optimal_share.png", ylabel="optimal share",
                title="Share of preferences whose return is their own optimum (mean, 95% CI)")
    plot_curves(curves["timeout_share"], out / "fig2a_timeouts.png", ylabel="time-out share",
                title="Share of preferences that loop until the time limit (mean, 95% CI)")
    first = analyses[algos[0]]
    plot_fronts(first["ccs"], {a: np.unique(np.round(analyses[a]["found"], 3), axis=0) for a in algos},
                out / "fig2b_front.png")
    shown = [a for a in algos if a in ("eql", "mope")] or list(algos)  # the paper's Fig. 3a compares these two
    plot_preference_solutions({a: (analyses[a]["prefs"], analyses[a]["found"], analyses[a]["best"]) for a in shown},
                              first["ccs"], out / "fig3a_preferences.png")
    maps = {a: analyses[a]["disc_map"] for a in algos if analyses[a]["disc_map"] is not None}
    if maps:
        plot_discriminator_maps(maps, first["sea_map"], out / "fig3b_discriminator.png")
    table = dst_table(algos, results)
    (out / "table.md").write_text(table + "\n")
    return table


def dst_table(algos: Sequence[str], results: dict[str, Any]) -> str:
    """The reproduction's table: final metrics (mean ± std over seeds), coverage speed and diversity."""
    from mope.experiments.plots import markdown_table

    def pm(d: dict[str, float], fmt: str = ".3f") -> str:
        return f"{d['mean']:{fmt}} ± {d['std']:{fmt}}"

    def ci(d: dict[str, Any], fmt: str) -> str:
        return f"{d['mean']:{fmt}} [{d['ci_low']:{fmt}}, {d['ci_high']:{fmt}}]"

    header = ["variant", "final CR", "steps to CR = 1 (median; seeds)", "HV", "EUM (optimum)", "optimal share",
              "time-outs", "path error", "routes per treasure [95 % CI]",
              "I(S; C) nats [95 % CI]", "s / 1k steps"]
    rows = []
    for a in algos:
        r = results[a]
        t = r["steps_to_cr1"]
        rows.append([a, pm(r["cr"]), f"{t['median']:.0f} ({t['reached']}/{t['seeds']})" if t["median"] else
                     f"never ({t['reached']}/{t['seeds']})", pm(r["hv"], ".1f"),
                     f"{pm(r['eum'], '.2f')} ({r['eum_optimal']['mean']:.2f})", pm(r["optimal_share"]),
                     pm(r["timeout_share"]), pm(r["path_error"]), ci(r["paths_per_solution"], ".2f"),
                     ci(r["mi_state_pref"], ".3f"),
                     f"{r['s_per_1k_steps']:.1f}"])
    return markdown_table(header, rows)


def reproduce_dst(out: str | Path, seeds: int | str | Sequence[int] = 3, steps: int = 20_000, eval_every: int = 1000,
                  algos: tuple[str, ...] = ("eql", "ee", "pe", "mope"), workers: int = 2, progress: bool = True,
                  backend: str = "local", address: str | None = None, env_id: str = DST,
                  **overrides: Any) -> dict[str, Any]:
    """Train, evaluate and plot the DST experiment; see the module docstring for the outputs.

    Runs go through :func:`mope.experiments.jobs.run_jobs` (local processes or Ray), so an interrupted reproduction
    resumes:
    finished runs are reused and interrupted ones continue from their last checkpoint.
    """
    from mope.experiments.sweep import seed_list

    seeds = seed_list(seeds)
    jobs = dst_jobs(seeds, steps, eval_every, algos, env_id, **overrides)
    out = Path(out)
    with FolderLock(out, what="reproduction folder"):
        t0 = time.perf_counter()
        records = run_all_or_raise(jobs, out, backend, workers, address, progress)
        train_wall = time.perf_counter() - t0
        n_prefs = Config.from_dict(jobs[0].payload).run.eval_prefs
        results, analyses, curves = {}, {}, {key: {} for key in CURVES}
        for a in algos:
            results[a], analyses[a], variant_curves = summarise_variant(out, a, seeds, n_prefs)
            for key in CURVES:
                curves[key][a] = variant_curves[key]
        table = render_dst(out, algos, results, analyses, curves)
        runs_wall = sum(json.loads((out / j.name / "summary.json").read_text())["wall_s"] for j in jobs)
        (out / "results.json").write_text(json.dumps({"results": results, "seeds": seeds, "steps": steps,
                                                      "env_id": env_id, "train_wall_s": train_wall,
                                                      "runs_wall_s": runs_wall, "overrides": overrides}, indent=2))
    return {"results": results, "table": table, "out": out, "train_wall_s": train_wall, "runs_wall_s": runs_wall,
            "records": records}
