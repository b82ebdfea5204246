"""Where one update's time goes, step by step, inside a real training run (issue: fast training).

Usage::

    .venv/bin/python benchmarks/update_sections.py [--updates 400]

Trains ``make_agent("mope", "deep-sea-treasure-v0", seed=0)`` for 1,500 steps (one torch thread), then runs
``--updates`` updates whose steps are those of :meth:`mope.agent.agent.MoPE.update`, written out here with a
timer around each (sampling, relabelling, the envelope target, the loss forward, the discriminator's loss, the
gradient step, the priorities, the statistics, the Polyak step), and prints the mean milliseconds of each. Keep the
steps here in line with ``update()`` when it changes: the total is checked against timing ``update()`` itself.
Unlike cProfile (``benchmarks/profile_train.py``) it adds no overhead per Python call.
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict

import torch

from mope import make_agent
from mope.agent import losses
from mope.agent.agent import check_finite, flushed_denormals, margin_rows, update_statistics


def timed_update(agent, times: dict[str, float]) -> None:  # noqa: ANN001 - a MoPE agent
    """One update, as MoPE.update does it, adding each step's seconds to ``times``."""
    c, t = agent.config, time.perf_counter
    t0 = t()
    batch = agent.buffer.sample(c.batch_size, agent.rng, agent._per_beta(), round(c.batch_size * c.demo_batch_share))
    obs, actions = agent._tensor(batch.obs), agent._tensor(batch.actions, torch.int64)
    acting = agent._tensor(batch.prefs)
    t1 = t()
    w = agent._tensor(agent.relabel(batch.prefs))
    t2 = t()
    demo = agent._tensor(batch.indices < agent.buffer.reserved, torch.bool)
    y = agent._envelope_target(batch, w, acting, demo)
    t3 = t()
    rows = margin_rows(c, agent.buffer, batch.indices, actions, demo)
    feats = agent.q_net.encoder(obs)
    q, loss_rows, parts = agent._eql_loss(obs, actions, w, y, rows, feats)
    loss = (agent._tensor(batch.weights) * loss_rows).mean()
    check_finite(loss, q, y, agent.global_step)
    t4 = t()
    bonus, disc_loss = agent._discriminator_loss(obs, batch.prefs, feats)
    t5 = t()
    agent._gradient_step(loss, disc_loss)
    t6 = t()
    td = losses.preference_interval_td(q.detach(), y, w)
    agent._set_priorities(batch, losses.priority(td, bonus, c.mi_alpha, c.per_eps, c.per_alpha))
    t7 = t()
    agent.last_losses = update_statistics(loss, parts, td, q.detach(), w, bonus, disc_loss, c.reward_scale)
    t8 = t()
    agent._polyak()
    t9 = t()
    for name, a, b in [("sample", t0, t1), ("relabel", t1, t2), ("envelope target", t2, t3),
                       ("loss forward", t3, t4), ("discriminator loss", t4, t5),
                       ("backward + clip + Adam (both)", t5, t6), ("TD + priorities", t6, t7),
                       ("statistics", t7, t8), ("Polyak", t8, t9)]:
        times[name] += b - a


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--updates", type=int, default=400)
    args = parser.parse_args()
    torch.set_num_threads(1)
    agent = make_agent("mope", "deep-sea-treasure-v0", seed=0, eval_every=0, checkpoint_every=0, total_steps=100_000)
    agent.train(1500)
    times: dict[str, float] = defaultdict(float)
    with flushed_denormals():
        t0 = time.perf_counter()
        for _ in range(args.updates):
            timed_update(agent, times)
        total = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(args.updates):
        agent.update()
        agent._polyak()
    plain = time.perf_counter() - t0
    for name, sec in times.items():
        print(f"{name:32s} {sec / args.updates * 1e3:6.3f} ms")
    print(f"{'total (timed steps)':32s} {total / args.updates * 1e3:6.3f} ms per update")
    print(f"{'update() + Polyak, untimed':32s} {plain / args.updates * 1e3:6.3f} ms per update")


if __name__ == "__main__":
    main()
