"""``mope reproduce confrontation``: the paper's Robot Confrontation experiment (Fig. 5, Fig. 6) and a table.

Trains, per seed, three preference-conditioned agents on ``mope/RobotConfrontationDiscrete-v0`` -- ``mope``
(the game's defaults, :data:`mope.config.ENV_DEFAULTS`: MoPE with scripted demonstrations and 4 envs),
``mope-nodemo`` (the paper's method alone: the same without demonstrations) and ``eql`` (EQL, also without
demonstrations, vectorised the same way) -- and the outer-loop PPO baseline on ``mope/RobotConfrontation-v0``
(one policy per preference, K of them, on the scalarised reward ``w^T r`` through MO-Gymnasium's
``LinearReward``). Every run goes into its own folder
and every run goes through the job runner (:mod:`mope.experiments.jobs`): a finished run is reused and an
interrupted one resumes from its last checkpoint, locally or on Ray.

Budget (``steps``): every agent gets ``steps`` environment steps. With ``ppo_budget="each"`` (default)
every PPO policy also gets ``steps``, so each trained policy sees as much experience as the one EQL/MoPE
agent (PPO as a whole uses K times more, as the paper's outer loop does); ``ppo_budget="shared"`` splits
``steps`` over the K policies (``steps // K`` each), so the three methods use the same total.

Evaluation: the agents under ``eval_prefs`` (100) equally spaced preferences, PPO with its K policies; each
preference/policy plays ``episodes`` (100) episodes from the same random initial states (reset seeds
``10_000 + j``: common random numbers for every method, preference and reference policy). A preference's
solution is its mean undiscounted return vector. Beside Fig. 5's points, every seed is scored as the issue
"the robot game, learned" asks (:func:`acceptance_scores`): outcome rates at w_catch = 1, 0.9, 0.8, 0.7 and the
largest out-of-arena share at w_catch <= 0.5 (0, 0.1, ..., 0.5), and the mean *discounted* utility over the
``eval_prefs`` preferences beside the reference policies' upper envelope (the best of the four at each
preference). PPO's utility at a preference is its best policy's there (a set of policies, as for the
references). Written into the output folder:

* ``fig5_front.png`` -- every method's solutions in (r_catch, r_move) space and its Pareto front (dashed);
* ``fig6_trajectories.png`` -- MoPE's games under 5 preferences from one initial state;
* ``table.md`` and ``results.json`` -- per method: the scores above (mean over seeds, bootstrap 95 % CI), HV,
  win / loss / out-of-arena / time-out rates, strategy diversity, mean returns, training wall time.

Strategy diversity: a preference's *strategy* is the pair (its most frequent episode outcome, its speed class:
mean speed below 1/3, between 1/3 and 2/3, or above 2/3 of ``v_max``). The table gives the number of distinct
strategies over a method's preferences and the entropy (bits) of their distribution.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

import mope.envs.confrontation as conf
from mope.config import Config
from mope.errors import ConfigError
from mope.experiments.jobs import Job, run_all_or_raise
from mope.experiments.locks import FolderLock

METHODS = ("ppo", "eql", "mope-nodemo", "mope")
#: The preference-conditioned agents and what each changes in the game's defaults (mope.config.ENV_DEFAULTS).
LEARNERS: dict[str, tuple[str, dict[str, Any]]] = {
    "eql": ("eql", {"demos": "", "demo_batch_share": 0.0, "demo_pretrain_steps": 0}),
    "mope-nodemo": ("mope", {"demos": "", "demo_batch_share": 0.0, "demo_pretrain_steps": 0}),
    "mope": ("mope", {}),
}
LABELS = {"ppo": "PPO, one policy per preference", "eql": "EQL (no demonstrations)",
          "mope-nodemo": "MoPE alone (the paper's method)", "mope": "MoPE + demonstrations (the defaults)"}
#: Catch weights of the outcome rates in the table, and those where leaving the arena is judged.
WIN_PREFS = (1.0, 0.9, 0.8, 0.7)
OUT_PREFS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
#: Red's reference policies (mope.envs.confrontation_batch.REFERENCE_POLICIES), one point each: the points a
#: learner must reach or pass, evaluated from the same initial states as the agents.
REFERENCES = ("scripted pursuer", "leave the arena", "pure pursuit", "random")
EVAL_SEED = 10_000
FIG6_PREFS = ((0.0, 1.0), (0.25, 0.75), (0.5, 0.5), (0.75, 0.25), (1.0, 0.0))
COLORS = {"ppo": "tab:orange", "eql": "tab:gray", "mope-nodemo": "tab:blue", "mope": "tab:green"}
MARKERS = {"ppo": "s", "eql": "^", "mope-nodemo": "v", "mope": "o"}


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


def evaluate_agent(run_dir: Path, prefs: np.ndarray, episodes: int, record_prefs: np.ndarray | None = None
                   ) -> tuple[Any, Any, Any]:
    """Play a trained agent's run under each preference; return its episodes, its recorded games (or None) and
    the agent itself."""
    import mo_gymnasium as mo_gym

    from mope.agent.agent import MoPE
    from mope.paper.ppo import play_episodes

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
    return eps, games, agent


def mean_discounted(discounted: np.ndarray, n: int, per_pref: int) -> np.ndarray:
    """``(n, m)`` mean discounted return of each of ``n`` preferences (or policies) from its ``per_pref``
    episodes (pref-major rows)."""
    return discounted.reshape(n, per_pref, -1).mean(axis=1)


def acceptance_scores(utility: np.ndarray, ref_utility: np.ndarray, rates: dict[float, dict[str, float]]
                      ) -> dict[str, float]:
    """One seed's scores against the issue's acceptance list.

    Args:
        utility: ``(n,)`` the method's discounted utility ``w^T G(w)`` at each evaluation preference.
        ref_utility: ``(n,)`` the reference policies' upper envelope there.
        rates: Outcome rates (:func:`mope.evaluation.game_probe.outcome_rates`) at every catch weight of
            :data:`WIN_PREFS` and :data:`OUT_PREFS`.

    Returns:
        ``eu``, ``eu_envelope``, ``eu_gap`` (eu minus the envelope), ``win_<w>`` per catch weight, ``win_hi`` (mean
        win share at w_catch 1, 0.9, 0.8), ``out_lo`` (the out-of-arena share of all games at w_catch <= 0.5,
        pooled as ``win_hi`` pools the wins) and ``out_lo_max`` (the largest share at any one of those weights).
    """
    return {"eu": float(np.mean(utility)), "eu_envelope": float(np.mean(ref_utility)),
            "eu_gap": float(np.mean(utility - ref_utility)),
            **{f"win_{w:g}": float(rates[w]["win"]) for w in WIN_PREFS},
            "win_hi": float(np.mean([rates[w]["win"] for w in (1.0, 0.9, 0.8)])),
            "out_lo": float(np.mean([rates[w]["out"] for w in OUT_PREFS])),
            "out_lo_max": float(max(rates[w]["out"] for w in OUT_PREFS))}


def evaluate_ppo(folders: list[Path], episodes: int, gamma: float = 0.99) -> tuple[np.ndarray, Any]:
    """Play each saved PPO policy ``episodes`` times; return the preferences and the episodes (policy-major)."""
    import mo_gymnasium as mo_gym
    from stable_baselines3 import PPO

    from mope.paper.ppo import Episodes, play_episodes, ppo_policy

    prefs, parts = [], []
    for folder in folders:
        meta = json.loads((folder / "summary.json").read_text())["meta"]
        model = PPO.load(folder / "policy.zip", device="cpu")
        prefs.append(meta["pref"])
        parts.append(play_episodes(ppo_policy(model, conf.RobotConfrontationEnv().action_space),
                                   lambda: mo_gym.make(conf.CONTINUOUS_ID).unwrapped, episodes,
                                   [EVAL_SEED + j for j in range(episodes)], conf.DEFAULT_HORIZON, gamma))
    eps = Episodes(np.concatenate([e.returns for e in parts]), np.concatenate([e.discounted for e in parts]),
                   np.concatenate([e.lengths for e in parts]), [o for e in parts for o in e.outcomes])
    return np.asarray(prefs, dtype=np.float64), eps


# ------------------------------------------------------------------------------------------------------------
# figures
# ------------------------------------------------------------------------------------------------------------
def plot_fig5(points: dict[str, np.ndarray], path: Path, references: dict[str, np.ndarray] | None = None) -> Path:
    """Fig. 5: each method's solutions in (r_catch, r_move) space, with its Pareto front as a dashed line; the
    reference policies as black markers."""
    import matplotlib

    matplotlib.use("Agg")
    from mope.experiments.plots import plt, save_figure
    from mope.metrics import pareto_front

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    for name, pts in points.items():
        c = COLORS.get(name)
        ax.scatter(pts[:, 0], pts[:, 1], s=22, marker=MARKERS.get(name, "o"), color=c, alpha=0.6,
                   label=f"{name} ({len(pts)} solutions)")
        front = pareto_front(pts)
        front = front[np.argsort(front[:, 0])]
        ax.plot(front[:, 0], front[:, 1], "--", color=c, lw=1.6)
    for (name, pt), marker in zip((references or {}).items(), "XPD*", strict=False):
        ax.scatter([pt[0]], [pt[1]], s=70, marker=marker, color="k", label=f"reference: {name}", zorder=5)
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
def confrontation_jobs(seeds: Sequence[int], steps: int, ppo_prefs: int, ppo_steps: int, eval_prefs: int,
                       device: str, overrides: dict[str, Any]) -> list[Job]:
    """The agents' runs (:data:`LEARNERS`, one per seed, each from the game's defaults) and PPO policies (K per
    seed), seed-major."""
    from mope.preferences import equally_spaced

    base = {"env_id": conf.DISCRETE_ID, "total_steps": steps, "eval_prefs": eval_prefs,
            "checkpoint_every": 25_000, **overrides}
    ppo_w = equally_spaced(2, ppo_prefs)
    jobs = []
    for s in seeds:
        jobs += [Job(f"{name}-s{s}", "train", Config.from_dict({"algo": algo, "seed": s, **changes, **base}).to_dict())
                 for name, (algo, changes) in LEARNERS.items()]
        jobs += [Job(ppo_name(s, k), "ppo", {"pref": ppo_w[k].tolist(), "steps": ppo_steps, "seed": 1000 * s + k,
                                             "env_id": conf.CONTINUOUS_ID, "device": device})
                 for k in range(ppo_prefs)]
    return jobs


def ppo_name(seed: int, k: int) -> str:
    """Folder of PPO policy ``k`` of seed ``seed``."""
    return f"ppo-s{seed}-pref{k:02d}"


def check_confrontation_args(seeds: int | str | Sequence[int], steps: int, ppo_prefs: int, eval_prefs: int,
                             episodes: int, workers: int, ppo_budget: str) -> tuple[list[int], int]:
    """Validate the arguments; return the seeds (:func:`mope.experiments.sweep.seed_list`) and the steps each PPO policy
    gets."""
    from mope.experiments.sweep import seed_list

    seed_values = seed_list(seeds)
    for name, val in (("steps", steps), ("ppo_prefs", ppo_prefs), ("eval_prefs", eval_prefs),
                      ("episodes", episodes), ("workers", workers)):
        if not isinstance(val, int) or val < 1:
            raise ConfigError(f"{name}={val!r} is out of range: must be an integer >= 1")
    if ppo_budget not in ("each", "shared"):
        raise ConfigError(f"ppo_budget={ppo_budget!r} is unknown; choose each or shared")
    ppo_steps = steps if ppo_budget == "each" else steps // ppo_prefs
    if ppo_steps < 64:
        raise ConfigError(f"steps={steps} leaves {ppo_steps} steps per PPO policy; need at least 64")
    return seed_values, ppo_steps


def evaluate_confrontation(out: Path, seeds: Sequence[int], ppo_prefs: int, eval_prefs: int, episodes: int,
                           max_steps: int | None) -> tuple[dict[str, list[dict[str, Any]]], Any]:
    """Every method's summary and scores (:func:`acceptance_scores`) per seed, and MoPE's recorded Fig. 6 games
    (the first seed)."""
    from mope.envs.confrontation_batch import play_reference
    from mope.evaluation.game_probe import outcome_rates, play_agent
    from mope.paper.ppo import Episodes
    from mope.preferences import equally_spaced

    probe = conf.RobotConfrontationEnv()
    horizon = max(max_steps or 0, conf.DEFAULT_HORIZON)
    ref = conf.reference_point(1.0, horizon)
    eval_w = equally_spaced(2, eval_prefs)
    fig6_w = np.asarray(FIG6_PREFS)
    catch_w = (*WIN_PREFS, *OUT_PREFS)
    starts = [EVAL_SEED + j for j in range(episodes)]
    played = {name: play_reference(name, starts, horizon) for name in REFERENCES}
    ref_utility = np.max([eval_w @ disc.mean(axis=0) for _, disc, _ in played.values()], axis=0)
    per_seed: dict[str, list[dict[str, Any]]] = {m: [] for m in METHODS}
    games = None
    for s in seeds:
        w, eps = evaluate_ppo([out / ppo_name(s, k) for k in range(ppo_prefs)], episodes)
        summary = summarize(w, eps, episodes, ref, probe.dt, probe.v_max)
        utility = (eval_w @ mean_discounted(eps.discounted, len(w), episodes).T).max(axis=1)  # the best policy
        nearest = {x: int(np.argmin(np.abs(w[:, 0] - x))) for x in catch_w}  # the policy trained nearest x
        rates = {x: outcome_rates(summary["outcomes"][k]) for x, k in nearest.items()}
        per_seed["ppo"].append({**summary, **acceptance_scores(utility, ref_utility, rates)})
        for a in LEARNERS:
            record = fig6_w if (a == "mope" and s == seeds[0]) else None
            eps, g, agent = evaluate_agent(out / f"{a}-s{s}", eval_w, episodes, record)
            games = g if g is not None else games
            summary = summarize(eval_w, eps, episodes, ref, probe.dt, probe.v_max)
            utility = (mean_discounted(eps.discounted, eval_prefs, episodes) * eval_w).sum(axis=1)
            rates = {x: outcome_rates(play_agent(agent, x, episodes, agent.config.gamma, horizon)[1])
                     for x in catch_w}
            per_seed[a].append({**summary, **acceptance_scores(utility, ref_utility, rates)})
    for name, (ret, disc, outcomes) in played.items():
        eps = Episodes(ret, disc, np.full(len(ret), 0), outcomes)
        summary = summarize(np.full((1, 2), 0.5), eps, len(ret), ref, probe.dt, probe.v_max)
        rates = dict.fromkeys(catch_w, outcome_rates(outcomes))  # a scripted policy ignores the preference
        per_seed[name] = [{**summary, **acceptance_scores(eval_w @ disc.mean(axis=0), ref_utility, rates)}]
    return per_seed, games


SCORE_KEYS = ("eu", "eu_envelope", "eu_gap", *(f"win_{w:g}" for w in WIN_PREFS), "win_hi", "out_lo", "out_lo_max")


def confrontation_results(out: Path, per_seed: dict[str, list[dict[str, Any]]], seeds: Sequence[int]
                          ) -> dict[str, Any]:
    """Mean, std and bootstrap 95 % CI over seeds of every table metric and score, each seed's values, plus the
    first seed's solutions and the agents' training time."""
    from mope.experiments.stats import bootstrap_ci

    keys = ("hv", "win", "loss", "out", "blue_out", "timeout", "strategies", "entropy_bits", "r_catch", "r_move",
            *SCORE_KEYS)
    results: dict[str, Any] = {}
    for m in (*METHODS, *REFERENCES):
        vals = {k: np.array([r[k] for r in per_seed[m]], dtype=np.float64) for k in keys}
        results[m] = {k: {"mean": float(v.mean()), "std": float(v.std()), "ci95": list(bootstrap_ci(v)),
                          "seeds": v.round(4).tolist()} for k, v in vals.items()}
        results[m]["solutions"] = len(per_seed[m][0]["points"])
        results[m]["points_seed0"] = per_seed[m][0]["points"].round(4).tolist()
        results[m]["prefs_seed0"] = per_seed[m][0]["prefs"].round(4).tolist()
    for a in LEARNERS:
        walls = [json.loads((out / f"{a}-s{s}" / "summary.json").read_text()) for s in seeds]
        results[a]["train_wall_s"] = float(np.mean([w.get("wall_s", np.nan) for w in walls]))
    return results


def reference_front_hv(per_seed: dict[str, list[dict[str, Any]]], ref: np.ndarray) -> float:
    """Hypervolume of the reference policies' points taken together (their front)."""
    from mope.metrics import hypervolume

    return float(hypervolume(np.concatenate([per_seed[r][0]["points"] for r in REFERENCES]), ref))


def confrontation_table(results: dict[str, Any], seeds: int, steps: int, ppo_steps: int, ppo_prefs: int,
                        eval_prefs: int) -> str:
    """The reproduction's table (mean ± std over seeds)."""
    from mope.experiments.plots import markdown_table

    def pm(d: dict[str, float], fmt: str) -> str:
        return f"{d['mean']:{fmt}}" if seeds == 1 else f"{d['mean']:{fmt}} ± {d['std']:{fmt}}"

    header = ["method", "policies x prefs", "steps per policy", "HV", "win", "loss", "out of arena", "time-out",
              "strategies (entropy, bits)", "mean r_catch", "mean r_move"]
    rows = []
    for m in (*METHODS, *REFERENCES):
        r = results[m]
        shape = f"{ppo_prefs} x 1" if m == "ppo" else "1 (scripted)" if m in REFERENCES else f"1 x {eval_prefs}"
        budget = "-" if m in REFERENCES else f"{ppo_steps if m == 'ppo' else steps:,}"
        name = f"reference: {m}" if m in REFERENCES else m
        rows.append([name, shape, budget, pm(r["hv"], ".1f"), pm(r["win"], ".3f"),
                     pm(r["loss"], ".3f"), pm(r["out"], ".3f"), pm(r["timeout"], ".3f"),
                     f"{pm(r['strategies'], '.1f')} ({pm(r['entropy_bits'], '.2f')})", pm(r["r_catch"], ".2f"),
                     pm(r["r_move"], ".2f")])
    return markdown_table(header, rows)


def scores_table(results: dict[str, Any], seeds: int, episodes: int, eval_prefs: int) -> str:
    """The acceptance scores per method (mean over seeds, bootstrap 95 % CI over seeds)."""
    from mope.experiments.plots import markdown_table

    def ci(d: dict[str, Any], fmt: str) -> str:
        return f"{d['mean']:{fmt}}" if seeds == 1 else f"{d['mean']:{fmt}} [{d['ci95'][0]:{fmt}}, {d['ci95'][1]:{fmt}}]"

    header = ["method", "win @ w_catch 1 / 0.9 / 0.8 / 0.7", "win, w_catch 0.8-1", "out, w_catch 0-0.5",
              "max out, w_catch <= 0.5",
              f"discounted EU ({eval_prefs} prefs)", "EU - references' envelope"]
    rows = []
    for m in (*METHODS, "scripted pursuer"):
        r = results[m]
        rows.append([LABELS.get(m, f"reference: {m}"), " / ".join(f"{r[f'win_{w:g}']['mean']:.2f}" for w in WIN_PREFS),
                     ci(r["win_hi"], ".3f"), ci(r["out_lo"], ".3f"),
                     f"{r['out_lo_max']['mean']:.3f} (max {max(r['out_lo_max']['seeds']):.2f})",
                     ci(r["eu"], ".3f"), ci(r["eu_gap"], "+.3f")])
    env = results["scripted pursuer"]["eu_envelope"]["mean"]
    return (markdown_table(header, rows) + f"\n\n{seeds} seed(s), {episodes} common start states (reset seeds "
            f"{EVAL_SEED}..{EVAL_SEED + episodes - 1}); references' upper envelope of discounted EU: {env:.3f}. "
            "Mean over seeds [bootstrap 95 % CI over seeds]; out: the share of all games at w_catch 0, 0.1, ..., "
            "0.5 that end out of the arena (pooled over the six weights, as the win share pools w_catch 0.8-1); "
            "max out: the mean over seeds of each seed's largest share at one of those weights (and the largest of "
            "any seed).")


def reproduce_confrontation(out: str | Path, seeds: int | str | Sequence[int] = 1, steps: int = 15_000,
                            ppo_prefs: int = 11, eval_prefs: int = 100, episodes: int = 100, workers: int = 2,
                            progress: bool = True, ppo_budget: str = "each", device: str = "cpu",
                            backend: str = "local", address: str | None = None, **overrides: Any) -> dict[str, Any]:
    """Train PPO x K and the agents of :data:`LEARNERS`, evaluate them and write Fig. 5, Fig. 6 and the tables.

    Args:
        out: Output folder (run folders ``eql-s<seed>``, ``mope-nodemo-s<seed>``, ``mope-s<seed>``,
            ``ppo-s<seed>-pref<k>`` inside).
        seeds: Seeds per method: a count ``N`` (``0..N-1``), a range ``"5-9"`` or a list
            (:func:`mope.experiments.sweep.seed_list`); the figures show the first.
        steps: Environment steps per EQL/MoPE agent, and per PPO policy (``ppo_budget="each"``) or for all K
            together (``"shared"``).
        ppo_prefs: K, PPO's equally spaced preferences.
        eval_prefs: Equally spaced preferences for evaluating EQL and MoPE.
        episodes: Episodes per preference (or PPO policy): the common start states.
        workers: Training processes.
        progress: Show a progress bar over the runs.
        ppo_budget: ``"each"`` or ``"shared"`` (see the module docstring).
        device: Torch device of PPO (EQL/MoPE take ``device`` from ``overrides``, default cpu).
        backend: ``local`` or ``ray`` (the job runner's backends).
        address: Ray cluster address.
        **overrides: Config fields for every agent (e.g. ``n_omega=32``), over the game's defaults.

    Returns:
        ``{"results", "table", "out", "train_wall_s", "eval_wall_s"}``.
    """
    seeds, ppo_steps = check_confrontation_args(seeds, steps, ppo_prefs, eval_prefs, episodes, workers, ppo_budget)
    jobs = confrontation_jobs(seeds, steps, ppo_prefs, ppo_steps, eval_prefs, device, overrides)
    out = Path(out)
    with FolderLock(out, what="reproduction folder"):
        t0 = time.perf_counter()
        records = run_all_or_raise(jobs, out, backend, workers, address, progress)
        train_wall = time.perf_counter() - t0
        t1 = time.perf_counter()
        per_seed, games = evaluate_confrontation(out, seeds, ppo_prefs, eval_prefs, episodes,
                                                 overrides.get("max_episode_steps"))
        eval_wall = time.perf_counter() - t1
        plot_fig5({m: per_seed[m][0]["points"] for m in METHODS}, out / "fig5_front.png",
                  {r: per_seed[r][0]["points"][0] for r in REFERENCES})
        plot_fig6(games, np.asarray(FIG6_PREFS), conf.RobotConfrontationEnv().half, out / "fig6_trajectories.png")
        results = confrontation_results(out, per_seed, seeds)
        results["reference_front_hv"] = reference_front_hv(
            per_seed, conf.reference_point(1.0, max(overrides.get("max_episode_steps") or 0, conf.DEFAULT_HORIZON)))
        table = scores_table(results, len(seeds), episodes, eval_prefs) + "\n\n" + confrontation_table(
            results, len(seeds), steps, ppo_steps, ppo_prefs, eval_prefs)
        table += f"\n\nHV of the four reference policies' front: {results['reference_front_hv']:.1f}"
        (out / "table.md").write_text(table + "\n")
        ref = conf.reference_point(1.0, max(overrides.get("max_episode_steps") or 0, conf.DEFAULT_HORIZON))
        (out / "results.json").write_text(json.dumps({
            "results": results, "seeds": seeds, "steps": steps, "ppo_steps": ppo_steps, "ppo_budget": ppo_budget,
            "ppo_prefs": ppo_prefs, "eval_prefs": eval_prefs, "episodes": episodes, "ref_point": ref.tolist(),
            "train_wall_s": train_wall, "eval_wall_s": eval_wall, "overrides": overrides}, indent=2))
    return {"results": results, "table": table, "out": out, "train_wall_s": train_wall, "eval_wall_s": eval_wall,
            "records": records}
