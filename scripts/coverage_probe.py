"""Probes of the early time-outs on Deep-Sea-Treasure (treasure-heavy preferences loop at 2k-9k steps, see
docs/results/early-loops). Each probe trains mope with the defaults plus JSON overrides and optional patches,
evaluating every 1,000 steps, and prints one JSON line.

    python scripts/coverage_probe.py NAME '{"config_key": value}' [tight-bounds] [double-components] [eval-target]
        [return-bound] [loop-target]
        [--greedy-share P] [--ez MU] [--env ID] [--seed S] [--steps N]

``tight-bounds`` (not in mope): clamps targets to the map's own return bounds (first objective within
[min(0, seabed), largest treasure]) instead of the reward-space bounds (largest treasure / (1 - gamma)).
``--greedy-share P`` (not in mope): each episode, with probability P, acts with epsilon_end (greedy episodes
run the greedy policy's loops, so their real returns reach the targets).
``--ez MU`` (not in mope): temporally extended epsilon-greedy (Dabney et al. 2021): an exploring step repeats
one random action for n ~ Zeta(MU) steps.
``eval-target`` (not in mope): evaluations use the greedy policy of the target network (Polyak-averaged weights,
tau = target_tau); the behaviour still acts with the online network.
``return-bound`` (not in mope): every target row is raised to the episode's observed return where that is better
for the row's preference (optimality tightening / self-imitation; valid in deterministic environments).
``loop-target`` (not in mope; n_step 1 only): a self-loop's target (s' = s) is its Bellman fixed point in closed
form, max(loop for ever, leave by the best other action), not a bootstrap from its own value.
``double-components`` (not in mope): the online network picks the (action, component) pair and the target
network's vector of that same pair is the value (double Q over the convex head's components too).
"""
import json
import sys
import time

import numpy as np
import torch

from mope.agent import targets
from mope.agent.agent import MoPE
from mope.agent.networks import ConvexQNetwork
from mope.config import Config
from mope.envs import make_env


def double_components(v_online, v_target, prefs):
    x, a, c, m = v_online.shape
    n = prefs.shape[1]
    flat = torch.einsum("xim,xacm->xiac", prefs, v_online).reshape(x, n, a * c).argmax(dim=2)
    rows = torch.arange(x, device=prefs.device).unsqueeze(1)
    return v_target[rows, flat // c, flat % c], flat // c


class GreedyEpisodes(MoPE):
    """A share of the episodes acts with epsilon_end instead of the scheduled epsilon (drawn per episode)."""

    share = 0.0

    def _start_episode(self):
        super()._start_episode()
        if not hasattr(self, "_ep_rng"):
            self._ep_rng = np.random.default_rng(10_000 + self.config.seed)
        self._greedy_episode = bool(self._ep_rng.random() < self.share)

    @property
    def epsilon(self):
        if getattr(self, "_greedy_episode", False):
            return self.config.epsilon_end
        return super().epsilon


class EzGreedy(GreedyEpisodes):
    """Temporally extended epsilon-greedy (Dabney et al. 2021): an exploring step starts a random action that is
    repeated for n ~ Zeta(mu) steps (the episode's end cuts it)."""

    mu = 2.0

    def _start_episode(self):
        super()._start_episode()
        self._repeat, self._repeat_action = 0, 0

    def act(self, obs, pref, greedy=True):
        if greedy or np.asarray(obs).shape != tuple(self.obs_shape):
            return super().act(obs, pref, greedy)
        if self._repeat == 0 and self.rng.random() < self.epsilon:
            self._repeat, self._repeat_action = int(self.rng.zipf(self.mu)), int(self.rng.integers(self.n_actions))
        if self._repeat > 0:
            self._repeat -= 1
            self._explored = np.array([True])
            return self._repeat_action
        return super().act(obs, pref, greedy=True)


class ReturnBound(MoPE):
    """Every target row is raised to the episode's observed return where that return is better for the row's
    preference: ``y <- G if w^T G > w^T y`` (optimality tightening, He et al. 2017; self-imitation, Oh et al. 2018).
    In a deterministic environment the return an episode obtained from (s, a) is achievable, so
    ``w^T Q*(s, a, w) >= w^T G`` for every w. Only episodes that terminated carry a return (a time-out's partial
    return misses the time costs to come)."""

    def _init_bound(self):
        if not hasattr(self, "_full"):
            n = self.buffer.capacity
            self._full = np.zeros((n, self.m), dtype=np.float32)
            self._full_ok = np.zeros(n, dtype=bool)
            self._slots = []

    def collect_step(self):
        self._init_bound()
        slot = self.buffer.pos
        self._full_ok[slot] = False
        super().collect_step()
        self._slots.append(slot)
        if self._obs is not None and len(self._episode_actions) == 0:  # an episode just ended (a new one started)
            slots = np.asarray(self._slots)
            self._slots = []
            if self.buffer.terminated[slots[-1]]:
                r = self.buffer.rewards[slots] * self.reward_scale  # the learner's factor (reward_norm too)
                g = np.zeros(self.m, dtype=np.float32)
                for t in range(len(slots) - 1, -1, -1):
                    g = r[t] + self.config.gamma * g
                    self._full[slots[t]] = g
                self._full_ok[slots] = True

    def _envelope_target(self, batch, w, acting):
        y = super()._envelope_target(batch, w, acting)
        ok = self._full_ok[batch.indices]
        if not ok.any():
            return y
        g = self._tensor(self._full[batch.indices])[:, None, :].expand_as(y)
        better = ((w * g).sum(-1) > (w * y).sum(-1)) & self._tensor(ok, torch.bool)[:, None]
        return torch.where(better[..., None], g, y)


_one_step = targets.one_step_target


@torch.no_grad()
def loop_one_step(q_net, target_net, buf, idx, w, acting, cfg):
    """Eq. 4's one-step target, except for self-loops (s' = s, not terminal): there the Bellman fixed point of the
    taken action a is solved in closed form, ``max_w(r / (1 - gamma), r + gamma V_{-a}(s))`` (loop for ever, or
    leave by the best other action), so a bump's target never bootstraps from its own value."""
    y = _one_step(q_net, target_net, buf, idx, w, acting, cfg)
    b = len(idx)
    selfloop = (buf.obs[idx].reshape(b, -1) == buf.next_obs[idx].reshape(b, -1)).all(1) & (buf.terminated[idx] == 0)
    if not selfloop.any():
        return y
    dev = w.device
    sl = torch.as_tensor(selfloop, device=dev)
    s_next = torch.as_tensor(buf.next_obs[idx][selfloop], device=dev, dtype=torch.float32)
    ws = w[sl]
    q_sel, q_tgt = q_net.forward_prefs(s_next, ws), target_net.forward_prefs(s_next, ws)  # (k, N, A, m)
    a = torch.as_tensor(buf.actions[idx][selfloop], device=dev)
    scores = torch.einsum("knm,knam->kna", ws, q_sel)
    scores.scatter_(2, a.view(-1, 1, 1).expand(-1, scores.shape[1], 1), float("-inf"))
    best = scores.argmax(2)
    v_other = q_tgt.gather(2, best[..., None, None].expand(-1, -1, 1, q_tgt.shape[3])).squeeze(2)
    r = torch.as_tensor(buf.rewards[idx][selfloop], device=dev, dtype=torch.float32)[:, None] * cfg.reward_scale
    y_other = r + cfg.gamma * v_other
    y_loop = (r / (1.0 - cfg.gamma)).expand_as(y_other)
    loop = (ws * y_loop).sum(-1) > (ws * y_other).sum(-1)
    y[sl] = torch.where(loop[..., None], y_loop, y_other)
    return y


def option(flag: str, default: str) -> str:
    return sys.argv[sys.argv.index(flag) + 1] if flag in sys.argv else default


name, overrides = sys.argv[1], json.loads(sys.argv[2])
if "double-components" in sys.argv[3:]:
    ConvexQNetwork.double_q_values = staticmethod(double_components)
    # the one-step path reads the convex head through forward_prefs; route it through the n-step code (n = 1)
    targets.one_step_target = lambda q, t, buf, idx, w, acting, c, scale: targets.n_step_target(
        q, t, buf, idx, w, acting, c, 1, scale=scale)
env_id, seed, steps = option("--env", "deep-sea-treasure-v0"), int(option("--seed", "0")), \
    int(option("--steps", "10000"))
cfg = Config.from_dict({"env_id": env_id, "algo": "mope", "seed": seed, "total_steps": 20000, **overrides})
GreedyEpisodes.share = float(option("--greedy-share", "0"))
EzGreedy.mu = float(option("--ez", "0"))
agent_cls = EzGreedy if EzGreedy.mu else GreedyEpisodes if GreedyEpisodes.share else MoPE
if "return-bound" in sys.argv[3:]:
    agent_cls = type("ReturnBoundAgent", (ReturnBound, agent_cls), {})
agent = agent_cls(env_id, cfg)
if "loop-target" in sys.argv[3:]:
    assert overrides.get("n_step", 1) == 1, "loop-target patches the one-step target only"
    targets.one_step_target = loop_one_step
if "eval-target" in sys.argv[3:]:  # evaluate the greedy policy of the Polyak-averaged (target) network
    import mope.evaluation.evaluator as _ev

    _evaluate = _ev.Evaluator.evaluate

    def _eval_target(self, ag, *a, **k):
        ag.q_net, ag.target_net = ag.target_net, ag.q_net
        try:
            return _evaluate(self, ag, *a, **k)
        finally:
            ag.q_net, ag.target_net = ag.target_net, ag.q_net

    _ev.Evaluator.evaluate = _eval_target
if "tight-bounds" in sys.argv[3:]:
    base = agent.env.unwrapped
    sea = np.asarray(base.sea_map, dtype=np.float64)
    low = min(0.0, float(getattr(base, "seabed_reward", 0.0)))
    agent._q_high_t[0] = float(sea.max()) * cfg.reward_scale
    agent._q_low_t[0] = low * cfg.reward_scale
t = time.time()
recs = agent.train(steps, eval_env=make_env(env_id), eval_every=1000)
tr = np.round(agent.buffer.rewards[: agent.global_step, 0], 1)
firsts = {float(v): int(np.argmax(tr == v)) + 1 for v in np.unique(tr[tr > 0])}
first = next((int(r["step"]) for r in recs if r["cr"] >= 1 - 1e-9), None)
out = {"probe": name, "env": env_id, "seed": seed, "patches": sys.argv[3:], "overrides": overrides,
       "s": round(time.time() - t), "first_cr1": first,
       "last_treasure_step": max(firsts.values()) if firsts else None, "treasures": len(firsts),
       "cr": [round(float(r["cr"]), 2) for r in recs], "timeouts": [round(float(r["timeout_share"]), 2) for r in recs],
       "path_error": [round(float(r["path_error"]), 3) for r in recs],
       "over": [round(float(r["overestimation"]), 2) for r in recs]}
print(json.dumps(out), flush=True)
