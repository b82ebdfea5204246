"""The Robot Confrontation Game's measures of a learned agent on common start states (issue: "the robot game,
learned"): outcome rates at fixed catch weights, and discounted expected utility against the reference policies'
upper envelope.

Every policy, learned or scripted, plays the same ``n_starts`` games (reset seeds ``10_000 + j``) with greedy
actions, all games batched (:class:`mope.envs.confrontation_batch.ConfrontationBatch`).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np

import mope.envs.confrontation as conf
from mope.envs.confrontation_batch import ConfrontationBatch, play_reference

#: Reset seeds of the common start states.
START_SEED = 10_000


def play_agent(agent: Any, w_catch: float, n_starts: int = 100, gamma: float = 0.99,
               max_steps: int = conf.DEFAULT_HORIZON) -> tuple[np.ndarray, list[str]]:
    """Greedy games of ``agent`` under the preference ``(w_catch, 1 - w_catch)`` from the common starts.

    Returns:
        ``(discounted, outcomes)``: ``(n, 2)`` discounted returns and each game's outcome.
    """
    seeds = [START_SEED + j for j in range(n_starts)]
    batch = ConfrontationBatch(conf.RobotConfrontationDiscreteEnv(), n_starts, seeds=seeds)
    obs = batch.reset()
    pref = np.tile([w_catch, 1.0 - w_catch], (n_starts, 1))
    disc = np.zeros((n_starts, 2))
    running, g = np.arange(n_starts), 1.0
    for _ in range(max_steps):
        actions = agent.greedy_actions(obs[running], pref[running])
        nxt, r, term = batch.step(running, actions)
        obs[running] = nxt
        disc[running] += g * r
        running, g = running[~term], g * gamma
        if not running.size:
            break
    return disc, batch.outcomes()


def outcome_rates(outcomes: Sequence[str]) -> dict[str, float]:
    """Shares of red wins, blue wins, red out of the arena and time-outs."""
    n = max(1, len(outcomes))
    return {"win": sum(o == "red_win" for o in outcomes) / n, "loss": sum(o == "blue_win" for o in outcomes) / n,
            "out": sum(o == "red_out" for o in outcomes) / n, "timeout": sum(o == "running" for o in outcomes) / n}


@functools.lru_cache(maxsize=4)
def reference_returns(n_starts: int = 100, gamma: float = 0.99) -> dict[str, tuple[np.ndarray, list[str]]]:
    """Every reference policy's discounted returns and outcomes on the common starts (computed once)."""
    seeds = [START_SEED + j for j in range(n_starts)]
    return {name: play_reference(name, seeds, gamma=gamma)[1:] for name in
            ("scripted pursuer", "leave the arena", "pure pursuit", "random")}


def probe(agent: Any, n_prefs: int = 11, n_starts: int = 100, gamma: float = 0.99) -> dict[str, Any]:
    """Outcome rates at ``n_prefs`` equally spaced catch weights (0, 0.1, ..., 1 by default), and the mean
    discounted utility over them beside the best reference policy's at each preference (the references' upper
    envelope).

    Returns:
        ``{"rates": {w_catch: {...}}, "eu": float, "eu_references": float, "eu_per_pref": [...], ...}``.
    """
    refs = {name: d.mean(axis=0) for name, (d, _) in reference_returns(n_starts, gamma).items()}
    rates, eu, eu_ref = {}, [], []
    for w in np.linspace(0.0, 1.0, n_prefs):
        pref = np.array([w, 1.0 - w])
        disc, outcomes = play_agent(agent, float(w), n_starts, gamma)
        rates[round(float(w), 6)] = outcome_rates(outcomes)
        eu.append(float(disc.mean(axis=0) @ pref))
        eu_ref.append(max(float(v @ pref) for v in refs.values()))
    return {"rates": rates, "eu": float(np.mean(eu)), "eu_references": float(np.mean(eu_ref)),
            "eu_per_pref": eu, "eu_ref_per_pref": eu_ref}


__all__ = ["START_SEED", "outcome_rates", "play_agent", "probe", "reference_returns"]
