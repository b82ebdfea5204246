"""The kinds of job that :func:`mope.experiments.jobs.run_jobs` runs: ``(payload, folder) -> final metrics``.

``train`` is one mope run from a config (:func:`mope.experiments.runs.train_run`; it resumes from
``checkpoints/resume.pt``), ``ppo`` one PPO policy of the outer-loop baseline (:mod:`mope.paper.ppo`), and
``envelope`` one run of morl-baselines' Envelope (:mod:`mope.paper.envelope`). Each resumes or skips what is
already in its folder. The executor (:mod:`mope.experiments.jobs`) knows nothing of what a job does.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mope.errors import ConfigError


def _train_job(payload: dict[str, Any], out: Path) -> dict[str, Any]:
    """A mope run (``payload`` is a config dict): resumed from resume.pt, started over if it has none yet."""
    from mope.config import Config
    from mope.experiments.runs import train_run

    train_run(Config.from_dict(payload), out, progress=False, overwrite=True, resume=True)
    return json.loads((out / "summary.json").read_text()).get("final", {})


def _ppo_job(payload: dict[str, Any], out: Path) -> dict[str, Any]:
    """One PPO policy on ``w^T r`` (:func:`mope.paper.ppo.train_ppo`), saved as ``policy.zip``."""
    import torch

    from mope.paper.ppo import train_ppo

    meta = {k: payload[k] for k in ("pref", "steps", "seed", "env_id")}
    out.mkdir(parents=True, exist_ok=True)
    if (out / "summary.json").is_file():
        saved = json.loads((out / "summary.json").read_text())
        if saved.get("meta") == meta:
            return saved.get("final", {})
        raise ConfigError(f"'{out}' holds a PPO policy trained with {saved.get('meta')}, not {meta}; use another --out")
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    model = train_ppo(payload["pref"], payload["steps"], payload["seed"], env_id=payload["env_id"],
                      device=payload.get("device", "cpu"))
    model.save(out / "policy.zip")
    final = {"wall_s": time.perf_counter() - t0}
    (out / "summary.json").write_text(json.dumps({"meta": meta, "final": final}) + "\n")  # marks the job done
    return final


def _envelope_job(payload: dict[str, Any], out: Path) -> dict[str, Any]:
    """morl-baselines' Envelope (:class:`mope.paper.envelope.EnvelopeRunner`), evaluated with mope's protocol every
    ``eval_every`` steps; writes ``peer.json``, ``metrics.csv`` and ``summary.json`` like a run folder (it cannot
    resume: an interrupted Envelope job starts over)."""
    from mope.config import Config
    from mope.envs import make_env
    from mope.evaluation.evaluator import Evaluator
    from mope.experiments.runs import METRIC_COLUMNS, CsvLog, write_summary
    from mope.paper.envelope import EnvelopeRunner

    out.mkdir(parents=True, exist_ok=True)
    (out / "peer.json").write_text(json.dumps({"method": "envelope", **payload}, indent=2) + "\n")
    cfg = Config(env_id=payload["env_id"], seed=payload["seed"], total_steps=payload["total_steps"],
                 eval_prefs=payload["eval_prefs"], max_episode_steps=payload.get("max_episode_steps"))
    runner = EnvelopeRunner(cfg.env_id, cfg.seed, payload.get("gamma", 0.99), payload.get("overrides"),
                            cfg.max_episode_steps)
    evaluator = Evaluator.from_config(make_env(cfg.env_id, cfg.max_episode_steps), cfg)
    rows, train_s = [], 0.0
    metrics = CsvLog(out / "metrics.csv", METRIC_COLUMNS, [])
    try:
        while runner.global_step < cfg.total_steps:
            t0 = time.perf_counter()
            runner.train(min(payload["eval_every"], cfg.total_steps - runner.global_step))
            train_s += time.perf_counter() - t0
            res, _ = evaluator.evaluate(runner.policy())
            rows.append({"step": runner.global_step, "wall_s": train_s, "train_s": train_s, **res})
            metrics.write(rows[-1])
    finally:
        metrics.close()
    write_summary(out, {"final": rows[-1], "wall_s": train_s, "s_per_1k_steps": 1000 * train_s / cfg.total_steps,
                        "train_s_per_1k_steps": 1000 * train_s / cfg.total_steps, "method": "envelope"})
    return rows[-1]


JOB_KINDS: dict[str, Callable[[dict[str, Any], Path], dict[str, Any]]] = {"train": _train_job, "ppo": _ppo_job,
                                                                           "envelope": _envelope_job}


__all__ = ["JOB_KINDS"]
