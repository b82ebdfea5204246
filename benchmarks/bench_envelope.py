"""Side-by-side benchmark of ``mope``, ``eql`` (this package) and morl-baselines' ``Envelope`` on Deep-Sea-Treasure.

Run it from a separate virtual environment that has the ``bench`` extra (morl-baselines is never a runtime
dependency of mope)::

    python3 -m venv .venv-bench
    .venv-bench/bin/pip install torch==2.13.0 -e ".[bench]"
    WANDB_MODE=disabled .venv-bench/bin/python benchmarks/bench_envelope.py --seeds 5 --steps 20000 \\
        --out benchmarks/results/envelope

What it measures, all in one invocation on one machine (each trial in its own fresh subprocess, one torch thread,
``--workers`` trials at a time; keep the default 1 for clean timings):

(a) Time to coverage. Train each method for up to ``--steps`` environment steps on ``deep-sea-treasure-v0`` and
    evaluate the coverage ratio (CR) every ``--eval-every`` steps with mope's :class:`~mope.Evaluator` (2,000
    uniform preferences drawn with the trial's seed, plus the 100 equally spaced EUM preferences; gamma 0.99; the
    environment's time limit of 100 steps). The same evaluator and preference set serve all three methods; Envelope
    is evaluated through :class:`EnvelopePolicy`, a batched greedy adapter over its Q-network. The clock runs only
    during training steps: evaluation time is recorded separately. Time to coverage is the training time and the
    step count at the first evaluation with CR = 1.0. A seed that never reaches 1.0 within ``--steps`` is a
    failure; the median over seeds counts failures as infinite ("> steps" when more than half fail).
(b) Cost per step: seconds per 1k training steps, timed over ``--cost-steps`` steps after a warm-up past
    ``learning_starts`` (so each timed step makes one gradient update): mope and eql at the paper's settings
    (B = 32, N_omega = 64, hidden 64-128-128-64), mope and eql at Envelope-equal settings (Envelope's network
    256x4, batch 256, N_omega = num_sample_w = 4), and Envelope itself.
(c) Evaluation: seconds for one 2,000(+100)-preference evaluation, on the agent of the cost trial (median of 3)
    and the median over all evaluations of the time-to-coverage trials. Evaluation time depends on how long the
    greedy episodes run, so the time-out share of the evaluated policy is reported with it.
(d) Memory: peak resident set size (``ru_maxrss``) of one ``--steps``-long run per method (seed ``--memory-seed``):
    its time-to-coverage trial when that one ran all the steps, else a training-only run without early stop;
    plus the peak of every time-to-coverage trial.
(e) The machine's ceiling: single-thread float32 matmul throughput (GFLOP/s) at the networks' shapes and at
    1024^3, against the FLOP rate training reaches (FLOP per step from the layer sizes, see :func:`flop_per_update`).

Envelope runs at the defaults morl-baselines' own launcher (``experiments/benchmark/launch_experiment.py``) uses
for Deep-Sea-Treasure: the constructor's defaults with ``gamma=0.99`` (lr 3e-4, epsilon fixed at 0.01 after 100
random steps, 256x4 network, batch 256, num_sample_w 4, PER, 1e6 buffer, hard target copy every 200 steps, grad
norm 1.0, homotopy lambda 0), the env wrapped in ``MORecordEpisodeStatistics``, ``seed_everything(seed)``, and
``log=False`` (no wandb). ``--envelope-kwargs '{"initial_epsilon": 1.0, ...}'`` overrides constructor arguments.
Its training loop is :meth:`EnvelopeRunner.train`, a step-for-step copy of ``Envelope.train``'s loop without the
logging and evaluation branches, keeping the observation, the episode's weight, ``global_step`` (hence the
epsilon schedule) and the replay buffer across chunks; ``Envelope.train`` itself would reset the environment
and draw a new weight at each call. The only addition is seeding the first reset and the action space, which
morl-baselines leaves unseeded.

Outputs ``<out>.md`` (the table, ratios to Envelope, the machine, the command) and ``<out>.json`` (raw trials);
one log per trial under ``--log-dir``. Duration: Envelope's update is about 6.5 times mope's in FLOP (4.5 vs 0.69
GFLOP per step), about 0.1 s per step on one idle core, so every Envelope seed that does not cover takes over
half an hour for 20k steps.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import datetime
import json
import math
import os
import platform
import resource
import shlex
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

ENV_ID = "deep-sea-treasure-v0"
GAMMA = 0.99
METHODS = ("mope", "eql", "eql-envelope", "envelope")
#: Settings of the (b) cost trials: name -> (method, overrides of mope's Config).
COST_VARIANTS: dict[str, tuple[str, dict[str, Any]]] = {
    "mope-default": ("mope", {}),
    "eql-default": ("eql", {}),
    "mope-paper": ("mope", {"preset": "paper"}),
    "eql-paper": ("eql", {"preset": "paper"}),
    "eql-envelope-preset": ("eql-envelope", {}),
    "envelope": ("envelope", {}),
}


# ------------------------------------------------------------------------------------------------------------
# inside a trial subprocess
# ------------------------------------------------------------------------------------------------------------
def peak_rss_mb() -> float:
    """Peak resident set size of this process in MiB (Linux reports ``ru_maxrss`` in KiB)."""
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / 1024 if sys.platform != "darwin" else kb / 2**20


class MopeRunner:
    """mope's own agent behind the same small interface as :class:`EnvelopeRunner`."""

    def __init__(self, algo: str, seed: int, total_steps: int, overrides: dict[str, Any] | None = None) -> None:
        import mope

        extra = {"preset": "envelope"} if algo == "eql-envelope" else {}
        self.agent = mope.make_agent(algo.split("-")[0], ENV_ID, seed=seed, total_steps=total_steps, torch_threads=1,
                                     **extra, **(overrides or {}))

    @property
    def global_step(self) -> int:
        return int(self.agent.global_step)

    def train(self, steps: int) -> None:
        self.agent.train(steps)  # the episode in progress carries over: train(a); train(b) == train(a + b)

    def policy(self) -> Any:
        return self.agent

    @property
    def learning_starts(self) -> int:
        return int(self.agent.config.learning_starts)

    @property
    def q_net(self) -> Any:
        return self.agent.q_net


def make_runner(method: str, seed: int, total_steps: int, overrides: dict[str, Any] | None = None) -> Any:
    if method == "envelope":
        from mope.paper.envelope import EnvelopeRunner

        return EnvelopeRunner(ENV_ID, seed, GAMMA, overrides)
    return MopeRunner(method, seed, total_steps, overrides)


def make_evaluator(seed: int) -> Any:
    """mope's evaluation protocol with the preference set of ``seed`` (as ``MoPE.train`` builds it)."""
    from mope import Evaluator, make_env

    return Evaluator(make_env(ENV_ID), ENV_ID, gamma=GAMMA, n_prefs=2000, seed=seed)


def linear_layers(net: Any) -> list[tuple[int, int]]:
    """``(in_features, out_features)`` of every ``nn.Linear`` of a module, in order."""
    from torch import nn

    return [(m.in_features, m.out_features) for m in net.modules() if isinstance(m, nn.Linear)]


def flop_per_update(method: str, runner: Any) -> dict[str, float]:
    """Estimated FLOP of one gradient update (the dense layers only; activations, losses and Adam are ignored).

    A forward pass of an MLP costs ``F = 2 * sum_l(in_l * out_l)`` FLOP per row; forward plus backward costs
    ``3 F`` (the backward pass computes the gradients of the inputs and of the weights, each as large as the
    forward product).

    * mope/eql (``MoPE.update``): the online network forward+backward on ``B * N`` rows, the target network
      forward on ``B * K`` rows and, with double Q-learning, the online network again on ``B * K`` rows
      (``K = N`` with the default ``envelope_prefs="relabel"`` and with "own"); with experience exploration, the
      discriminator forward+backward on ``B`` rows. Acting adds one row forward per step (negligible).
    * Envelope (``Envelope.update``): the batch is repeated ``W = num_sample_w`` times, so the online network
      runs forward+backward on ``B * W`` rows, and ``envelope_target`` repeats those rows ``W`` times again:
      the online and the target network each run forward on ``B * W * W`` rows.
    """
    q_layers = linear_layers(runner.q_net)
    f_q = 2.0 * sum(i * o for i, o in q_layers)
    if method == "envelope":
        a = runner.agent
        b, w = a.batch_size, a.num_sample_w
        rows_fb, rows_f = b * w, 2 * b * w * w
        flop = 3 * f_q * rows_fb + f_q * rows_f
        return {"flop_per_step": flop, "rows_forward_backward": rows_fb, "rows_forward_only": rows_f,
                "net_flop_per_row": f_q}
    agent = runner.agent
    c = agent.config
    b, n = c.batch_size, c.n_omega
    k = {"batch": b, "both": n + b}.get(c.envelope_prefs, n)  # "relabel" and "own": the rows' own N preferences
    rows_fb = b * n
    rows_f = b * k * (2 if c.double_q else 1)
    if c.q_head == "convex":  # the network sees states only: one row per transition, whatever N and K are
        rows_fb, rows_f = b, b * (2 if c.double_q else 1)
    flop = 3 * f_q * rows_fb + f_q * rows_f
    if agent.discriminator is not None:
        f_d = 2.0 * sum(i * o for i, o in linear_layers(agent.discriminator))
        flop += 3 * f_d * b
    return {"flop_per_step": flop * c.gradient_steps, "rows_forward_backward": rows_fb, "rows_forward_only": rows_f,
            "net_flop_per_row": f_q}


def trial_ttc(method: str, seed: int, steps: int, eval_every: int, stop_at_coverage: bool,
              overrides: dict[str, Any] | None) -> dict[str, Any]:
    """(a) train in ``eval_every`` chunks, evaluating CR after each; training and evaluation timed apart."""
    runner = make_runner(method, seed, steps, overrides)
    evaluator = make_evaluator(seed)
    train_s = eval_s_total = 0.0
    curve: list[dict[str, float]] = []
    ttc_steps = ttc_s = None
    while runner.global_step < steps:
        chunk = min(eval_every, steps - runner.global_step)
        t0 = time.perf_counter()
        runner.train(chunk)
        train_s += time.perf_counter() - t0
        t0 = time.perf_counter()
        res, sols = evaluator.evaluate(runner.policy())
        ev = time.perf_counter() - t0
        eval_s_total += ev
        curve.append({"step": runner.global_step, "train_s": train_s, "eval_s": ev, "cr": res["cr"],
                      "precision": res["precision"], "recall": res["recall"], "hv": res["hv"],
                      "timeout_share": res["timeout_share"], "optimal_share": res.get("optimal_share", math.nan),
                      "path_error": res.get("path_error", math.nan), "eum_gap": res.get("eum_gap", math.nan),
                      "mean_len": float(np.mean(sols.lengths))})
        print(f"eval step={runner.global_step} cr={res['cr']:.4f} timeout_share={res['timeout_share']:.3f} "
              f"train_s={train_s:.1f} eval_s={ev:.3f}", file=sys.stderr, flush=True)
        if ttc_steps is None and res["cr"] >= 1.0 - 1e-12:
            ttc_steps, ttc_s = runner.global_step, train_s
            if stop_at_coverage:
                break
    return {"kind": "ttc", "method": method, "seed": seed, "steps_cap": steps, "eval_every": eval_every,
            "steps_run": runner.global_step, "reached": ttc_steps is not None, "ttc_steps": ttc_steps,
            "ttc_train_s": ttc_s, "train_s": train_s, "eval_s_total": eval_s_total,
            "s_per_1k": 1000 * train_s / max(1, runner.global_step), "curve": curve, "peak_rss_mb": peak_rss_mb()}


def trial_cost(variant: str, steps: int, warmup: int, overrides: dict[str, Any] | None) -> dict[str, Any]:
    """(b) seconds per 1k steps after a warm-up past learning_starts, and (c) one evaluation of that agent."""
    method, variant_overrides = COST_VARIANTS[variant]
    extra = {**variant_overrides, **(overrides or {})}
    runner = make_runner(method, 0, 20_000, extra)
    runner.train(runner.learning_starts + warmup)
    t0 = time.perf_counter()
    runner.train(steps)
    dt = time.perf_counter() - t0
    evaluator = make_evaluator(0)
    evaluator.evaluate(runner.policy())  # warm-up
    times, res = [], {}
    for _ in range(3):
        t0 = time.perf_counter()
        res, _sols = evaluator.evaluate(runner.policy())
        times.append(time.perf_counter() - t0)
    flops = flop_per_update(method, runner)
    s_per_step = dt / steps
    return {"kind": "cost", "variant": variant, "method": method, "overrides": {k: list(v) if isinstance(v, tuple)
                                                                                else v for k, v in extra.items()},
            "steps": steps, "warmup": runner.learning_starts + warmup, "s_per_1k": 1000 * s_per_step,
            "eval_s": statistics.median(times), "eval_timeout_share": res.get("timeout_share"),
            **flops, "achieved_gflops": flops["flop_per_step"] / s_per_step / 1e9, "peak_rss_mb": peak_rss_mb()}


def trial_memory(method: str, seed: int, steps: int, overrides: dict[str, Any] | None) -> dict[str, Any]:
    """(d) one full-length training run, no evaluation, no early stop: peak RSS and whole-run seconds per 1k."""
    runner = make_runner(method, seed, steps, overrides)
    t0 = time.perf_counter()
    runner.train(steps)
    dt = time.perf_counter() - t0
    return {"kind": "memory", "method": method, "seed": seed, "steps": steps, "train_s": dt,
            "s_per_1k": 1000 * dt / steps, "peak_rss_mb": peak_rss_mb()}


def trial_ceiling(repeats: int = 5) -> dict[str, Any]:
    """(e) single-thread float32 matmul GFLOP/s at the networks' shapes and at 1024^3 (best of ``repeats``)."""
    import torch
    import torch.nn.functional as F  # noqa: N812

    shapes = {"2048x128 @ 128x128 (mope paper hidden layer, B*N rows)": (2048, 128, 128),
              "1024x256 @ 256x256 (Envelope hidden layer, B*W rows)": (1024, 256, 256),
              "4096x256 @ 256x256 (Envelope target pass, B*W*W rows)": (4096, 256, 256),
              "1024x1024 @ 1024x1024": (1024, 1024, 1024)}
    out = {}
    for name, (m, k, n) in shapes.items():
        a, b, bias = torch.randn(m, k), torch.randn(n, k), torch.randn(n)
        inner = max(1, int(2e9 / (2 * m * k * n)))  # about 2 GFLOP per timing
        for label, fn in (("a @ b", lambda a=a, b=b: a @ b.T),
                          ("F.linear (as nn.Linear)", lambda a=a, b=b, bias=bias: F.linear(a, b, bias))):
            for _ in range(2):
                fn()
            best = math.inf
            for _ in range(repeats):
                t0 = time.perf_counter()
                for _ in range(inner):
                    fn()
                best = min(best, (time.perf_counter() - t0) / inner)
            out[f"{name}, {label}"] = 2 * m * k * n / best / 1e9
    return {"kind": "ceiling", "gflops": out, "peak_rss_mb": peak_rss_mb()}


def run_trial(spec: dict[str, Any]) -> dict[str, Any]:
    import torch

    torch.set_num_threads(1)
    kind = spec["kind"]
    t0 = time.perf_counter()
    if kind == "ttc":
        res = trial_ttc(spec["method"], spec["seed"], spec["steps"], spec["eval_every"], spec["stop"],
                        spec.get("overrides"))
    elif kind == "cost":
        res = trial_cost(spec["variant"], spec["steps"], spec["warmup"], spec.get("overrides"))
    elif kind == "memory":
        res = trial_memory(spec["method"], spec["seed"], spec["steps"], spec.get("overrides"))
    elif kind == "ceiling":
        res = trial_ceiling()
    else:
        raise ValueError(f"unknown trial kind {kind!r}")
    res["process_s"] = time.perf_counter() - t0
    res["loadavg_end"] = os.getloadavg()
    return res


# ------------------------------------------------------------------------------------------------------------
# the driver
# ------------------------------------------------------------------------------------------------------------
def launch(spec: dict[str, Any], log_dir: Path) -> dict[str, Any]:
    """Run one trial in a fresh interpreter (clean peak RSS, one torch thread) and return its JSON result."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "WANDB_MODE": "disabled",
           "PYTHONWARNINGS": "ignore"}
    cmd = [sys.executable, __file__, "--trial", json.dumps(spec)]
    t0 = time.perf_counter()
    label = "-".join(str(spec[k]) for k in ("kind", "method", "variant", "seed") if k in spec)
    log_path = log_dir / f"{label}.log"
    with log_path.open("w") as log:  # progress (one line per evaluation) streams into the log as the trial runs
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=log, text=True, env=env)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stdout + log_path.read_text())[-2000:]
        print(f"trial {label} failed (rc {proc.returncode}):\n{tail}", file=sys.stderr)
        return {**spec, "error": tail, "returncode": proc.returncode}
    res = json.loads(lines[-1])
    print(f"done {label} in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    return res


def lscpu() -> dict[str, str]:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        return {k.strip(): v.strip() for k, v in (ln.split(":", 1) for ln in out.splitlines() if ":" in ln)}
    except (OSError, subprocess.CalledProcessError):
        return {}


def machine() -> dict[str, Any]:
    import torch

    info = lscpu()
    versions = {"torch": torch.__version__, "numpy": np.__version__, "python": platform.python_version()}
    for pkg in ("mope", "morl_baselines", "mo_gymnasium", "gymnasium"):
        try:
            from importlib.metadata import version

            versions[pkg] = version(pkg.replace("_", "-"))
        except Exception:  # noqa: BLE001 - a missing package is reported as such
            versions[pkg] = "not installed"
    return {"cpu": info.get("Model name", platform.processor()), "cpus": info.get("CPU(s)", str(os.cpu_count())),
            "threads_per_core": info.get("Thread(s) per core", "?"), "versions": versions,
            "date": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC"),
            "loadavg_start": os.getloadavg()}


def _median_with_failures(values: list[float | None]) -> float:
    """Median where ``None`` (a failure) counts as +inf."""
    if not values:
        return math.nan
    return float(statistics.median([math.inf if v is None else v for v in values]))


def _fmt(x: float | None, digits: int = 1, cap: str = "") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    if math.isinf(x):
        return f"> {cap}" if cap else "never"
    return f"{x:,.{digits}f}"


def _ratio(a: float | None, b: float | None) -> str:
    if a is None or b is None or any(math.isnan(v) for v in (a, b)):
        return "n/a"
    if math.isinf(a) and math.isinf(b):
        return "n/a (neither)"
    if math.isinf(b):
        return "Envelope never"
    if math.isinf(a):
        return "∞"
    return f"{a / b:.2f}x" if b else "n/a"


def _mean_ci(values: list[float]) -> str:
    """``mean [lo, hi]``: the percentile bootstrap 95% CI of the mean (mope.experiments.report's)."""
    from mope.experiments.stats import aggregate

    v = [x for x in values if x is not None and not math.isnan(x)]
    if not v:
        return "n/a"
    st = aggregate(v)
    return f"{st.mean:.3f} [{st.ci_low:.3f}, {st.ci_high:.3f}]"


def summarise(results: list[dict[str, Any]], args: argparse.Namespace) -> dict[str, dict[str, Any]]:
    """Per method: time to coverage, failures, eval and RSS figures of the ttc trials; cost and memory rows."""
    summary: dict[str, dict[str, Any]] = {}
    for method in args.methods:
        ttc = [r for r in results if r.get("kind") == "ttc" and r.get("method") == method and "error" not in r]
        s: dict[str, Any] = {"n_seeds": len(ttc)}
        if ttc:
            steps = [r["ttc_steps"] for r in ttc]
            secs = [r["ttc_train_s"] for r in ttc]
            ok = [r for r in ttc if r["reached"]]
            s.update({
                "ttc_s_median": _median_with_failures(secs),
                "ttc_s_range": (min(secs, key=lambda v: math.inf if v is None else v),
                                max(secs, key=lambda v: math.inf if v is None else v)),
                "ttc_steps_median": _median_with_failures(steps),
                "ttc_steps_range": (min(steps, key=lambda v: math.inf if v is None else v),
                                    max(steps, key=lambda v: math.inf if v is None else v)),
                "failures": len(ttc) - len(ok),
                "ttc_s_median_reached": statistics.median([r["ttc_train_s"] for r in ok]) if ok else None,
                "s_per_1k_ttc": statistics.median([r["s_per_1k"] for r in ttc]),
                "eval_s_median": statistics.median([c["eval_s"] for r in ttc for c in r["curve"]]),
                "rss_ttc_max": max(r["peak_rss_mb"] for r in ttc),
                "final_cr": [r["curve"][-1]["cr"] for r in ttc],
                "max_cr": [max(c["cr"] for c in r["curve"]) for r in ttc],
                "final_timeout_share": [r["curve"][-1]["timeout_share"] for r in ttc],
                "final_optimal_share": [r["curve"][-1].get("optimal_share", math.nan) for r in ttc],
                "final_path_error": [r["curve"][-1].get("path_error", math.nan) for r in ttc],
            })
        mem = [r for r in results if r.get("kind") == "memory" and r.get("method") == method and "error" not in r]
        full = [r for r in ttc if r["steps_run"] == args.steps and r["seed"] == args.memory_seed]
        if mem:
            s["rss_full_run"] = mem[0]["peak_rss_mb"]
            s["s_per_1k_full_run"] = mem[0]["s_per_1k"]
            s["memory_source"] = "training-only run"
        elif full and "memory" in args.parts:
            s["rss_full_run"] = full[0]["peak_rss_mb"]
            s["s_per_1k_full_run"] = full[0]["s_per_1k"]
            s["memory_source"] = "time-to-coverage trial that ran all steps"
        summary[method] = s
    return summary


def render(results: list[dict[str, Any]], args: argparse.Namespace, info: dict[str, Any], command: str) -> str:
    summary = summarise(results, args)
    cost = {r["variant"]: r for r in results if r.get("kind") == "cost" and "error" not in r}
    ceiling = next((r for r in results if r.get("kind") == "ceiling" and "error" not in r), None)
    methods = [m for m in args.methods if m != "envelope"]
    env_s = summary.get("envelope", {})
    cap = f"{args.steps:,}"
    cap_steps = f"{cap} steps"  # what a failed seed's time to coverage is shown as: more than the step cap

    def row(label: str, key: str, digits: int = 1, capped: bool = False) -> str:
        cells = [_fmt(summary.get(m, {}).get(key), digits, cap_steps if capped else "") for m in args.methods]
        ratios = [_ratio(summary.get(m, {}).get(key), env_s.get(key)) for m in methods] if env_s else []
        return f"| {label} | " + " | ".join(cells + ratios) + " |"

    def spread(key: str, digits: int = 1) -> str:
        cells = []
        for m in args.methods:
            lo_hi = summary.get(m, {}).get(key)
            cells.append("n/a" if not lo_hi else f"{_fmt(lo_hi[0], digits, cap_steps)} – "
                         f"{_fmt(lo_hi[1], digits, cap_steps)}")
        return " | ".join(cells + [""] * (len(methods) if env_s else 0))

    header = "| measure | " + " | ".join(f"`{m}`" for m in args.methods)
    header += "".join(f" | `{m}` / Envelope" for m in methods) if env_s else ""
    sep = "|---|" + "---:|" * (len(args.methods) + (len(methods) if env_s else 0))
    lines = [
        f"Side-by-side benchmark on `{ENV_ID}` (CR protocol: mope's Evaluator, 2,000 uniform + 100 equally spaced "
        f"preferences, gamma {GAMMA}, CR every {args.eval_every} steps, cap {cap} steps; training time excludes "
        "evaluation; one torch thread; each trial in its own process).",
        "",
        f"Machine: {info['cpu']}, {info['cpus']} CPUs ({info['threads_per_core']} threads/core); "
        + ", ".join(f"{k} {v}" for k, v in info["versions"].items())
        + f"; {info['date']}; load average at start {info['loadavg_start'][0]:.2f}.",
        "",
        f"Command: `{command}`",
        "",
        "### (a) time to coverage, (c) evaluation, (d) memory",
        "",
        header + " |",
        sep,
    ]
    if any(s.get("n_seeds") for s in summary.values()):
        n_fail = " | ".join(f"{summary[m].get('failures', 'n/a')} / {summary[m].get('n_seeds', 0)}"
                            for m in args.methods)
        lines += [
            row("time to CR = 1, training seconds (median; failures = ∞)", "ttc_s_median", 1),
            f"| … spread (min – max over seeds) | {spread('ttc_s_range')} |",
            row("time to CR = 1, environment steps (median)", "ttc_steps_median", 0, True),
            f"| … spread (min – max) | {spread('ttc_steps_range', 0)} |",
            f"| seeds that never reached CR = 1 within {cap} steps | {n_fail}"
            + " |" * (len(methods) if env_s else 0) + " |",
            row("training s / 1k steps over the run (median over seeds)", "s_per_1k_ttc", 2),
            row("one evaluation, s (median over all evaluations)", "eval_s_median", 3),
            row("peak RSS of a time-to-coverage trial, MiB (max over seeds)", "rss_ttc_max", 0),
        ]
    if any("rss_full_run" in s for s in summary.values()):
        lines += [row(f"peak RSS of a {cap}-step run (seed {args.memory_seed}), MiB", "rss_full_run", 0),
                  row(f"training s / 1k steps of that {cap}-step run", "s_per_1k_full_run", 2)]
    if any(s.get("final_cr") for s in summary.values()):
        lines += ["", "Final evaluation, mean [bootstrap 95% CI] over seeds:", "",
                  "| method | seeds | final CR | optimal share | path error | time-outs |",
                  "|---|---:|---:|---:|---:|---:|"]
        for m in args.methods:
            s = summary.get(m, {})
            if s.get("final_cr"):
                cells = [_mean_ci(s[k]) for k in ("final_cr", "final_optimal_share", "final_path_error",
                                                    "final_timeout_share")]
                lines.append(f"| `{m}` | {len(s['final_cr'])} | " + " | ".join(cells) + " |")
        lines += ["", "Per seed (final CR / best CR / final time-out share):", ""]
        for m in args.methods:
            s = summary.get(m, {})
            if s.get("final_cr"):
                per = ", ".join(f"{f:.2f} / {b:.2f} / {t:.0%}" for f, b, t in
                                zip(s["final_cr"], s["max_cr"], s["final_timeout_share"], strict=True))
                lines.append(f"- `{m}`: {per}")
    if cost:
        env_c = cost.get("envelope")
        top = max(ceiling["gflops"].values()) if ceiling else None
        lines += ["", f"### (b) cost per step, (c) one evaluation, (e) FLOP rate (timed over {args.cost_steps} steps "
                  "after the warm-up)", "",
                  "| setting | s / 1k steps | x Envelope | FLOP / step (est.) | achieved GFLOP/s | % of matmul ceiling "
                  "| one evaluation, s (time-out share) | peak RSS MiB |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
        for name, r in cost.items():
            ratio = _ratio(r["s_per_1k"], env_c["s_per_1k"]) if env_c else "n/a"
            share = f"{100 * r['achieved_gflops'] / top:.0f} %" if top else "n/a"
            lines.append(f"| {name} | {r['s_per_1k']:.2f} | {ratio} | {r['flop_per_step'] / 1e9:.3f} G | "
                         f"{r['achieved_gflops']:.1f} | {share} | {r['eval_s']:.3f} ({r['eval_timeout_share']:.0%}) | "
                         f"{r['peak_rss_mb']:.0f} |")
        lines += ["", "Settings: `*-default`: mope's defaults (convex head, B = 128, N_omega = 32, hidden 256x3); "
                  "`*-paper`: the paper preset (B = 32, N_omega = 64, hidden 64-128-128-64); `eql-envelope-preset`: "
                  "the envelope preset (hidden 256x4, B = 64, N_omega = 4); `envelope`: morl-baselines' Envelope "
                  "with --envelope-settings. FLOP / step counts the dense layers only (see `flop_per_update`); the "
                  "ceiling is the best single-thread matmul rate of (e)."]
    if ceiling:
        lines += ["", "### (e) the machine's ceiling: single-thread float32 matmul", "",
                  "| matmul | GFLOP/s |", "|---|---:|"]
        lines += [f"| {k} | {v:.1f} |" for k, v in ceiling["gflops"].items()]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..n-1 for time to coverage")
    parser.add_argument("--steps", type=int, default=20_000, help="step cap of a time-to-coverage trial")
    parser.add_argument("--eval-every", type=int, default=500)
    parser.add_argument("--stop-at-coverage", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--cost-steps", type=int, default=1000, help="timed steps of each (b) cost trial")
    parser.add_argument("--cost-warmup", type=int, default=100, help="untimed steps after learning_starts")
    parser.add_argument("--memory-seed", type=int, default=0)
    parser.add_argument("--parts", nargs="+", default=["ttc", "cost", "memory", "ceiling"],
                        choices=["ttc", "cost", "memory", "ceiling"])
    parser.add_argument("--workers", type=int, default=1, help="trials at a time (1 for clean timings)")
    parser.add_argument("--envelope-kwargs", type=json.loads, default=None,
                        help="JSON dict of Envelope constructor overrides (on top of --envelope-settings)")
    parser.add_argument("--envelope-settings", choices=["defaults", "example"], default="example",
                        help="Envelope's constructor defaults, or its example's settings (ENVELOPE_EXAMPLE)")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/envelope"),
                        help="writes OUT.md and OUT.json")
    parser.add_argument("--log-dir", type=Path, default=Path("runs/bench-envelope-logs"),
                        help="one log per trial (one progress line per evaluation)")
    parser.add_argument("--trial", type=json.loads, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--merge", type=Path, nargs="+", default=None,
                        help="render one table from the .json outputs of earlier invocations (runs no trial)")
    args = parser.parse_args()

    if args.trial is not None:
        print(json.dumps(run_trial(args.trial)), flush=True)
        return

    if args.merge:
        merge(args)
        return
    if "envelope" in args.methods:
        try:
            import morl_baselines  # noqa: F401
        except ImportError:
            sys.exit("morl-baselines is missing: install the bench extra in a separate venv, "
                     "e.g. `.venv-bench/bin/pip install torch==2.13.0 -e \".[bench]\"`")

    def overrides(method: str) -> dict[str, Any] | None:
        if method != "envelope":
            return None
        from mope.paper.envelope import ENVELOPE_EXAMPLE

        base = ENVELOPE_EXAMPLE if args.envelope_settings == "example" else {}
        return {**base, **(args.envelope_kwargs or {})}

    specs: list[dict[str, Any]] = []
    if "ceiling" in args.parts:
        specs.append({"kind": "ceiling"})
    if "cost" in args.parts:
        for variant, (method, _) in COST_VARIANTS.items():
            if method in args.methods:
                specs.append({"kind": "cost", "variant": variant, "steps": args.cost_steps,
                              "warmup": args.cost_warmup, "overrides": overrides(method)})
    if "ttc" in args.parts:
        for seed in range(args.seeds):
            for method in args.methods:
                specs.append({"kind": "ttc", "method": method, "seed": seed, "steps": args.steps,
                              "eval_every": args.eval_every, "stop": args.stop_at_coverage,
                              "overrides": overrides(method)})

    command = " ".join(shlex.quote(a) for a in ["WANDB_MODE=disabled", os.path.relpath(sys.executable),
                                               *sys.argv])
    info = machine()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    log_dir = args.log_dir
    log_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.workers) as pool:
        results = list(pool.map(lambda s: launch(s, log_dir), specs))
        if "memory" in args.parts:
            # (d) needs one full-length run per method; a time-to-coverage trial that ran all --steps already is one
            # (its evaluations add a few MiB of rollout arrays), so only the others get a training-only run.
            full = {r["method"] for r in results if r.get("kind") == "ttc" and r.get("steps_run") == args.steps
                    and r.get("seed") == args.memory_seed}
            mem_specs = [{"kind": "memory", "method": m, "seed": args.memory_seed, "steps": args.steps,
                          "overrides": overrides(m)} for m in args.methods if m not in full]
            results += list(pool.map(lambda s: launch(s, log_dir), mem_specs))
    info["total_wall_s"] = time.perf_counter() - t0
    info["loadavg_end"] = os.getloadavg()
    write_outputs(results, args, info, command)


def write_outputs(results: list[dict[str, Any]], args: argparse.Namespace, info: dict[str, Any],
                  command: str) -> None:
    """Print the markdown table and write it (``--out``.md) with the raw results (``--out``.json)."""
    text = render(results, args, info, command)
    print(text)
    args.out.with_suffix(".md").write_text(text)
    payload = {"machine": info, "command": command, "args": {k: v for k, v in vars(args).items() if k != "trial"},
               "summary": summarise(results, args), "results": results}
    args.out.with_suffix(".json").write_text(json.dumps(payload, indent=1, default=str) + "\n")


def merge(args: argparse.Namespace) -> None:
    """One table from several invocations' outputs (e.g. Envelope's and ours' time to coverage run side by side)."""
    payloads = [json.loads(p.read_text()) for p in args.merge]
    results = [r for pl in payloads for r in pl["results"]]
    present = {r.get("method") for r in results} | {COST_VARIANTS[r["variant"]][0] for r in results
                                                      if r.get("kind") == "cost" and r.get("variant") in COST_VARIANTS}
    args.methods = [m for m in METHODS if m in present]
    args.parts = sorted({r["kind"] for r in results})
    ttc_args = [pl["args"] for pl in payloads if any(r.get("kind") == "ttc" for r in pl["results"])]
    if ttc_args:
        args.seeds = max(a["seeds"] for a in ttc_args)
        args.steps, args.eval_every = ttc_args[0]["steps"], ttc_args[0]["eval_every"]
    info = payloads[0]["machine"]
    info["merged_from"] = [str(p) for p in args.merge]
    command = "; ".join(pl["command"] for pl in payloads)
    write_outputs(results, args, info, command)


if __name__ == "__main__":
    main()
