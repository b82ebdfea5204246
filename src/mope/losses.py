"""The equations of the paper, one small function each, as batched tensor operations.

Shapes: ``B`` transitions, ``N`` relabeled preferences per transition, ``K`` envelope preferences per
transition, ``A`` actions, ``m`` objectives. Nothing here loops over preferences or samples in Python.
"""

from __future__ import annotations

import torch

from mope.networks import QNetwork


def envelope_target(target_net: QNetwork, next_feats: torch.Tensor, rewards: torch.Tensor,
                    terminated: torch.Tensor, row_prefs: torch.Tensor, envelope_prefs: torch.Tensor,
                    gamma: float, select_net: QNetwork | None = None, envelope: bool = True) -> torch.Tensor:
    """Envelope target y of eq. 4 (Yang et al. 2019).

    For row ``(b, i)`` with preference ``w = row_prefs[b, i]``::

        (a*, w'*) = argmax_{a, w' in envelope_prefs[b]}  w^T Q_target(s'_b, a, w')
        y         = r_b + gamma * (1 - terminated_b) * Q_target(s'_b, a*, w'*)

    ``Q_target(s'_b, ., w')`` is computed once per (transition, envelope preference): a single forward pass
    over ``B * K`` rows. Each of the ``N`` row preferences then only rescalarises those values, so the cost is
    never ``B * N * K`` network rows.

    With ``select_net`` (double Q-learning, van Hasselt et al. 2016), the argmax is taken on ``select_net`` (the
    online network) and the value read from ``target_net``; this curbs the overestimation that a max over
    ``K * A`` noisy estimates otherwise feeds back through looping states.

    Args:
        target_net: The target Q-network.
        next_feats: ``(B, d)`` encoded next observations.
        rewards: ``(B, m)`` vector rewards.
        terminated: ``(B,)`` 1.0 where s' is terminal (truncation is not termination).
        row_prefs: ``(B, N, m)`` preferences of the training rows.
        envelope_prefs: ``(B, K, m)`` preferences the max runs over.
        gamma: Discount factor.
        select_net: Optional network for the argmax (double Q-learning).
        envelope: If False (an ablation, morl-baselines' ``envelope=False``), row ``(b, i)`` maxes over actions
            at its own preference only; ``envelope_prefs`` must then be ``row_prefs`` (``K = N``).

    Returns:
        ``(B, N, m)`` targets.
    """
    b, k, m = envelope_prefs.shape
    feats = next_feats.unsqueeze(1).expand(b, k, next_feats.shape[1]).reshape(b * k, -1)
    flat_prefs = envelope_prefs.reshape(b * k, m)
    q_next = target_net.forward_features(feats, flat_prefs).view(b, k, -1, m)  # (B, K, A, m)
    q_sel = q_next if select_net is None else select_net.forward_features(feats, flat_prefs).view(b, k, -1, m)
    a = q_next.shape[2]
    if not envelope:
        best_a = torch.einsum("bim,biam->bia", row_prefs, q_sel).argmax(dim=2)  # (B, N)
        q_star = torch.gather(q_next, 2, best_a.view(b, k, 1, 1).expand(b, k, 1, m)).squeeze(2)
        return rewards.unsqueeze(1) + gamma * (1.0 - terminated).view(b, 1, 1) * q_star
    scal = torch.einsum("bim,bkam->bika", row_prefs, q_sel).reshape(b, row_prefs.shape[1], k * a)
    best = scal.argmax(dim=2)  # (B, N) index into (K*A)
    q_flat = q_next.reshape(b, k * a, m)
    q_star = torch.gather(q_flat, 1, best.unsqueeze(-1).expand(-1, -1, m))  # (B, N, m)
    return rewards.unsqueeze(1) + gamma * (1.0 - terminated).view(b, 1, 1) * q_star


def eql_loss(q: torch.Tensor, y: torch.Tensor, prefs: torch.Tensor, lb_weight: float = 1.0
             ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per-transition EQL loss of eq. 4: L = L^A + L^B, each averaged over the transition's N preferences.

    ``L^A = ||y - Q(s, a, w)||_2^2`` (vector regression) and ``L^B = |w^T y - w^T Q(s, a, w)|`` (the auxiliary
    scalarised loss).

    Args:
        q: ``(B, N, m)`` Q(s, a, w) of the taken action.
        y: ``(B, N, m)`` targets (no gradient).
        prefs: ``(B, N, m)`` row preferences.
        lb_weight: Weight of L^B (1 in the paper).

    Returns:
        ``(loss, l_a, l_b)``, each of shape ``(B,)``.
    """
    diff = y - q
    l_a = diff.pow(2).sum(-1).mean(1)
    l_b = (prefs * diff).sum(-1).abs().mean(1)
    return l_a + lb_weight * l_b, l_a, l_b


def preference_interval_td(q: torch.Tensor, y: torch.Tensor, prefs: torch.Tensor) -> torch.Tensor:
    """Preference-interval TD error of eq. 5: ``delta = 1/N sum_i (w_i^T y - w_i^T Q(s, a, w_i))``.

    The mean is taken with signs, as eq. 5 is written; the priority uses its magnitude (see
    :func:`priority`).

    Returns:
        ``(B,)`` signed mean scalarised TD errors.
    """
    return (prefs * (y - q)).sum(-1).mean(1)


def mutual_information_bonus(log_q: torch.Tensor, log_p: torch.Tensor) -> torch.Tensor:
    """The per-sample term of the variational bound of eq. 6: ``log q_phi(w | s) - log p(w)``."""
    return log_q - log_p


def priority(td: torch.Tensor, mi_bonus: torch.Tensor | None, alpha: float, eps: float) -> torch.Tensor:
    """Replay priority of eq. 7, made a valid positive PER priority.

    ``q(s_i) = |delta| + alpha * (log q_phi(w|s) - log p(w))``. eq. 7 can be negative (a state whose preference
    the discriminator finds unlikely); it is clipped at 0, then ``eps`` is added so every transition keeps a
    chance to be replayed. Without a discriminator (EQL, PE) the priority is ``|delta| + eps``.

    Returns:
        ``(B,)`` priorities before the PER exponent.
    """
    p = td.abs()
    if mi_bonus is not None:
        p = p + alpha * mi_bonus
    return p.clamp_min(0.0) + eps
