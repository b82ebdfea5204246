"""Profile mope's training loop with cProfile and say where the time goes.

Usage::

    .venv/bin/python benchmarks/profile_train.py [--algo mope eql] [--steps 600] [--learning-starts 100] \\
        [--top 25] [--out benchmarks/results/profile-before.txt]

For each algorithm it builds ``make_agent(algo, "deep-sea-treasure-v0", seed=0, learning_starts=...)`` with one
torch thread, trains ``--warmup`` untimed steps (imports, first allocations), then profiles ``agent.train(steps)``.
The report lists the top functions by self time (tottime) and by cumulative time, and a breakdown of the total
into buckets (network forward, backward, optimizer step, replay sampling, relabelling, the sum tree, tensor
creation, acting, ...), each bucket being the cumulative time of the named entry points (the buckets are
disjoint by construction except where noted). cProfile adds overhead to every Python call, so the Python-heavy
buckets look somewhat larger than they are without the profiler; the unprofiled seconds per step are printed too.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import time
from pathlib import Path

import torch

import mope

#: Bucket -> list of (filename fragment, function name) whose cumulative time the bucket sums. Each is an entry point
#: called from MoPE.update / MoPE.train; the network forwards inside ``envelope_target`` are split out of it.
BUCKETS: dict[str, list[tuple[str, str]]] = {
    "online forward, with grad (forward_features outside envelope_target)": [],
    "target + double-Q select forwards, no grad (inside envelope_target)": [],
    "envelope target, rest (einsum, argmax, gather)": [],
    "backward (autograd) of the Q loss": [("_tensor.py", "backward")],
    "optimizer step (Adam) of the Q-network": [("optimizer.py", "wrapper")],
    "zero_grad": [("optimizer.py", "zero_grad")],
    "grad-norm clipping": [("clip_grad.py", "_no_grad_wrapper")],
    "EQL loss / TD / priority": [("losses.py", "eql_loss"), ("losses.py", "preference_interval_td"),
                                 ("losses.py", "priority")],
    "discriminator loss (forward; its backward and Adam are in the rows above)": [("agent.py", "_discriminator_loss")],
    "replay sample (sum-tree find, gather)": [("replay.py", "sample")],
    "replay update_priorities (sum tree)": [("replay.py", "update_priorities")],
    "replay add (sum tree)": [("replay.py", "add")],
    "relabel (sample_simplex / sample_neighbours)": [("agent.py", "relabel")],
    "numpy -> tensor (_tensor)": [("agent.py", "_tensor")],
    "acting (greedy_actions)": [("agent.py", "greedy_actions")],
    "env.step": [("mo_gymnasium", "step"), ("gymnasium/wrappers", "step"), ("gymnasium/core.py", "step")],
    "target-network copy (load_state_dict)": [("module.py", "load_state_dict")],
    "episode start (reset, preference sampling)": [("agent.py", "_start_episode")],
}


def _entries(stats: pstats.Stats, fragment: str, name: str) -> list[tuple]:
    return [(key, val) for key, val in stats.stats.items()  # type: ignore[attr-defined]
            if key[2] == name and fragment in key[0]]


def outermost(stats: pstats.Stats, fragment: str, name: str) -> float:
    """Cumulative seconds of the matching functions, counting only calls not made from another match.

    (The env's ``step`` goes through several wrappers, each named ``step``; only the outermost one counts.)
    """
    matches = {key for key, _ in _entries(stats, fragment, name)}
    total = 0.0
    for _key, (_cc, _nc, _tt, ct, callers) in _entries(stats, fragment, name):
        inner = sum(v[3] for caller, v in callers.items() if caller in matches)
        total += ct - inner
    return total


def from_caller(stats: pstats.Stats, fragment: str, name: str, caller_fragment: str, caller_name: str) -> float:
    """Cumulative seconds of ``name`` spent in calls made by ``caller_name``."""
    total = 0.0
    for _key, (_cc, _nc, _tt, _ct, callers) in _entries(stats, fragment, name):
        for caller, v in callers.items():
            if caller[2] == caller_name and caller_fragment in caller[0]:
                total += v[3]
    return total


def self_time(stats: pstats.Stats, predicate) -> float:
    """Sum of tottime over functions whose ``(filename, func)`` satisfies ``predicate``."""
    return sum(tt for (filename, _l, func), (_cc, _nc, tt, _ct, _c) in stats.stats.items()  # type: ignore[attr-defined]
               if predicate(filename, func))


def profile(algo: str, steps: int, learning_starts: int, warmup: int, top: int) -> str:
    agent = mope.make_agent(algo, "deep-sea-treasure-v0", seed=0, learning_starts=learning_starts, torch_threads=1)
    agent.train(warmup)
    t0 = time.perf_counter()
    agent.train(steps)
    plain = time.perf_counter() - t0  # unprofiled reference

    prof = cProfile.Profile()
    prof.enable()
    t0 = time.perf_counter()
    agent.train(steps)
    wall = time.perf_counter() - t0
    prof.disable()

    out = io.StringIO()
    stats = pstats.Stats(prof, stream=out)
    total = max(wall, 1e-9)
    lines = [f"=== {algo}: {steps} steps after {warmup} warm-up steps (learning_starts={learning_starts}, "
             f"every profiled step makes one update) ===",
             f"unprofiled: {plain:.2f} s = {1000 * plain / steps:.1f} ms/step;  profiled: {wall:.2f} s "
             f"= {1000 * wall / steps:.1f} ms/step (profiler overhead {wall / plain - 1:+.0%})", "",
             "where the time goes (cumulative time of each entry point, % of the profiled wall time):"]
    ff_all = outermost(stats, "networks.py", "forward_features")
    ff_env = from_caller(stats, "networks.py", "forward_features", "losses.py", "envelope_target")
    env_all = outermost(stats, "losses.py", "envelope_target")
    accounted = 0.0
    for bucket, keys in BUCKETS.items():
        if bucket.startswith("online forward"):
            t = ff_all - ff_env
        elif bucket.startswith("target + double-Q"):
            t = ff_env
        elif bucket.startswith("envelope target, rest"):
            t = env_all - ff_env
        else:
            t = sum(outermost(stats, frag, name) for frag, name in keys)
        accounted += t
        lines.append(f"  {bucket:<70s} {t:7.2f} s  {100 * t / total:5.1f} %")
    lines.append(f"  {'rest (Python glue in update/train: gather/expand/view, isfinite, .item(), ...)':<70s} "
                 f"{total - accounted:7.2f} s  {100 * (total - accounted) / total:5.1f} %")

    def is_torch_c(filename: str, func: str) -> bool:
        return filename == "~" and any(k in func for k in ("torch", "Tensor", "_VariableFunctions", "run_backward",
                                                           "of type object"))

    torch_c = self_time(stats, is_torch_c)
    autograd_engine = self_time(stats, lambda f, fn: "run_backward" in fn)
    numpy_c = self_time(stats, lambda f, fn: f == "~" and "numpy" in fn)
    lines += ["", "self time by kind:",
              f"  C++ torch ops (incl. autograd engine {autograd_engine:.2f} s) {torch_c:7.2f} s  "
              f"{100 * torch_c / total:5.1f} %",
              f"  numpy C functions {numpy_c:7.2f} s  {100 * numpy_c / total:5.1f} %",
              f"  Python code (everything else) {total - torch_c - numpy_c:7.2f} s  "
              f"{100 * (total - torch_c - numpy_c) / total:5.1f} %", ""]

    stats.sort_stats("tottime").print_stats(top)
    lines += [f"top {top} by self time (tottime):", _strip(out.getvalue())]
    out.seek(0)
    out.truncate()
    stats.sort_stats("cumulative").print_stats(top)
    lines += [f"top {top} by cumulative time:", _strip(out.getvalue())]
    return "\n".join(lines)


def _strip(text: str) -> str:
    """pstats output without its header lines."""
    keep = text.split("   ncalls", 1)
    return ("   ncalls" + keep[1]).rstrip() if len(keep) == 2 else text.rstrip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algo", nargs="+", default=["mope", "eql"], choices=["mope", "eql", "ee", "pe"])
    parser.add_argument("--steps", type=int, default=600)
    parser.add_argument("--learning-starts", type=int, default=100)
    parser.add_argument("--warmup", type=int, default=200, help="untimed steps first (must exceed learning-starts)")
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    header = (f"torch {torch.__version__}, 1 thread; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}\n"
              f"command: .venv/bin/python benchmarks/profile_train.py --algo {' '.join(args.algo)} "
              f"--steps {args.steps} --learning-starts {args.learning_starts} --warmup {args.warmup}\n")
    text = header + "\n\n".join(profile(a, args.steps, args.learning_starts, args.warmup, args.top)
                                for a in args.algo)
    print(text)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
