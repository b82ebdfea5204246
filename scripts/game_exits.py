"""Why red leaves the arena: where blue is when red exits, and what the scripted pursuer would have done instead.

For a trained agent on the robot game, greedy play at w_catch = 0.4 and 0.5 from 300 start states (reset seeds
20,000-20,299, apart from the probes' common starts). For every game that ends out of the arena:

* the geometry at the exit: the distance to blue, and the angle between red's heading and the line to blue
  (180 degrees: blue straight behind red);
* a counterfactual: from red's and blue's states k steps before the exit, the scripted pursuer (and pure pursuit)
  plays the rest of the episode on the continuous game, and its discounted utility is set beside what the agent
  actually got from the same step.

Usage::

    .venv/bin/python scripts/game_exits.py runs/reproduce-confrontation-v3/mope-s1
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

import mope
import mope.envs.confrontation as conf
from mope.envs.confrontation_batch import REFERENCE_POLICIES, ConfrontationBatch

GAMMA = 0.99


def play(agent: mope.MoPE, w: float, n: int) -> tuple[list[str], list[np.ndarray], list[list[np.ndarray]]]:
    """Greedy games: outcomes, state histories and per-step rewards."""
    batch = ConfrontationBatch(conf.RobotConfrontationDiscreteEnv(), n, seeds=[20_000 + j for j in range(n)],
                               record=True)
    obs = batch.reset()
    pref = np.tile([w, 1 - w], (n, 1))
    running = np.arange(n)
    rewards: list[list[np.ndarray]] = [[] for _ in range(n)]
    for _ in range(conf.DEFAULT_HORIZON):
        nxt, r, term = batch.step(running, agent.greedy_actions(obs[running], pref[running]))
        obs[running] = nxt
        for k, i in enumerate(running):
            rewards[i].append(r[k])
        running = running[~term]
        if not running.size:
            break
    return batch.outcomes(), batch.histories(), rewards


def continue_with(policy: str, states: list[tuple[np.ndarray, np.ndarray, int]]) -> tuple[np.ndarray, list[str]]:
    """A reference policy plays on from each ``(red, blue, t)`` until the horizon: discounted returns, outcomes."""
    n = len(states)
    batch = ConfrontationBatch(conf.RobotConfrontationEnv(), n, seeds=list(range(n)))
    batch.reset()
    for i, (red, blue, _) in enumerate(states):
        batch.red[i], batch.blue[i] = red, blue
    steps_left = np.array([conf.DEFAULT_HORIZON - t for _, _, t in states])
    disc, g = np.zeros((n, 2)), np.ones(n)
    running, rng = np.arange(n), np.random.default_rng(0)
    for step in range(conf.DEFAULT_HORIZON):
        running = running[steps_left[running] > step]
        if not running.size:
            break
        _, r, term = batch.step(running, REFERENCE_POLICIES[policy](batch, running, rng))
        disc[running] += g[running, None] * r
        g[running] *= GAMMA
        running = running[~term]
    return disc, batch.outcomes()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, help="a run folder of the robot game (its checkpoints/final.pt is read)")
    parser.add_argument("--games", type=int, default=300)
    args = parser.parse_args()
    torch.set_num_threads(1)
    agent = mope.MoPE.load(args.run / "checkpoints" / "final.pt")
    for w in (0.4, 0.5):
        outcomes, hist, rewards = play(agent, w, args.games)
        exits = [i for i, o in enumerate(outcomes) if o == "red_out"]
        if not exits:
            print(f"w_catch {w}: no exits in {args.games} games")
            continue
        dist, behind = [], []
        for i in exits:
            red, blue = hist[i][-1]
            dist.append(float(np.hypot(*(blue[:2] - red[:2]))))
            los = np.arctan2(blue[1] - red[1], blue[0] - red[0])
            behind.append(float(np.degrees(abs(conf.wrap_angle(los - red[2])))))
        losses = sum(o == "blue_win" for o in outcomes)
        print(f"w_catch {w}: {len(exits)}/{args.games} exits, {losses} losses; at the exit blue is "
              f"{np.median(dist):.2f} m away (median), at {np.median(behind):.0f} deg from red's heading (median; "
              f"{np.mean(np.array(behind) > 120):.0%} of exits with blue behind red, > 120 deg)")
        pref = np.array([w, 1 - w])
        for k in (3, 8, 15):
            states, actual = [], []
            for i in exits:
                # red's and blue's states k steps before the exit, and the agent's discounted return from there
                t = max(0, len(rewards[i]) - k)
                states.append((hist[i][t][0].copy(), hist[i][t][1].copy(), t))
                actual.append(sum(GAMMA ** j * rewards[i][t + j] for j in range(len(rewards[i]) - t)))
            u_agent = np.array(actual) @ pref
            for policy in ("scripted pursuer", "pure pursuit"):
                disc, outs = continue_with(policy, states)
                u_alt = disc @ pref
                counts = {o: outs.count(o) for o in sorted(set(outs))}
                print(f"  {k:2d} steps before the exit: agent {u_agent.mean():+.2f}, {policy} {u_alt.mean():+.2f} "
                      f"(better in {np.mean(u_alt > u_agent):.0%} of exits; its outcomes {counts})")


if __name__ == "__main__":
    main()
