"""Single-seed probes of the divergence on deep-sea-treasure-mirrored-v0 (seed 2 diverges by 8k steps with the
defaults: overestimate 24.6 at 8k, 121.9 at 9k). Each probe changes one thing; 9k steps of a 20k-step run.

    python scripts/mirrored_probe.py NAME '{"config_key": value}' [double-components|act-target|--beta B|--lam L]
        [--env ID] [--seed S] [--steps N]

``near-returns``, ``near-same`` (not in mope): see :class:`NearReturns`, :class:`NearSameReturns`.
``--eval-every K`` evaluates every K steps.
``act-target`` (not in mope) acts and evaluates with the target network, the Polyak average of the online weights.
``double-components`` (not in mope): with the convex head, the target network picks its own best component
(a max over C noisy vectors that double Q does not cover); this variant selects the component with the online
network and reads it from the target network.
"""
import json
import sys
import time

import numpy as np
import torch

from mope.agent import losses
from mope.agent.agent import MoPE
from mope.config import Config
from mope.envs import make_env


def gather_components(v: torch.Tensor, best: torch.Tensor) -> torch.Tensor:
    b, a, c, m = v.shape
    k = best.shape[1]
    return v.unsqueeze(1).expand(b, k, a, c, m).gather(3, best[..., None, None].expand(b, k, a, 1, m)).squeeze(3)


class DoubleComponents(MoPE):
    def _envelope_target(self, batch, w, acting):
        c = self.config
        next_obs = self._tensor(batch.next_obs)
        env_prefs, envelope = losses.envelope_set(c.envelope_prefs, w, acting)
        v_on = self.q_net.components(next_obs)[:, 0]  # one head (n_critics = 1)
        v_tg = self.target_net.components(next_obs)[:, 0]
        best = torch.einsum("bkm,bacm->bkac", env_prefs, v_on).argmax(dim=3)
        y = losses.envelope_target(gather_components(v_tg, best), self._tensor(batch.rewards),
                                   self._tensor(batch.terminated), w, c.gamma,
                                   q_select=gather_components(v_on, best), envelope=envelope)
        return losses.clip_targets(y, self._q_low_t, self._q_high_t) if c.clip_targets else y


class ActTarget(MoPE):
    """Acts and evaluates with the target network (the Polyak average of the online weights)."""

    @torch.inference_mode()
    def q_values(self, obs, prefs):
        return self.target_net(self._tensor(obs), self._tensor(prefs)).cpu().numpy()

    @torch.inference_mode()
    def greedy_actions(self, obs, prefs):
        w = self._tensor(prefs)
        return torch.einsum("bm,bam->ba", w, self.target_net(self._tensor(obs), w)).argmax(dim=1).cpu().numpy()


class CountPessimism(MoPE):
    """Lowers the next state's value in every target by ``beta / sqrt(N(s'))`` on every objective (N: visits of s'
    so far), so the bias of the max cannot compound in rarely visited states and cycles (not in mope)."""

    beta = 1.0

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._visits: dict[tuple, int] = {}
        add = self.buffer.add

        def counted_add(obs, pref, action, reward, next_obs, terminated):
            key = tuple(np.asarray(next_obs).reshape(-1).tolist())
            self._visits[key] = self._visits.get(key, 0) + 1
            add(obs, pref, action, reward, next_obs, terminated)

        self.buffer.add = counted_add

    def _envelope_target(self, batch, w, acting):
        y = super()._envelope_target(batch, w, acting)
        n = np.array([self._visits.get(tuple(o.reshape(-1).tolist()), 1) for o in batch.next_obs], dtype=np.float32)
        live = 1.0 - self._tensor(batch.terminated).float()
        pen = self.config.gamma * self.beta * live / torch.sqrt(self._tensor(n))
        return y - pen.view(-1, *([1] * (y.dim() - 1)))


class GreedyReturns(MoPE):
    """Mixes, into the acting preference's row of each target, the return the behaviour actually got from s'
    (Watkins-style: the episode's rewards while its actions were greedy, then the target network's value where a
    random action cut the trace, or where the time limit ended it). Only returns stored within the last ``window``
    steps are used (greedy tails of old policies are stale). Not in mope.

    y_row0 = (1 - lam) * y_row0 + lam * G
    """

    lam, window = 0.5, 2000

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        cap = self.buffer.capacity
        self._G = np.zeros((cap, self.m), dtype=np.float32)
        self._G_step = np.full(cap, -10**9, dtype=np.int64)
        self._ep: list[tuple[int, np.ndarray, bool, np.ndarray]] = []

    def collect_step(self):
        if self._obs is None:
            self._start_episode()
        obs, pref = self._obs, self._pref
        slot = self.buffer.pos
        action = self.act(obs, pref, greedy=False)
        greedy = int(self.greedy_actions(np.asarray(obs)[None], np.asarray(pref)[None])[0]) == action
        next_obs, reward, terminated, truncated, _ = self.env.step(action)
        self.buffer.add(obs, pref, action, np.asarray(reward, dtype=np.float32), next_obs, terminated)
        self._ep.append((slot, np.asarray(reward, dtype=np.float32), greedy, np.asarray(next_obs)))
        self._obs = next_obs
        self._episode_actions.append(action)
        self.global_step += 1
        if terminated or truncated:
            self._close_episode(terminated)
            self.episodes += 1
            self._start_episode()

    @torch.no_grad()
    def _close_episode(self, terminated):
        w = self._tensor(self._pref)[None]
        nxt = self._tensor(np.stack([e[3] for e in self._ep]))
        q = self.target_net(nxt, w.expand(len(nxt), -1))  # (T, A, m)
        v = q[torch.arange(len(nxt)), torch.einsum("m,tam->ta", w[0], q).argmax(1)].cpu().numpy()  # V(s_{t+1})
        cur = np.zeros(self.m, dtype=np.float32) if terminated else v[-1]
        for t in range(len(self._ep) - 1, -1, -1):
            slot, r, _, _ = self._ep[t]
            g = r + self.config.gamma * cur
            self._G[slot], self._G_step[slot] = g, self.global_step
            # the value at s_t for the step before: the return if a_t was greedy, else the target's value at s_t
            cur = g if self._ep[t][2] else (v[t - 1] if t > 0 else g)
        self._ep = []

    def _envelope_target(self, batch, w, acting):
        y = super()._envelope_target(batch, w, acting)
        fresh = (self.global_step - self._G_step[batch.indices]) < self.window
        if fresh.any():
            idx = torch.as_tensor(np.flatnonzero(fresh))
            g = self._tensor(self._G[batch.indices[fresh]])
            y[idx, 0] = (1 - self.lam) * y[idx, 0] + self.lam * g
        return y


def similar_rows(c: Config) -> int:
    """EE's similar-preference rows after row 0 (the agent's relabel: N_omega - 1 - the broad rows)."""
    return c.n_omega - 1 - min(c.n_omega - 1, round(c.n_omega * c.relabel_broad))


class NearReturns(MoPE):
    """``return_mix`` applied to the acting preference's similar-preference rows as well (EE's sigma_omega
    neighbours, rows 1 .. N_omega - 1 - broad), not only to its own row 0: a neighbour that follows the same greedy
    policy has the same return (for one that does not, G is only a lower bound, in a deterministic environment), so
    the episode's return corrects a loop 16 rows at a time instead of one. Not in mope."""

    def _envelope_target(self, batch, w, acting):
        y = super()._envelope_target(batch, w, acting)  # row 0 already mixed (return_mix)
        c = self.config
        n_near = similar_rows(c)
        fresh = self.global_step - self.buffer.return_steps[batch.indices] < c.return_window
        if c.return_mix and n_near and fresh.any():
            g = self._tensor(self.buffer.returns[batch.indices])[:, None, :]
            near = y[:, 1:1 + n_near]
            mixed = (1.0 - c.return_mix) * near + c.return_mix * g
            y = y.clone()
            y[:, 1:1 + n_near] = torch.where(self._tensor(fresh, torch.bool)[:, None, None], mixed, near)
        return y


class NearSameReturns(MoPE):
    """Like :class:`NearReturns`, but a neighbour's row gets the return only where the online network's greedy
    (action, component) at s' under the neighbour is the acting preference's: the neighbour is predicted to
    continue as the episode did, so G is its return, not a lower bound across a change of policy (the bias that
    cost Deep-Sea-Treasure precision, docs/results/return-mix-near). Not in mope."""

    @torch.no_grad()
    def _envelope_target(self, batch, w, acting):
        y = super()._envelope_target(batch, w, acting)  # row 0 already mixed (return_mix)
        c = self.config
        n_near = similar_rows(c)
        fresh = self.global_step - self.buffer.return_steps[batch.indices] < c.return_window
        if not (c.return_mix and n_near and fresh.any()):
            return y
        comps = self.q_net.components(self._tensor(batch.next_obs))[:, 0]  # (B, A, C, m), one head
        pick = torch.einsum("bkm,bacm->bkac", w, comps).flatten(2).argmax(2)  # (B, N) greedy (action, component)
        same = pick == pick[:, :1]
        mask = torch.zeros_like(same)
        mask[:, 1:1 + n_near] = same[:, 1:1 + n_near] & self._tensor(fresh, torch.bool)[:, None]
        g = self._tensor(self.buffer.returns[batch.indices])[:, None, :]
        return torch.where(mask[..., None], (1.0 - c.return_mix) * y + c.return_mix * g, y)


def option(flag: str, default: str) -> str:
    return sys.argv[sys.argv.index(flag) + 1] if flag in sys.argv else default


name, overrides = sys.argv[1], json.loads(sys.argv[2])
CountPessimism.beta = float(option("--beta", "1"))
GreedyReturns.lam = float(option("--lam", "0.5"))
GreedyReturns.window = int(option("--window", "2000"))
variants = {"--lam": GreedyReturns, "--beta": CountPessimism, "double-components": DoubleComponents,
            "act-target": ActTarget, "near-returns": NearReturns,
            "near-same": NearSameReturns}
cls = next((v for flag, v in variants.items() if flag in sys.argv[3:]), MoPE)
env_id, seed, steps = option("--env", "deep-sea-treasure-mirrored-v0"), int(option("--seed", "2")), \
    int(option("--steps", "9000"))
# return_mix 0, n_step 1, epsilon over 10k: the probes ran on the defaults before these became defaults (the
# greedyret probes mix in their own way)
cfg = Config.from_dict({"env_id": env_id, "algo": "mope", "seed": seed, "total_steps": 20000, "return_mix": 0.0,
                        "n_step": 1, "epsilon_decay_steps": 10_000, **overrides})
agent = cls(env_id, cfg)
t = time.time()
every = int(option("--eval-every", "3000" if steps < 20000 else "5000"))
recs = agent.train(steps, eval_env=make_env(env_id), eval_every=every)
out = {"probe": name, "env": env_id, "seed": seed, "class": cls.__name__, "overrides": overrides,
       "s": round(time.time() - t),
       "evals": [{k: round(float(r[k]), 3) for k in ("step", "cr", "timeout_share", "path_error", "overestimation")}
                 for r in recs]}
print(json.dumps(out), flush=True)
