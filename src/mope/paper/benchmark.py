"""``mope benchmark``: mope's variants beside morl-baselines' Envelope on several MO-Gymnasium environments.

One command trains and evaluates a grid of (environment, method, seed) in one run, through the job runner
(:mod:`mope.experiments.jobs`: local processes or Ray, every job in a fresh process so its peak memory is its
own; a re-run keeps the finished jobs and resumes the interrupted ones), then writes one table and one figure
per environment.

Methods: ``mope`` and ``eql`` (the defaults), ``mope-paper`` and ``eql-paper`` (the paper preset),
``mope-eps-greedy`` (the defaults with one-step epsilon-greedy, :data:`mope.config.PLAIN_EPSILON`; named
``mope-bound`` before 2026-12-07), ``mope-eps-greedy-unbounded`` and ``eql-eps-greedy-unbounded`` (also without the
seen-return bound, :data:`mope.config.UNBOUNDED`: the defaults before 2026-12-07),
``mope-eps10k``, ``eql-eps10k`` and ``mope-bound-eps10k`` (those with epsilon over 10k steps and a 20k buffer
whatever the budget, :data:`mope.config.SHORT_EXPLORATION`: the defaults before both followed the run's length),
``mope-const``, ``eql-const`` and ``mope-const-bound`` (also before the late target anneal,
:data:`mope.config.CONSTANT_TARGET`; their runs were committed before the switch), and
``envelope`` (morl-baselines' Envelope at its example's settings, :data:`mope.paper.envelope.ENVELOPE_EXAMPLE`;
needs the optional ``bench`` extra) and ``envelope-eps-half`` (the same with epsilon over half the run, as mope's
defaults: the exploration schedule alike on both sides). Environments and their evaluation settings and budgets:
:data:`BENCH_ENVS`.

Per environment and method: CR where the front is known, EUM and its gap to the optimum, HV, the optimal share,
time-outs, the steps and training seconds until CR = 1 (or, without a known front, until 95 % of the best final
EUM any method reached), training seconds per 1k steps and peak memory: means with bootstrap 95 % CIs over seeds,
and the ratio of each mean to Envelope's from the same run.

**In pieces.** The report covers every finished run in the folder, not only this call's: a session can run one
environment (or some seeds) into a committed folder such as ``docs/results/benchmark``, and a later session, on
another machine, adds the next piece there; ``--report-only`` rebuilds the table and figures from what is there.
Each call appends its machine, date, command and wall time to ``pieces.jsonl``, and the report lists them. Only
the compact files of a run are meant to be committed (:data:`COMPACT_FILES`; the folder's ``.gitignore`` is
written to keep the rest out).
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mope.config import CONSTANT_TARGET, PLAIN_EPSILON, SHORT_EXPLORATION, UNBOUNDED, Config, half_run_epsilon_decay
from mope.errors import ConfigError, MopeError, suggest
from mope.experiments.jobs import Job, run_jobs
from mope.experiments.locks import FolderLock


@dataclass(frozen=True)
class EnvBench:
    """How one environment is benchmarked.

    Attributes:
        steps: Full budget (environment steps per run); ``source`` says where it comes from.
        quick_steps: Budget of ``--quick``.
        eval_every: Steps between evaluations (full mode; quick mode evaluates 3 times).
        eval_prefs: Uniform preferences per evaluation.
        max_episode_steps: Episode cap of training and evaluation (None: the registered limit).
        source: Where the budget comes from.
        stochastic: The dynamics are random. The evaluation plays one episode per preference, so its EUM is an
            unbiased estimate of the expected utility, but CR, the optimal share and HV compare single outcomes
            with a front of expected returns: the report leaves them out.
    """

    steps: int
    quick_steps: int
    eval_every: int
    eval_prefs: int
    max_episode_steps: int | None
    source: str
    stochastic: bool = False


#: ``--quick`` evaluates at most this many preferences, episodes of at most this many steps, twice per run.
QUICK_PREFS, QUICK_EPISODE_CAP = 100, 200
#: The environments of the benchmark, each with its evaluation settings and budget.
BENCH_ENVS: dict[str, EnvBench] = {
    "deep-sea-treasure-v0": EnvBench(20_000, 2_000, 1_000, 2_000, None,
                                     "the MoPE paper (Fig. 2) and Yang et al.: 20k steps, 2,000 preferences"),
    "resource-gathering-v0": EnvBench(50_000, 2_000, 2_500, 500, None,
                                      "no published EQL budget: 2.5x Deep-Sea-Treasure's (a 5x5 grid, 3 objectives, "
                                      "the front's 3 points need the enemy-free detours)", stochastic=True),
    "minecart-deterministic-v0": EnvBench(100_000, 2_000, 5_000, 100, 1_000,
                                          "a tenth of morl-baselines' Envelope example (examples/envelope_minecart.py"
                                          " trains 1M steps, epsilon over 50k, gamma 0.98), for 2 cores: 100k steps, "
                                          "epsilon over 10k and gamma 0.99 for every method; 100 preferences (each "
                                          "episode can last 1,000 steps)"),
    "four-room-v0": EnvBench(50_000, 2_000, 2_500, 200, None,
                             "no published front or budget: 50k steps (a 13x13 grid, 3 objectives); EUM against "
                             "the exact optimum (mope.evaluation.four_room, from the environment's dynamics)"),
}
#: Methods: name -> config settings (``envelope`` is morl-baselines' Envelope). The ``*-eps-greedy*`` methods are the
#: defaults before ez-greedy exploration and, ``*-unbounded``, the seen-return bound (2026-12-07). Older still, the
#: ``*-eps10k`` methods are the defaults before epsilon's decay and the replay buffer followed the run's length
#: (2026-12-06, later): epsilon over 10k steps and a 20k buffer whatever the budget. The ``*-const`` methods are the
#: defaults before the late target anneal (issue 33): the Polyak weight constant for the whole run, with the fixed 10k
#: and 20k of that time and no reward normalisation (``reward_norm`` came later; it scales Deep-Sea-Treasure's rewards
#: only, the others stay below 25). Every one of them, and the ``*-lb-abs`` methods (the defaults before L^B became
#: squared, 2026-12-07, later), has the absolute L^B of eq. 4 as written (``lb_loss: abs``): the committed runs
#: of those methods were trained with it, and every one but ``mope-paper`` with the weight 1 of L^B (``lb_weight``;
#: ``mope-lb-w1`` is the squared L^B of weight 1, the defaults between the squared L^B and its weight 4).
BEFORE_EZ_BOUND: dict[str, Any] = {**PLAIN_EPSILON, **UNBOUNDED}
BEFORE_ANNEAL: dict[str, Any] = {**CONSTANT_TARGET, **SHORT_EXPLORATION, "reward_norm": None, **BEFORE_EZ_BOUND}
LB_W1: dict[str, Any] = {"lb_weight": 1.0}
LB_ABS: dict[str, Any] = {"lb_loss": "abs"}
_METHODS: dict[str, dict[str, Any]] = {"mope-lb-abs": {"algo": "mope"}, "eql-lb-abs": {"algo": "eql"},
                                      "mope-paper": {"algo": "mope", "preset": "paper"},
                                      "eql-paper": {"algo": "eql", "preset": "paper"},
                                      "mope-eps-greedy": {"algo": "mope", **PLAIN_EPSILON},
                                      "mope-eps-greedy-unbounded": {"algo": "mope", **BEFORE_EZ_BOUND},
                                      "eql-eps-greedy-unbounded": {"algo": "eql", **BEFORE_EZ_BOUND},
                                      "mope-eps10k": {"algo": "mope", **SHORT_EXPLORATION, **BEFORE_EZ_BOUND},
                                      "eql-eps10k": {"algo": "eql", **SHORT_EXPLORATION, **BEFORE_EZ_BOUND},
                                      "mope-bound-eps10k": {"algo": "mope", "seen_bound_margin": 0.1,
                                                            **SHORT_EXPLORATION, **PLAIN_EPSILON},
                                      "mope-const": {"algo": "mope", **BEFORE_ANNEAL},
                                      "eql-const": {"algo": "eql", **BEFORE_ANNEAL},
                                      "mope-const-bound": {"algo": "mope", **BEFORE_ANNEAL, "seen_bound_margin": 0.1}}
METHODS: dict[str, dict[str, Any]] = {"mope": {"algo": "mope"}, "eql": {"algo": "eql"},
                                      "mope-lb-w1": {"algo": "mope", **LB_W1},
                                      **{m: {**LB_W1, **LB_ABS, **v} for m, v in _METHODS.items()},
                                      "envelope": {}, "envelope-eps-half": {}}
#: morl-baselines' Envelope methods: name -> the settings that differ from its example's, given the run's budget.
ENVELOPE_METHODS: dict[str, Callable[[int], dict[str, Any]]] = {
    "envelope": lambda total: {},
    "envelope-eps-half": lambda total: {"epsilon_decay_steps": half_run_epsilon_decay(total)},  # mope's rule
}
DEFAULT_METHODS = ("mope", "eql", "mope-paper", "envelope")
#: Renamed methods: old name -> (today's name, when and why).
RENAMED_METHODS: dict[str, tuple[str, str]] = {
    **{old: (new, "(the late target anneal with epsilon over 10k steps and a 20k buffer, as on 2026-12-06); the "
                  "'*-const' methods keep the constant target") for old, new in (
        ("mope-late", "mope-eps10k"), ("eql-late", "eql-eps10k"), ("mope-late-bound", "mope-bound-eps10k"))},
    "mope-bound": ("mope-eps-greedy", "when the seen-return bound and ez-greedy became the defaults (2026-12-07): "
                                      "the bound with one-step epsilon-greedy")}


def check_choices(envs: list[str], methods: list[str], seeds: int | str | Sequence[int], steps: int | None
                  ) -> list[int]:
    """One-line errors for an unknown environment or method, a continuous-action environment, bad seeds or a
    budget <= 0; returns the seeds (:func:`mope.experiments.sweep.seed_list`)."""
    from mope.envs import make_env
    from mope.experiments.sweep import seed_list

    for env_id in envs:
        if env_id not in BENCH_ENVS:
            make_env(env_id)  # an unknown id or a continuous-action env gets make_env's own message
            raise ConfigError(f"environment '{env_id}' has no benchmark settings; choose from {', '.join(BENCH_ENVS)}"
                              " (or add it to mope.paper.benchmark.BENCH_ENVS)")
    for m in methods:
        if m in RENAMED_METHODS:
            raise ConfigError(f"method '{m}' was renamed '{RENAMED_METHODS[m][0]}' {RENAMED_METHODS[m][1]}")
        if m not in METHODS:
            raise ConfigError(f"unknown method '{m}'{suggest(m, METHODS)}; choose from {', '.join(METHODS)}")
    seed_values = seed_list(seeds)
    if steps is not None and steps < 1:
        raise ConfigError(f"--steps {steps} is out of range: must be >= 1 (the budget)")
    if set(methods) & set(ENVELOPE_METHODS):
        from mope.paper.envelope import require_morl_baselines

        require_morl_baselines()
    return seed_values


def plan_line(envs: list[str], methods: list[str], seeds: Sequence[int], out: Path) -> str:
    """What a benchmark call is about to run, printed before it starts: ``--seeds 4`` means seeds 0-3, not seed 4."""
    ordered = sorted(seeds)
    contiguous = len(ordered) > 2 and ordered == list(range(ordered[0], ordered[-1] + 1))
    seed_text = f"{ordered[0]}-{ordered[-1]}" if contiguous else ", ".join(map(str, ordered))
    n = len(envs) * len(methods) * len(seeds)
    return (f"benchmark: {n} run{'s' * (n != 1)} into {out} (finished ones are kept): {', '.join(envs)}; "
            f"{', '.join(methods)}; seed{'s' * (len(ordered) != 1)} {seed_text}")


def benchmark_jobs(envs: list[str], methods: list[str], seeds: Sequence[int], quick: bool, steps: int | None
                   ) -> list[Job]:
    """One job per (seed, environment, method), seed-major (a stopped benchmark has whole seeds to report)."""
    from mope.paper.envelope import ENVELOPE_EXAMPLE

    jobs = []
    for seed in seeds:
        for env_id in envs:
            b = BENCH_ENVS[env_id]
            total = steps or (b.quick_steps if quick else b.steps)
            every = max(1, total // 2) if quick else min(b.eval_every, total)
            prefs = min(b.eval_prefs, QUICK_PREFS) if quick else b.eval_prefs
            cap = min(b.max_episode_steps or QUICK_EPISODE_CAP, QUICK_EPISODE_CAP) if quick else b.max_episode_steps
            name = f"{env_id}-{{m}}-s{seed}".replace("/", "_")
            for m in methods:
                if m in ENVELOPE_METHODS:
                    jobs.append(Job(name.format(m=m), "envelope", {
                        "env_id": env_id, "seed": seed, "total_steps": total, "eval_every": every,
                        "eval_prefs": prefs, "max_episode_steps": cap, "gamma": 0.99,
                        "overrides": {**ENVELOPE_EXAMPLE, **ENVELOPE_METHODS[m](total)}}))
                    continue
                cfg = Config.from_dict({**METHODS[m], "env_id": env_id, "seed": seed, "total_steps": total,
                                        "eval_every": every, "eval_prefs": prefs, "max_episode_steps": cap,
                                        "checkpoint_every": every})
                jobs.append(Job(name.format(m=m), "train", cfg.to_dict()))
    return jobs


def _read_run(folder: Path) -> dict[str, Any]:
    from mope.experiments.runs import read_metrics

    rows = read_metrics(folder)
    summary = json.loads((folder / "summary.json").read_text())
    s_per_1k = summary.get("train_s_per_1k_steps", summary.get("s_per_1k_steps", math.nan))  # evaluations excluded
    return {"rows": rows, "final": rows[-1], "s_per_1k": s_per_1k,
            "peak_rss_mb": summary.get("peak_rss_mb", math.nan)}


#: The files of a finished run that a committed piece keeps (the report reads ``metrics.csv`` and ``summary.json``).
COMPACT_FILES = ("config.json", "peer.json", "metrics.csv", "summary.json", "train_stats.csv")
GITIGNORE = ("# written by mope benchmark: a committed piece keeps each run's compact files only\n"
             ".mope*\n*/*\n" + "".join(f"!*/{name}\n" for name in COMPACT_FILES))


def _method(job: Job) -> str:
    """The method of a benchmark job, from its name ``ENV-METHOD-sSEED``."""
    return job.name[len(job.payload["env_id"].replace("/", "_")) + 1:].rpartition("-s")[0]


def _run_identity(folder: Path) -> tuple[str, str, int, int] | None:
    """``(env_id, method, seed, total_steps)`` of a finished benchmark run folder, or None for any other folder."""
    if not (folder / "summary.json").is_file():
        return None
    meta = folder / "peer.json" if (folder / "peer.json").is_file() else folder / "config.json"
    try:
        payload = json.loads(meta.read_text())
    except (OSError, ValueError):
        return None
    env_id = payload.get("env_id")
    if env_id not in BENCH_ENVS:
        return None
    method, seed = _method(Job(folder.name, "", {"env_id": env_id})), folder.name.rpartition("-s")[2]
    if not folder.name.startswith(env_id.replace("/", "_") + "-") or method not in METHODS or not seed.isdigit():
        return None
    return env_id, method, int(seed), int(payload["total_steps"])


def finished_runs(out: Path) -> list[Job]:
    """Every finished benchmark run in ``out`` (this call's and earlier pieces'), as jobs, sorted by name.

    Raises:
        MopeError: when one environment's runs have different budgets (they cannot share a table).
    """
    jobs, budgets = [], {}
    for folder in sorted(p for p in Path(out).iterdir() if p.is_dir()) if Path(out).is_dir() else []:
        ident = _run_identity(folder)
        if ident is None:
            continue
        env_id, method, seed, steps = ident
        budgets.setdefault(env_id, {}).setdefault(steps, folder.name)
        jobs.append(Job(folder.name, "envelope" if method in ENVELOPE_METHODS else "train",
                        {"env_id": env_id, "seed": seed, "total_steps": steps}))
    for env_id, by_steps in budgets.items():
        if len(by_steps) > 1:
            examples = ", ".join(f"{name} ({steps:,} steps)" for steps, name in sorted(by_steps.items()))
            raise MopeError(f"{out} holds {env_id} runs with different budgets ({examples}); one table needs one "
                            "budget: use another --out for the other budget")
    return jobs


def _check_budgets(out: Path, jobs: list[Job]) -> None:
    """Raise a :class:`MopeError` when a planned run's budget differs from its environment's finished runs in
    ``out``."""
    have = {j.payload["env_id"]: (j.payload["total_steps"], j.name) for j in finished_runs(out)}
    for job in jobs:
        env_id, steps = job.payload["env_id"], job.payload["total_steps"]
        if env_id in have and have[env_id][0] != steps:
            raise MopeError(f"{out} holds {env_id} runs of {have[env_id][0]:,} steps ({have[env_id][1]}); this call "
                            f"would add {steps:,}-step runs, and one table needs one budget: use another --out")


def _first(rows: list[dict[str, float]], ok: Any) -> tuple[float, float]:
    """Step and training seconds (evaluations excluded) of the first evaluation where ``ok(row)``; NaN otherwise."""
    for r in rows:
        if ok(r):
            return float(r["step"]), float(r.get("train_s", r["wall_s"]))
    return math.nan, math.nan


#: Evaluations the "EUM, last evaluations" column averages per run: one final evaluation of a noisy run says less
#: than its last stretch (Envelope's seed 0 on four-room: EUM 0.84 at 47.5k steps, 0.44 at 50k).
LAST_EVALS = 5


def eum_of_last_evaluations(rows: list[dict[str, float]], k: int = LAST_EVALS) -> float:
    """Mean EUM of a run's last ``k`` evaluations (all of them where it has fewer)."""
    return float(np.mean([r["eum"] for r in rows[-k:]])) if rows else math.nan


def reference_optimal_eum(env_id: str, gamma: float) -> float:
    """The optimal EUM of the evaluator's equally spaced preferences against mope's reference front
    (:func:`mope.evaluation.diagnose.reference_front`: the published one, or the exact one where the published
    one is wrong); NaN without a front."""
    from mope.envs import make_env
    from mope.evaluation.diagnose import reference_front
    from mope.evaluation.evaluator import N_EUM_PREFS
    from mope.metrics import optimal_utility
    from mope.preferences import equally_spaced

    env = make_env(env_id)
    try:
        front = reference_front(env, gamma)
        if front is None:
            return math.nan
        return float(np.mean(optimal_utility(equally_spaced(front.shape[1], N_EUM_PREFS), front)))
    finally:
        env.close()


def summarise(out: Path, jobs: list[Job]) -> dict[str, dict[str, dict[str, Any]]]:
    """Per environment, per method: the metrics' values over seeds, aggregated (mean, bootstrap CI)."""
    from mope.experiments.stats import aggregate

    runs: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for job in jobs:
        env_id = job.payload["env_id"]
        method = _method(job)
        runs.setdefault(env_id, {}).setdefault(method, []).append(_read_run(out / job.name))
    table: dict[str, dict[str, dict[str, Any]]] = {}
    for env_id, by_method in runs.items():
        stochastic = BENCH_ENVS[env_id].stochastic
        known = any(np.isfinite(r["final"].get("cr", math.nan)) for rs in by_method.values() for r in rs)
        best_eum = max(r["final"]["eum"] for rs in by_method.values() for r in rs)
        optimal = [r["final"].get("eum_optimal", math.nan) for rs in by_method.values() for r in rs]
        recorded = next((float(o) for o in optimal if np.isfinite(o)), math.nan)  # the first run that recorded one
        gamma = float(next(j.payload.get("gamma", 0.99) for j in jobs if j.payload["env_id"] == env_id))
        optimal_eum = reference_optimal_eum(env_id, gamma)  # today's reference, also for runs that recorded none
        for rs in by_method.values():  # the gap to today's reference front, whatever front a run recorded
            for r in rs:
                r["final"]["eum_gap"] = optimal_eum - r["final"]["eum"]
        # the target: 95 % of the way from 0 to the optimal EUM where the front is known, else to the best final
        # EUM any method reached (EUM may be negative: 5 % of its size below it)
        ref = optimal_eum if np.isfinite(optimal_eum) else best_eum
        target = ref - 0.05 * abs(ref)
        table[env_id] = {}
        for method, rs in by_method.items():
            reach = [_first(r["rows"], lambda row, t=target: row["eum"] >= t) for r in rs]
            cover = ([_first(r["rows"], lambda row: row["cr"] >= 1.0 - 1e-9)[0] for r in rs]
                     if known and not stochastic else [math.nan] * len(rs))
            values = {k: [r["final"].get(k, math.nan) for r in rs]
                      for k in ("cr", "eum", "eum_gap", "hv", "optimal_share", "timeout_share", "path_error")}
            values.update(eum_last=[eum_of_last_evaluations(r["rows"]) for r in rs],
                          steps_to_target=[s for s, _ in reach], seconds_to_target=[w for _, w in reach],
                          steps_to_cr1=cover,
                          s_per_1k=[r["s_per_1k"] for r in rs], peak_rss_mb=[r["peak_rss_mb"] for r in rs])
            table[env_id][method] = {"seeds": len(rs), "values": values,
                                     "stats": {k: vars(aggregate(v)) for k, v in values.items()},
                                     "reached": int(np.sum(np.isfinite(values["steps_to_target"])))}
        budget = int(next(j.payload["total_steps"] for j in jobs if j.payload["env_id"] == env_id))
        table[env_id]["_meta"] = {"known_front": known, "best_eum": best_eum, "steps": budget,
                                  "stochastic": stochastic, "optimal_eum": optimal_eum, "target_eum": target,
                                  "recorded_optimal_eum": recorded}
    return table


#: Table columns: (key, label, format). Seconds are training only (evaluations excluded), for every method.
COLUMNS = (("cr", "CR", ".3f"), ("eum_gap", "EUM gap", ".2f"), ("eum", "EUM", ".2f"),
           ("eum_last", f"EUM, last {LAST_EVALS} evaluations", ".2f"), ("hv", "HV", ".1f"),
           ("optimal_share", "optimal share", ".3f"), ("timeout_share", "time-outs", ".3f"),
           ("steps_to_cr1", "steps to CR = 1", ".0f"), ("steps_to_target", "steps to 95 % EUM", ".0f"),
           ("seconds_to_target", "train s to 95 % EUM", ".0f"), ("s_per_1k", "train s / 1k steps", ".1f"),
           ("peak_rss_mb", "peak MiB", ".0f"))
#: Columns that compare single episodes with a front of expected returns: left out on stochastic environments.
SINGLE_OUTCOME_COLUMNS = ("cr", "optimal_share", "hv", "steps_to_cr1")


def _cell(stats: dict[str, Any], fmt: str) -> str:
    if not stats["n"]:
        return "n/a"
    return f"{stats['mean']:{fmt}} [{stats['ci_low']:{fmt}}, {stats['ci_high']:{fmt}}]"


#: The README's benchmark table sits between these two lines; ``readme_table.md`` is what goes there.
README_MARKERS = ("<!-- benchmark table: generated by mope benchmark (readme_table.md) -->",
                  "<!-- end of the benchmark table -->")


#: The README table's methods, in its order: today's defaults, the two defaults before them, and the peer. The
#: older methods are in ``benchmark.md`` only.
README_METHODS = ("mope", "eql", "mope-lb-w1", "mope-lb-abs", "eql-lb-abs", "envelope")


def readme_table(summary: dict[str, dict[str, dict[str, Any]]]) -> str:
    """The compact table of the README: per environment and method of :data:`README_METHODS`, seeds, CR (where the
    front is known), EUM and its gap to the optimum, HV, and the seeds that reached the target (mean [95 % CI] over
    seeds)."""
    from mope.experiments.plots import markdown_table

    rows, unrecorded = [], False
    for env_id, by_method in summary.items():
        known = by_method["_meta"]["known_front"]
        optimum = math.isfinite(by_method["_meta"].get("optimal_eum", math.nan))
        single = not by_method["_meta"].get("stochastic", False)  # single outcomes compare with the front
        steps = by_method["_meta"]["steps"]
        for k, method in enumerate(m for m in README_METHODS if m in by_method):
            st = by_method[method]["stats"]
            missing_cr = known and single and not st["cr"]["n"]  # the runs predate the front: no CR recorded
            unrecorded |= missing_cr
            cr = "n/a *" if missing_cr else _cell(st["cr"], ".3f") if known and single else "-"
            rows.append([env_id if k == 0 else "", f"{steps:,}" if k == 0 else "", method,
                         str(by_method[method]["seeds"]), cr,
                         _cell(st["eum"], ".3f"), _cell(st["eum_last"], ".3f") if "eum_last" in st else "n/a",
                         _cell(st["eum_gap"], ".3f") if known or optimum else "-",
                         _cell(st["hv"], ".1f") if single else "-",
                         f"{by_method[method]['reached']}/{by_method[method]['seeds']}"])
    table = markdown_table(["environment", "steps", "method", "seeds", "CR", "EUM",
                           f"EUM, mean of the last {LAST_EVALS} evaluations", "EUM gap to optimum", "HV",
                           "seeds that reached 95 % of the optimal EUM"], rows)
    if unrecorded:
        table += ("\n\n\\* These runs ran before mope knew the environment's exact front, and their compact files keep "
                  "no solutions, so their CR cannot be computed now; the EUM gap is of the exact optimum.")
    return table + "\n"


def _target_note(meta: dict[str, Any]) -> list[str]:
    """The sentences above an environment's table: its target, which optimum it is of, and what stochastic
    dynamics leave out."""
    target = meta.get("target_eum", math.nan)
    note = [f"Target EUM: {target:.3f}" + (f" (95 % of the optimal {meta['optimal_eum']:.3f})"
                                            if math.isfinite(meta.get("optimal_eum", math.nan)) else
                                            " (95 % of the best final EUM)") + "."] if math.isfinite(target) else []
    recorded = meta.get("recorded_optimal_eum", math.nan)
    if not math.isfinite(recorded) and math.isfinite(meta.get("optimal_eum", math.nan)):
        note.append("The runs' metrics.csv recorded no optimum (they ran before mope knew this environment's exact "
                    "front, mope.evaluation.diagnose.reference_front); the optimum and the EUM gap here are of it.")
    elif math.isfinite(recorded) and abs(recorded - meta["optimal_eum"]) > 1e-6:
        note.append(f"The runs' metrics.csv recorded the optimum {recorded:.3f}, of the environment's published "
                    "front; the optimum and the EUM gap here are of the exact front "
                    "(mope.evaluation.diagnose.WRONG_PUBLISHED_FRONTS says why).")
    if meta.get("stochastic", False):
        note.append("Stochastic dynamics: each preference is evaluated with one episode, so EUM (an unbiased "
                    "estimate of the expected utility) is reported, and CR, the optimal share and HV, which "
                    "would compare single outcomes with a front of expected returns, are not.")
    return note


def render(summary: dict[str, dict[str, dict[str, Any]]], quick: bool, info: dict[str, Any]) -> str:
    """The markdown report: one table per environment, ratios to Envelope where it ran."""
    from mope.experiments.plots import markdown_table

    pieces = info.get("pieces") or [info]
    lines = [f"# mope benchmark{' (--quick)' if quick else ''}", "",
             "Generated by `mope benchmark` from every finished run in its folder. The pieces that trained them "
             "(machine, date, wall time, command):", "",
             *(f"* {p['machine']}; {p['date']}; {p['wall_s']:.0f} s"
               + (f"; {p['code']}" if p.get("code") else "") + f": `{p['command']}`" for p in pieces), "",
             "Each cell: mean [bootstrap 95% CI] over seeds of the final evaluation (the column 'EUM, last "
             f"{LAST_EVALS} evaluations': of each run's mean over its last {LAST_EVALS}). Target: 95 % of the optimal "
             "EUM where the front is known, else of the best final EUM of any method (5 % of its size below it); "
             "steps and training seconds to it, and to CR = 1, are the means over the seeds that reached them "
             "(the count of seeds that reached the target is the last column)."]
    for env_id, by_method in summary.items():
        meta = by_method["_meta"]
        b = BENCH_ENVS[env_id]
        stochastic = meta.get("stochastic", False)
        optimum = math.isfinite(meta.get("optimal_eum", math.nan))
        cols = [c for c in COLUMNS if (meta["known_front"] or (optimum and c[0] == "eum_gap")
                                       or c[0] not in ("cr", "optimal_share", "eum_gap", "steps_to_cr1"))
                and not (stochastic and c[0] in SINGLE_OUTCOME_COLUMNS)]
        header = ["method", "seeds", *(c[1] for c in cols), "seeds that reached the target"]
        env_ratio = by_method.get("envelope")
        rows = []
        for method, s in by_method.items():
            if method == "_meta":
                continue
            rows.append([method, str(s["seeds"]), *(_cell(s["stats"][k], f) for k, _, f in cols),
                         f"{s['reached']}/{s['seeds']}"])
        budget = f"{meta['steps']:,} steps per run" + ("" if meta["steps"] == b.steps else
                                                        f" (the full benchmark's: {b.steps:,})")
        note = _target_note(meta)
        lines += ["", f"## {env_id}", "", f"Budget: {budget}; the full budget's source: {b.source}.", "",
                  *([" ".join(note), ""] if note else []), markdown_table(header, rows)]
        if env_ratio is not None:
            ratios = []
            for method, s in by_method.items():
                if method in ("_meta", "envelope"):
                    continue
                cells = []
                for key in ("s_per_1k", "peak_rss_mb", "seconds_to_target"):
                    a, e = s["stats"][key]["mean"], env_ratio["stats"][key]["mean"]
                    cells.append(f"{a / e:.2f}x" if e and math.isfinite(a) and math.isfinite(e) else "n/a")
                ratios.append([method, *cells])
            same = len({p["machine"] for p in pieces}) == 1
            lines += ["", "Ratios to Envelope (" + ("every piece on the same machine" if same else
                                                     "the pieces ran on different machines: seconds do not compare")
                      + "):", "",
                      markdown_table(["method", "train s / 1k steps", "peak memory", "seconds to target"], ratios)]
        lines += ["", f"![{env_id}]({env_id.replace('/', '_')}.png)"]
    return "\n".join(lines) + "\n"


def plot_curves(out: Path, jobs: list[Job], dest: Path) -> list[Path]:
    """One figure per environment: CR (or EUM), EUM and time-outs against steps, mean and 95 % band per method."""
    from mope.experiments.plots import mean_ci, plt, save_figure

    paths = []
    by_env: dict[str, dict[str, list[list[dict[str, float]]]]] = {}
    for job in jobs:
        env_id = job.payload["env_id"]
        method = _method(job)
        by_env.setdefault(env_id, {}).setdefault(method, []).append(_read_run(out / job.name)["rows"])
    for env_id, by_method in by_env.items():
        known = any(np.isfinite(rows[-1].get("cr", math.nan)) for rs in by_method.values() for rows in rs)
        metrics = ["cr", "eum", "timeout_share"] if known else ["eum", "hv", "timeout_share"]
        fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
        for method, rs in by_method.items():
            n = min(len(r) for r in rs)
            steps = np.array([row["step"] for row in rs[0][:n]])
            for ax, m in zip(axes, metrics, strict=True):
                mean, lo, hi = mean_ci(np.array([[row[m] for row in r[:n]] for r in rs]))
                ax.plot(steps, mean, lw=2, label=f"{method} (n={len(rs)})")
                ax.fill_between(steps, lo, hi, alpha=0.2)
        for ax, m in zip(axes, metrics, strict=True):
            ax.set_title(f"{env_id}: {m}", fontsize=9)
            ax.set_xlabel("environment steps")
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=7)
        paths.append(save_figure(fig, dest / f"{env_id.replace('/', '_')}.png", dpi=110))
    return paths


def run_benchmark(out: str | Path, envs: list[str] | None = None, methods: list[str] | None = None,
                  seeds: int | str | Sequence[int] = 5, quick: bool = False, steps: int | None = None,
                  workers: int | None = None,
                  backend: str = "local", address: str | None = None, report_dir: str | Path | None = None,
                  progress: bool = True, command: str = "", report_only: bool = False) -> dict[str, Any]:
    """Train and evaluate the grid, then write ``benchmark.md``, ``benchmark.json`` and one PNG per environment.

    Args:
        out: The folder of the runs (one sub-folder per job); the report goes there too unless ``report_dir``.
        envs: Environments (default: every one of :data:`BENCH_ENVS`).
        methods: Methods (default: mope, eql, mope-paper, and envelope when morl-baselines is installed).
        seeds: Seeds per (environment, method): a count ``N`` (``0..N-1``), a range ``"5-9"`` or a list
            (:func:`mope.experiments.sweep.seed_list`); ``quick`` forces seed 0 alone.
        quick: Small budgets (each environment's ``quick_steps``), one seed, at most 100 preferences and 200-step
            episodes per evaluation, two evaluations per run: a first look, and CI's test.
        steps: Override every environment's budget.
        workers: Jobs at once (default every core).
        backend, address: The job runner's backend (``local`` or ``ray``) and Ray address.
        report_dir: Where the table and figures go (default ``out``).
        progress: Show the live line.
        command: The command line, for the report.
        report_only: Train nothing: rebuild the report from the finished runs already in ``out``.
    """
    envs = list(envs or BENCH_ENVS)
    if methods is None:
        methods = [m for m in DEFAULT_METHODS if m != "envelope"]
        try:
            import morl_baselines  # noqa: F401

            methods.append("envelope")
        except ImportError:
            pass
    out = Path(out)
    dest = Path(report_dir) if report_dir is not None else out
    if report_only:
        if not finished_runs(out):
            raise MopeError(f"--report-only: {out} holds no finished benchmark run")
        jobs: list[Job] = []
    else:
        seeds = check_choices(envs, list(methods), 1 if quick else seeds, steps)
        jobs = benchmark_jobs(envs, list(methods), seeds, quick, steps)
        _check_budgets(out, jobs)  # different budgets in one folder: say so before training, not after
    # --report-only writes the report alone, so it does not wait for a piece that is training into the folder
    with contextlib.nullcontext() if report_only else FolderLock(out, what="benchmark folder"):
        t0 = time.perf_counter()
        if jobs:
            print(plan_line(envs, list(methods), seeds, out), file=sys.stderr, flush=True)
            out.mkdir(parents=True, exist_ok=True)
            if not (out / ".gitignore").exists():
                (out / ".gitignore").write_text(GITIGNORE)
            records = run_jobs(jobs, out, backend, workers, address, progress, desc="benchmark",
                               fresh_processes=True)
            failed = [r for r in records.values() if r["status"] == "failed"]
            if failed:
                raise MopeError(f"{len(failed)} of {len(jobs)} runs failed, the first: {failed[0]['name']} "
                                f"({failed[0]['error']}); see {out / failed[0]['name'] / 'error.txt'}")
        wall = time.perf_counter() - t0
        trained = bool(jobs) and any(r["action"] != "skipped" for r in records.values())
        summary, text, figures = write_report(out, dest, _machine(wall, command), quick, trained)
    return {"summary": summary, "table": text, "out": dest, "wall_s": wall, "figures": figures}


def write_report(out: Path, dest: Path, info: dict[str, Any], quick: bool, new_piece: bool
                 ) -> tuple[dict[str, Any], str, list[Path]]:
    """Write ``benchmark.md``, ``benchmark.json``, ``readme_table.md`` and the figures into ``dest`` from every
    finished run in ``out``; with ``new_piece``, first append ``info`` (this call's machine, date, wall time and
    command) to ``out/pieces.jsonl``.

    Returns:
        ``(summary, markdown, figure paths)``.
    """
    pieces_file = out / "pieces.jsonl"
    if new_piece:
        with open(pieces_file, "a") as f:
            f.write(json.dumps(info) + "\n")
    info["pieces"] = ([json.loads(line) for line in pieces_file.read_text().splitlines() if line.strip()]
                      if pieces_file.is_file() else [dict(info)])
    all_jobs = finished_runs(out)
    summary = summarise(out, all_jobs)
    dest.mkdir(parents=True, exist_ok=True)
    text = render(summary, quick, info)
    (dest / "benchmark.md").write_text(text)
    (dest / "readme_table.md").write_text(readme_table(summary))
    (dest / "benchmark.json").write_text(json.dumps({"info": info, "summary": summary}, indent=1, default=_json))
    return summary, text, plot_curves(out, all_jobs, dest)


def _machine(wall_s: float, command: str) -> dict[str, Any]:
    import datetime
    import os
    import platform

    from mope.experiments.runs import cpu_description

    return {"machine": f"{cpu_description()}, {os.cpu_count()} CPUs, Python {platform.python_version()}",
            "date": datetime.date.today().isoformat(), "wall_s": wall_s, "command": command, "code": _code_version()}


def _code_version() -> str:
    """``mope X.Y.Z``, plus the commit when the package runs from a git checkout (pieces of one report can come
    from different commits: the learner's stream may differ between them)."""
    import subprocess

    import mope
    from mope.agent.checkpoint import mope_version

    text = f"mope {mope_version()}"
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=Path(mope.__file__).parent,
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return text
    return f"{text} ({out.stdout.strip()})" if out.returncode == 0 and out.stdout.strip() else text


def _json(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return str(x)


__all__ = ["BENCH_ENVS", "METHODS", "EnvBench", "benchmark_jobs", "finished_runs", "readme_table", "run_benchmark",
           "write_report"]
