"""The target y of eq. 4 for a sampled batch: one step, or n stored steps with each row's own Watkins cut.

The agent calls :func:`one_step_target` or :func:`n_step_target` (``Config.n_step``); both run the networks
once over the states they need and leave the arithmetic to :mod:`mope.agent.losses`.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from mope.agent import losses
from mope.agent.networks import ConvexQNetwork
from mope.agent.replay import ReplayBuffer
from mope.config import Config, one_pass_target


def _t(x: np.ndarray, device: torch.device, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    return torch.as_tensor(np.asarray(x), dtype=dtype, device=device)


@torch.no_grad()
def one_step_target(q_net: nn.Module, target_net: nn.Module, buffer: ReplayBuffer, idx: np.ndarray,
                    w: torch.Tensor, acting: torch.Tensor, cfg: Config, *, scale: float) -> torch.Tensor:
    """Eq. 4 for transitions ``idx``: one target-network pass over the B x K envelope rows (plus one online pass
    for double Q). ``(B, N, m)``, in the learner's units (rewards times ``scale``, the agent's
    :attr:`~mope.agent.base.BaseAgent.reward_scale`)."""
    dev = w.device
    next_obs = _t(buffer.next_obs[idx], dev)
    rewards = _t(buffer.rewards[idx], dev) * scale
    not_end = 1.0 - _t(buffer.terminated[idx], dev)[:, None, None]
    if _one_pass(q_net, cfg):  # the default: the convex head's double-Q values straight from its components
        feats = q_net.encoder(next_obs)  # the same parameter-free encoder in both networks: encoded once
        v_target = target_net.components(next_obs, feats)[:, 0]
        values, _ = ConvexQNetwork.double_q_values(q_net.components(next_obs, feats)[:, 0], v_target, w)
        if cfg.consistent_bellman:
            values = consistent_values(values, v_target, buffer, idx, w)
        return rewards.unsqueeze(1) + cfg.gamma * not_end * values
    env_prefs, envelope = losses.envelope_set(cfg.envelope_prefs, w, acting)
    q_next = target_net.forward_prefs(next_obs, env_prefs)
    q_select = q_net.forward_prefs(next_obs, env_prefs) if cfg.double_q else None
    return losses.envelope_target(q_next, rewards, _t(buffer.terminated[idx], dev), w, cfg.gamma,
                                  q_select=q_select, envelope=envelope)


@torch.no_grad()
def n_step_target(q_net: nn.Module, target_net: nn.Module, buffer: ReplayBuffer, idx: np.ndarray,
                  w: torch.Tensor, acting: torch.Tensor, cfg: Config, n: int,
                  uncut: torch.Tensor | None = None, *, scale: float) -> torch.Tensor:
    """Eq. 4's target over ``n`` stored steps, each row cut where its preference's greedy action differs from the
    stored one (:func:`mope.agent.losses.watkins_n_step_targets`). One pass of each network over the ``B x n`` next
    states gives the envelope value after every step and the rows' greedy actions. ``n = 1`` is
    :func:`one_step_target`. Transitions flagged in ``uncut`` (``(B,)``, demonstrations: DQfD's n-step return)
    are cut only at their episode's end. Rewards are times ``scale``, as in :func:`one_step_target`."""
    dev = w.device
    b, rows, m = w.shape
    slots, valid = buffer.sequences(idx, n)
    next_obs = _t(buffer.next_obs[slots.reshape(-1)], dev)
    not_end = 1.0 - _t(buffer.terminated[slots.reshape(-1)], dev)[:, None, None]
    values, greedy = values_after(q_net, target_net, next_obs, w, acting, cfg, n)
    values, greedy = values * not_end, greedy.view(b, n, rows)
    taken = _t(buffer.actions[slots], dev, torch.int64)  # (B, n)
    cont = torch.zeros(b, n, rows, dtype=torch.bool, device=dev)
    same = greedy[:, :-1] == taken[:, 1:, None]
    if uncut is not None:
        same = same | uncut[:, None, None]
    cont[:, 1:] = _t(valid[:, 1:], dev, torch.bool).unsqueeze(-1) & same
    rewards = _t(buffer.rewards[slots], dev) * scale
    return losses.watkins_n_step_targets(rewards, values.view(b, n, rows, m), cont, cfg.gamma)


def consistent_values(values: torch.Tensor, v_target: torch.Tensor, buffer: ReplayBuffer, idx: np.ndarray,
                      w: torch.Tensor) -> torch.Tensor:
    """The consistent Bellman operator (Bellemare et al. 2016, "Increasing the action gap", eq. 7): where a transition
    left the state as it was (``s' = s``), the value after it is the target network's ``Q(s, a, w)`` of the action
    taken, not the greedy action's. A self-loop's value then settles at ``r / (1 - gamma)``, the return of repeating
    it, instead of sinking from the state's best value by 1 % per bootstrap (not in the paper).

    ``values`` ``(B, N, m)`` (the double-Q values of :func:`one_step_target`), ``v_target`` ``(B, A, C, m)`` the
    target network's components at ``s'``; returns ``values`` with the self-transitions' rows replaced."""
    b = len(idx)
    stay = np.flatnonzero(np.all(buffer.obs[idx].reshape(b, -1) == buffer.next_obs[idx].reshape(b, -1), axis=1))
    if len(stay) == 0:
        return values
    rows = torch.as_tensor(stay, device=values.device)
    taken = v_target[rows, _t(buffer.actions[idx][stay], values.device, torch.int64)]  # (S, C, m)
    best = torch.einsum("scm,snm->scn", taken, w[rows]).argmax(dim=1)  # (S, N): w's component of that action
    out = values.clone()
    out[rows] = taken.gather(1, best.unsqueeze(-1).expand(-1, -1, taken.shape[-1]))
    return out


def _one_pass(q_net: nn.Module, cfg: Config) -> bool:
    """:func:`mope.config.one_pass_target`, for a network that is the convex head it describes."""
    return isinstance(q_net, ConvexQNetwork) and one_pass_target(cfg)


def values_after(q_net: nn.Module, target_net: nn.Module, next_obs: torch.Tensor, w: torch.Tensor,
                 acting: torch.Tensor, cfg: Config, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """For the ``B x n`` states after each stored step (rows of one transition consecutive): eq. 4's value
    ``(B*n, N, m)`` (no termination mask) and the rows' greedy actions ``(B*n, N)`` under the online network."""
    w_rep = w.repeat_interleave(n, dim=0)
    if _one_pass(q_net, cfg):  # the default: one pass of each net, no select
        states, inverse = torch.unique(next_obs, dim=0, return_inverse=True)  # consecutive steps share states
        feats = q_net.encoder(states)
        return ConvexQNetwork.double_q_values(q_net.components(states, feats)[inverse, 0],
                                              target_net.components(states, feats)[inverse, 0], w_rep)
    env_prefs, envelope = losses.envelope_set(cfg.envelope_prefs, w, acting)
    env_prefs = env_prefs.repeat_interleave(n, dim=0)
    q_next = target_net.forward_prefs(next_obs, env_prefs)
    q_online = q_net.forward_prefs(next_obs, env_prefs)
    zeros = torch.zeros(len(next_obs), w.shape[2], device=w.device)
    values = losses.envelope_target(q_next, zeros, zeros[:, 0], w_rep, 1.0,
                                    q_select=q_online if cfg.double_q else None, envelope=envelope)
    if cfg.envelope_prefs not in ("relabel", "own"):  # the envelope set is not the rows': Q at the rows' own
        q_online = q_net.forward_prefs(next_obs, w_rep)
    return values, torch.einsum("xim,xiam->xia", w_rep, q_online).argmax(dim=2)
