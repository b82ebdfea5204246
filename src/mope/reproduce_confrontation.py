"""``mope reproduce confrontation``: the paper's Robot Confrontation experiment (Fig. 5, Fig. 6) and a table.

Trains, per seed, EQL and MoPE on ``mope/RobotConfrontationDiscrete-v0`` (one preference-conditioned agent
each) and the outer-loop PPO baseline on ``mope/RobotConfrontation-v0`` (one policy per preference, K of them,
on the scalarised reward ``w^T r`` through MO-Gymnasium's ``LinearReward``). Every run goes into its own folder
and a finished run is reused, so an interrupted reproduction resumes where it stopped.

Budget (``steps``): EQL and MoPE get ``steps`` environment steps each. With ``ppo_budget="each"`` (default)
every PPO policy also gets ``steps``, so each trained policy sees as much experience as the one EQL/MoPE
agent (PPO as a whole uses K times more, as the paper's outer loop does); ``ppo_budget="shared"`` splits
``steps`` over the K policies (``steps // K`` each), so the three methods use the same total.

Evaluation: EQL and MoPE under ``eval_prefs`` (100) equally spaced preferences, PPO with its K policies; each
preference/policy plays ``episodes`` episodes from the same random initial states (reset seeds
``10_000 + j``: common random numbers for every method and preference). A preference's solution is its mean
undiscounted return vector. Written into the output folder:

* ``fig5_front.png`` -- every method's solutions in (r_catch, r_move) space and its Pareto front (dashed);
* ``fig6_trajectories.png`` -- MoPE's games under 5 preferences from one initial state;
* ``table.md`` and ``results.json`` -- per method: HV, win / loss / out-of-arena / time-out rates, strategy
  diversity, mean returns, training wall time.

Strategy diversity: a preference's *strategy* is the pair (its most frequent episode outcome, its speed class:
mean speed below 1/3, between 1/3 and 2/3, or above 2/3 of ``v_max``). The table gives the number of distinct
strategies over a method's preferences and the entropy (bits) of their distribution.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import numpy as np

import mope.envs.confrontation as conf
from mope.config import Config
from mope.errors import ConfigError
from mope.experiments import run_worker

METHODS = ("ppo", "eql", "mope")
EVAL_SEED = 10_000
FIG6_PREFS = ((0.0, 1.0), (0.25, 0.75), (0.5, 0.5), (0.75, 0.25), (1.0, 0.0))
COLORS = {"ppo": "tab:orange", "eql": "tab:gray", "mope": "tab:green"}
MARKERS = {"ppo": "s", "eql": "^", "mope": "o"}


# ------------------------------------------------------------------------------------------------------------
# training (process-pool workers)
# ------------------------------------------------------------------------------------------------------------


def _train_ppo(pref: list[float], steps: int, seed: int, path: str, device: str) -> str:
    """Worker: train one PPO policy and save it to ``path`` (``.zip``) unless it exists."""
    import torch

    from mope.baselines import train_ppo

    p = Path(path)
    meta_path, meta = p.with_suffix(".json"), {"pref": pref, "steps": steps, "seed": seed}
    if p.is_file() and meta_path.is_file():
        saved = json.loads(meta_path.read_text())
        if saved == meta:
            return path
        raise ConfigError(f"'{p}' holds a PPO policy trained with {saved}, not {meta}; use another --out")
    torch.set_num_threads(1)
    p.parent.mkdir(parents=True, exist_ok=True)
    model = train_ppo(pref, steps, seed, device=device)
    tmp = p.with_name(p.stem + ".partial.zip")
    model.save(tmp)
    meta_path.write_text(json.dumps(meta))  # the metadata first: the .zip under its name marks the policy done
    tmp.rename(p)
    return path


# ------------------------------------------------------------------------------------------------------------
# evaluation
# ------------------------------------------------------------------------------------------------------------
def speed_class(mean_speed: np.ndarray, v_max: float) -> np.ndarray:
    """0, 1, 2: mean speed below 1/3, between 1/3 and 2/3, above 2/3 of ``v_max``."""
    return np.clip((np.asarray(mean_speed) / v_max * 3).astype(int), 0, 2)


def strategy_diversity(outcomes: list[list[str]], mean_speeds: np.ndarray, v_max: float) -> dict[str, float]:
    """Distinct strategies and their entropy (bits) over preferences (see the module docstring).

    Args:
        outcomes: Per preference, the outcomes of its episodes.
        mean_speeds: Per preference, red's mean speed over its episodes (m/s).
        v_max: Speed limit.
    """
    classes = speed_class(mean_speeds, v_max)
    labels = [(Counter(o).most_common(1)[0][0], int(c)) for o, c in zip(outcomes, classes, strict=True)]
    counts = np.array(list(Counter(labels).values()), dtype=np.float64)
    p = counts / counts.sum()
    return {"strategies": len(counts), "entropy_bits": float(-(p * np.log2(p)).sum())}


def summarize(prefs: np.ndarray, episodes: Any, per_pref: int, ref_point: np.ndarray, dt: float,
              v_max: float) -> dict[str, Any]:
    """Per-preference solutions and the method's metrics from ``len(prefs) * per_pref`` episodes (pref-major)."""
    from mope.metrics import hypervolume

    n = len(prefs)
    ret = episodes.returns.reshape(n, per_pref, -1)
    points = ret.mean(axis=1)
    outcomes = [episodes.outcomes[i * per_pref:(i + 1) * per_pref] for i in range(n)]
    # red's mean speed: the distance it covered (r_move without the -10 penalty) over the time it drove
    out_pen = np.array([[o == "red_out" for o in row] for row in outcomes])
    lengths = episodes.lengths.reshape(n, per_pref)
    dist = ret[..., 1] + 10.0 * out_pen
    speed = (dist / np.maximum(lengths * dt, dt)).mean(axis=1)
    flat = Counter(episodes.outcomes)
    total = len(episodes.outcomes)
    return {
        "points": points, "prefs": prefs, "outcomes": outcomes,
        "hv": float(hypervolume(points, ref_point)),
        "win": flat["red_win"] / total, "loss": flat["blue_win"] / total, "out": flat["red_out"] / total,
        "blue_out": flat["blue_out"] / total, "timeout": flat["running"] / total,
        **strategy_diversity(outcomes, speed, v_max),
        "r_catch": float(points[:, 0].mean()), "r_move": float(points[:, 1].mean()),
    }


def evaluate_agent(run_dir: Path, prefs: np.ndarray, episodes: int, record_prefs: np.ndarray | None = None) -> tuple:
    """Play a trained EQL/MoPE run under each preference; return its episodes (and recorded games)."""
    import mo_gymnasium as mo_gym

    from mope.agent import MoPE
    from mope.baselines import play_episodes

    agent = MoPE.load(run_dir / "checkpoints" / "final.pt")
    c = agent.config
    limit = c.max_episode_steps or conf.DEFAULT_HORIZON
    rep = np.repeat(prefs, episodes, axis=0)
    seeds = [EVAL_SEED + j for _ in range(len(prefs)) for j in range(episodes)]

    def make() -> Any:
        return mo_gym.make(c.env_id).unwrapped

    eps = play_episodes(lambda obs, idx: agent.greedy_actions(obs, rep[idx]), make, len(rep), seeds, limit, c.gamma)
    games = None
    if record_prefs is not None:
        rp = np.asarray(record_prefs, dtype=np.float64)
        games = play_episodes(lambda obs, idx: agent.greedy_actions(obs, rp[idx]), make, len(rp),
                              [EVAL_SEED] * len(rp), limit, c.gamma, record=True)
    return eps, games


def evaluate_ppo(paths: list[Path], episodes: int, gamma: float = 0.99) -> tuple[np.ndarray, Any]:
    """Play each saved PPO policy ``episodes`` times; return the preferences and the episodes (policy-major)."""
    import mo_gymnasium as mo_gym
    from stable_baselines3 import PPO

    from mope.baselines import Episodes, play_episodes

    prefs, parts = [], []
    for p in paths:
        meta = json.loads(p.with_suffix(".json").read_text())
        model = PPO.load(p, device="cpu")
        prefs.append(meta["pref"])
        parts.append(play_episodes(lambda obs, idx, mdl=model: mdl.predict(obs, deterministic=True)[0],
                                   lambda: mo_gym.make(conf.CONTINUOUS_ID).unwrapped, episodes,
                                   [EVAL_SEED + j for j in range(episodes)], conf.DEFAULT_HORIZON, gamma))
    eps = Episodes(np.concatenate([e.returns for e in parts]), np.concatenate([e.discounted for e in parts]),
                   np.concatenate([e.lengths for e in parts]), [o for e in parts for o in e.outcomes])
    return np.asarray(prefs, dtype=np.float64), eps


# ------------------------------------------------------------------------------------------------------------
# figures
# ------------------------------------------------------------------------------------------------------------
def plot_fig5(points: dict[str, np.ndarray], path: Path) -> Path:
    """Fig. 5: each method's solutions in (r_catch, r_move) space, with its Pareto front as a dashed line."""
    import matplotlib

    matplotlib.use("Agg")
    from mope.metrics import pareto_front
    from mope.plots import plt, save_figure

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    for name, pts in points.items():
        c = COLORS.get(name)
        ax.scatter(pts[:, 0], pts[:, 1], s=22, marker=MARKERS.get(name, "o"), color=c, alpha=0.6,
                   label=f"{name} ({len(pts)} solutions)")
        front = pareto_front(pts)
        front = front[np.argsort(front[:, 0])]
        ax.plot(front[:, 0], front[:, 1], "--", color=c, lw=1.6)
    ax.axvline(10, color="k", lw=0.6, ls=":")
    ax.text(10, ax.get_ylim()[1], " catch = 10", fontsize=7, va="top")
    ax.set_xlabel("r_catch (episode return, mean over episodes)")
    ax.set_ylabel("r_move (episode return, mean over episodes)")
    ax.set_title("Robot Confrontation: solutions per preference and fitted (Pareto) fronts", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    save_figure(fig, path, dpi=120)
    return path


def plot_fig6(games: Any, prefs: np.ndarray, half: float, path: Path) -> Path:
    """Fig. 6: MoPE's games under several preferences, from one initial state."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(prefs)
    fig, axes = plt.subplots(1, n, figsize=(2.9 * n, 3.2), squeeze=False)
    for k, ax in enumerate(axes[0]):
        r = games.returns[k]
        conf.draw_episode(ax, games.histories[k], half, legend=k == 0,
                          title=f"w = ({prefs[k, 0]:.2f}, {prefs[k, 1]:.2f})\n{games.outcomes[k]}, "
                                f"r = ({r[0]:.1f}, {r[1]:.1f})")
    fig.suptitle("MoPE under different preferences (w_catch, w_move); same initial state", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.9))
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


# ------------------------------------------------------------------------------------------------------------
# the experiment
# ------------------------------------------------------------------------------------------------------------
def reproduce_confrontation(out: str | Path, seeds: int = 1, steps: int = 15_000, ppo_prefs: int = 11,
                            eval_prefs: int = 100, episodes: int = 5, workers: int = 2, progress: bool = True,
                            ppo_budget: str = "each", device: str = "cpu",
                            **overrides: Any) -> dict[str, Any]:
    """Train PPO x K, EQL and MoPE, evaluate them and write Fig. 5, Fig. 6 and the table.

    Args:
        out: Output folder (run folders ``eql/seed_s``, ``mope/seed_s``, ``ppo/seed_s/pref_k.zip`` inside).
        seeds: Seeds per method.
        steps: Environment steps per EQL/MoPE agent, and per PPO policy (``ppo_budget="each"``) or for all K
            together (``"shared"``).
        ppo_prefs: K, PPO's equally spaced preferences.
        eval_prefs: Equally spaced preferences for evaluating EQL and MoPE.
        episodes: Episodes per preference (or PPO policy).
        workers: Training processes.
        progress: Show a progress bar over the runs.
        ppo_budget: ``"each"`` or ``"shared"`` (see the module docstring).
        device: Torch device of PPO (EQL/MoPE take ``device`` from ``overrides``, default cpu).
        **overrides: Config fields for EQL and MoPE (e.g. ``n_omega=32``).

    Returns:
        ``{"results", "table", "out", "train_wall_s", "eval_wall_s"}``.
    """
    from tqdm.auto import tqdm

    from mope.plots import markdown_table
    from mope.preferences import equally_spaced

    for name, val in (("seeds", seeds), ("steps", steps), ("ppo_prefs", ppo_prefs), ("eval_prefs", eval_prefs),
                      ("episodes", episodes), ("workers", workers)):
        if not isinstance(val, int) or val < 1:
            raise ConfigError(f"{name}={val!r} is out of range: must be an integer >= 1")
    if ppo_budget not in ("each", "shared"):
        raise ConfigError(f"ppo_budget={ppo_budget!r} is unknown; choose each or shared")
    ppo_steps = steps if ppo_budget == "each" else steps // ppo_prefs
    if ppo_steps < 64:
        raise ConfigError(f"steps={steps} leaves {ppo_steps} steps per PPO policy; need at least 64")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    base = {"env_id": conf.DISCRETE_ID, "total_steps": steps, "eval_every": 0, "eval_prefs": eval_prefs,
            "checkpoint_every": 0, **overrides}
    configs = {f"{a}/seed_{s}": Config.for_algo(a, seed=s, **base) for s in range(seeds) for a in ("eql", "mope")}
    ppo_w = equally_spaced(2, ppo_prefs)
    ppo_paths = {s: [out / "ppo" / f"seed_{s}" / f"pref_{k:02d}.zip" for k in range(ppo_prefs)] for s in range(seeds)}

    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(run_worker, cfg.to_dict(), str(out / name)): name for name, cfg in configs.items()}
        for s in range(seeds):
            for k, p in enumerate(ppo_paths[s]):
                futures[pool.submit(_train_ppo, ppo_w[k].tolist(), ppo_steps, 1000 * s + k, str(p), device)] = \
                    f"ppo/seed_{s}/pref_{k:02d}"
        with tqdm(total=len(futures), desc="runs", disable=not progress, unit="run") as bar:
            for fut in as_completed(futures):
                fut.result()
                bar.update(1)
                bar.set_postfix_str(futures[fut])
    train_wall = time.perf_counter() - t0

    t1 = time.perf_counter()
    probe = conf.RobotConfrontationEnv()
    ref = conf.reference_point(1.0, max(overrides.get("max_episode_steps") or 0, conf.DEFAULT_HORIZON))
    eval_w = equally_spaced(2, eval_prefs)
    fig6_w = np.asarray(FIG6_PREFS)
    per_seed: dict[str, list[dict[str, Any]]] = {m: [] for m in METHODS}
    games = None
    for s in range(seeds):
        w, eps = evaluate_ppo(ppo_paths[s], episodes)
        per_seed["ppo"].append(summarize(w, eps, episodes, ref, probe.dt, probe.v_max))
        for a in ("eql", "mope"):
            eps, g = evaluate_agent(out / a / f"seed_{s}", eval_w, episodes,
                                    fig6_w if (a == "mope" and s == 0) else None)
            games = g if g is not None else games
            per_seed[a].append(summarize(eval_w, eps, episodes, ref, probe.dt, probe.v_max))
    eval_wall = time.perf_counter() - t1

    plot_fig5({m: per_seed[m][0]["points"] for m in METHODS}, out / "fig5_front.png")
    plot_fig6(games, fig6_w, probe.half, out / "fig6_trajectories.png")

    keys = ("hv", "win", "loss", "out", "blue_out", "timeout", "strategies", "entropy_bits", "r_catch", "r_move")
    results: dict[str, Any] = {}
    for m in METHODS:
        vals = {k: np.array([r[k] for r in per_seed[m]], dtype=np.float64) for k in keys}
        results[m] = {k: {"mean": float(v.mean()), "std": float(v.std())} for k, v in vals.items()}
        results[m]["solutions"] = len(per_seed[m][0]["points"])
        results[m]["points_seed0"] = per_seed[m][0]["points"].round(4).tolist()
        results[m]["prefs_seed0"] = per_seed[m][0]["prefs"].round(4).tolist()
    for a in ("eql", "mope"):
        walls = [json.loads((out / a / f"seed_{s}" / "summary.json").read_text()) for s in range(seeds)]
        results[a]["train_wall_s"] = float(np.mean([w.get("wall_s", np.nan) for w in walls]))

    def pm(d: dict[str, float], fmt: str) -> str:
        return f"{d['mean']:{fmt}}" if seeds == 1 else f"{d['mean']:{fmt}} ± {d['std']:{fmt}}"

    header = ["method", "policies x prefs", "steps per policy", "HV", "win", "loss", "out of arena", "time-out",
              "strategies (entropy, bits)", "mean r_catch", "mean r_move"]
    rows = []
    for m in METHODS:
        r = results[m]
        shape = f"{ppo_prefs} x 1" if m == "ppo" else f"1 x {eval_prefs}"
        rows.append([m, shape, f"{ppo_steps if m == 'ppo' else steps:,}", pm(r["hv"], ".1f"), pm(r["win"], ".3f"),
                     pm(r["loss"], ".3f"), pm(r["out"], ".3f"), pm(r["timeout"], ".3f"),
                     f"{pm(r['strategies'], '.1f')} ({pm(r['entropy_bits'], '.2f')})", pm(r["r_catch"], ".2f"),
                     pm(r["r_move"], ".2f")])
    table = markdown_table(header, rows)
    (out / "table.md").write_text(table + "\n")
    (out / "results.json").write_text(json.dumps({
        "results": results, "seeds": seeds, "steps": steps, "ppo_steps": ppo_steps, "ppo_budget": ppo_budget,
        "ppo_prefs": ppo_prefs, "eval_prefs": eval_prefs, "episodes": episodes, "ref_point": ref.tolist(),
        "train_wall_s": train_wall, "eval_wall_s": eval_wall, "overrides": overrides}, indent=2))
    return {"results": results, "table": table, "out": out, "train_wall_s": train_wall, "eval_wall_s": eval_wall}
