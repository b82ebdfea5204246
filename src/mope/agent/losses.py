"""The equations of the paper, one small function each, as pure batched tensor operations.

Shapes: ``B`` transitions, ``N`` relabeled preferences per transition, ``K`` envelope preferences per
transition, ``A`` actions, ``m`` objectives. Nothing here runs a network or loops over preferences or samples
in Python: the agent passes in the Q tensors it computed.
"""

from __future__ import annotations

import numpy as np
import torch


def objective_sum(x: torch.Tensor) -> torch.Tensor:
    """The sum over the last axis (the m objectives), as m slices added in order.

    The same sums as ``x.sum(-1)`` for m <= 2 and the same up to float rounding order beyond; on the CPU a
    reduction over a short innermost axis is about 10x slower than m - 1 elementwise additions
    (``benchmarks/bench_update.py``, issue: fast training).
    """
    total = x[..., 0]
    for k in range(1, x.shape[-1]):
        total = total + x[..., k]
    return total


def envelope_set(mode: str, row_prefs: torch.Tensor, acting_prefs: torch.Tensor) -> tuple[torch.Tensor, bool]:
    """The preferences the envelope max of eq. 4 runs over, ``(B, K, m)``, and whether it is an envelope at all.

    Args:
        mode: ``relabel`` (the transition's own relabeled set), ``batch`` (the acting preferences of the whole
            batch), ``both``, or ``own`` (no envelope: each row maxes over actions at its own preference).
        row_prefs: ``(B, N, m)`` preferences of the training rows.
        acting_prefs: ``(B, m)`` the preferences the transitions were collected under.

    Returns:
        ``(prefs, envelope)``; with ``own`` the set is ``row_prefs`` and ``envelope`` is False.
    """
    if mode in ("relabel", "own"):
        return row_prefs, mode != "own"
    batch = acting_prefs.unsqueeze(0).expand(acting_prefs.shape[0], -1, -1)
    return (batch if mode == "batch" else torch.cat([row_prefs, batch], dim=1)), True


def envelope_target(q_next: torch.Tensor, rewards: torch.Tensor, terminated: torch.Tensor, row_prefs: torch.Tensor,
                    gamma: float, q_select: torch.Tensor | None = None, envelope: bool = True) -> torch.Tensor:
    """Envelope target y of eq. 4 (Yang et al. 2019).

    For row ``(b, i)`` with preference ``w = row_prefs[b, i]``::

        (a*, k*) = argmax_{a, k}  w^T Q_select(s'_b, a, w'_k)
        y        = r_b + gamma * (1 - terminated_b) * Q_next(s'_b, a*, w'_k*)

    ``Q(s'_b, ., w'_k)`` is computed once per (transition, envelope preference) by the caller; each of the ``N``
    row preferences only rescalarises those values, so the cost is never ``B * N * K`` network rows.

    With ``q_select`` from the online network (double Q-learning, van Hasselt et al. 2016), the argmax is taken
    on it and the value read from ``q_next`` (the target network); this curbs the overestimation that a max over
    ``K * A`` noisy estimates otherwise feeds back through looping states.

    Args:
        q_next: ``(B, K, A, m)`` target-network Q-values at s' for the K envelope preferences.
        rewards: ``(B, m)`` vector rewards.
        terminated: ``(B,)`` 1.0 where s' is terminal (truncation is not termination).
        row_prefs: ``(B, N, m)`` preferences of the training rows.
        gamma: Discount factor.
        q_select: Optional ``(B, K, A, m)`` Q-values for the argmax (double Q-learning).
        envelope: If False (an ablation, morl-baselines' ``envelope=False``), row ``(b, i)`` maxes over actions
            at its own preference only; the envelope preferences must then be the row preferences (``K = N``).

    Returns:
        ``(B, N, m)`` targets.
    """
    q_sel = q_next if q_select is None else q_select
    b, k, a, m = q_next.shape
    if not envelope:
        best_a = torch.einsum("bim,biam->bia", row_prefs, q_sel).argmax(dim=2)  # (B, N)
        q_star = torch.gather(q_next, 2, best_a.view(b, k, 1, 1).expand(b, k, 1, m)).squeeze(2)
        return rewards.unsqueeze(1) + gamma * (1.0 - terminated).view(b, 1, 1) * q_star
    scal = torch.einsum("bim,bkam->bika", row_prefs, q_sel).reshape(b, row_prefs.shape[1], k * a)
    best = scal.argmax(dim=2)  # (B, N) index into (K*A)
    q_flat = q_next.reshape(b, k * a, m)
    q_star = torch.gather(q_flat, 1, best.unsqueeze(-1).expand(-1, -1, m))  # (B, N, m)
    return rewards.unsqueeze(1) + gamma * (1.0 - terminated).view(b, 1, 1) * q_star


def watkins_n_step_targets(rewards: torch.Tensor, values: torch.Tensor, cont: torch.Tensor, gamma: float
                           ) -> torch.Tensor:
    """n-step targets of eq. 4 for every row preference, each cut where its own greedy policy leaves the data.

    Row ``(b, i)`` follows the stored sequence ``t, t+1, ..., t+n-1`` of transition ``b`` while each next action
    is the greedy one of *its* preference ``w_i`` (Watkins' Q(lambda) cut, lambda = 1 up to ``n`` steps), so the
    target is that of the greedy policy of ``w_i`` and carries no off-policy bias::

        G_k = r_k + gamma * (G_{k+1} if cont[k+1] else V_k),      G_{n-1} = r_{n-1} + gamma * V_{n-1}

    where ``V_k`` is the envelope value of eq. 4 after step ``k`` (0 past a terminal step). With ``n = 1`` or no
    step continued it is the one-step target of eq. 4. A reward then reaches ``n`` states back in one update
    instead of one.

    Args:
        rewards: ``(B, n, m)`` rewards of the sequence's steps.
        values: ``(B, n, N, m)`` ``V(s_{t+k+1}, w_i)``, already zero after a terminal step.
        cont: ``(B, n, N)`` bool, whether step ``k`` continues row ``i``'s trace (``cont[:, 0]`` is not read).
        gamma: Discount factor.

    Returns:
        ``(B, N, m)`` targets.
    """
    n = rewards.shape[1]
    g = rewards[:, n - 1].unsqueeze(1) + gamma * values[:, n - 1]
    for k in range(n - 2, -1, -1):  # n is a handful of steps: the loop runs over time, never over samples
        after = torch.where(cont[:, k + 1].unsqueeze(-1), g, values[:, k])
        g = rewards[:, k].unsqueeze(1) + gamma * after
    return g


def greedy_tail_returns(rewards: np.ndarray, next_values: np.ndarray, greedy: np.ndarray, terminated: bool,
                        gamma: float) -> np.ndarray:
    """Return of one finished episode from each step, along its greedy actions (Watkins' trace cut).

    ``G_t = r_t + gamma * U_{t+1}``, where the value ``U_{t+1}`` of ``s_{t+1}`` is ``G_{t+1}`` if the action taken
    there was the greedy one, else ``V(s_{t+1})`` (the trace is cut where a random action was taken); after the
    last step it is 0 if ``terminated`` and ``V(s_T)`` if not. So ``G_t`` is the return of taking ``a_t`` and then
    following the greedy policy of the episode's own preference as far as the episode did: a target for
    ``Q(s_t, a_t, w_episode)`` that a looping greedy policy cannot inflate. (With ``return_timeout_bootstrap=False``
    the agent passes ``terminated=True`` for an episode the time limit ended as well: a loop that runs until the
    limit would otherwise end on its own stale value, ``gamma^k V(s_T)``.)

    Args:
        rewards: ``(T, m)`` the episode's rewards.
        next_values: ``(T, m)`` ``V(s_{t+1}) = Q(s_{t+1}, a*, w)`` under the episode's preference.
        greedy: ``(T,)`` whether each action was the greedy one.
        terminated: Whether nothing follows the last step (0 after it); False: ``V(s_T)`` follows.
        gamma: Discount factor.

    Returns:
        ``(T, m)`` returns.
    """
    n = len(rewards)
    out = np.empty_like(np.asarray(rewards, dtype=np.float32))
    after = np.zeros(out.shape[1], dtype=np.float32) if terminated else np.asarray(next_values[-1], np.float32)
    for t in range(n - 1, -1, -1):
        out[t] = rewards[t] + gamma * after
        after = out[t] if greedy[t] or t == 0 else np.asarray(next_values[t - 1], np.float32)
    return out


def mix_behaviour_returns(y: torch.Tensor, returns: torch.Tensor, fresh: torch.Tensor, weight: float) -> torch.Tensor:
    """Blend the first row of each transition's targets (its own preference) with its greedy-tail return.

    ``y[b, 0] <- (1 - weight) * y[b, 0] + weight * G_b`` where ``fresh[b]`` (G recent enough to be the current
    greedy policy's); other rows and stale transitions keep the envelope target (eq. 4).

    Args:
        y: ``(B, N, m)`` targets; row 0 is the transition's own preference.
        returns: ``(B, m)`` greedy-tail returns (:func:`greedy_tail_returns`).
        fresh: ``(B,)`` bool.
        weight: Blend weight in [0, 1].
    """
    mixed = y.clone()
    mixed[:, 0] = torch.where(fresh[:, None], (1.0 - weight) * y[:, 0] + weight * returns, y[:, 0])
    return mixed


def clip_targets(y: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """Clamp targets to the per-objective range of returns the reward bounds allow (not in the paper)."""
    return torch.maximum(torch.minimum(y, high), low)


def taken_action_q(q_all: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """``Q(s, a, w)`` of the taken action: ``(B, N, A, m)`` and ``(B,)`` actions -> ``(B, N, m)``."""
    b, n, _, m = q_all.shape
    return q_all.gather(2, actions.view(b, 1, 1, 1).expand(b, n, 1, m)).squeeze(2)


def eql_loss(q: torch.Tensor, y: torch.Tensor, prefs: torch.Tensor, lb_weight: float = 1.0, lb_loss: str = "squared"
             ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per-transition EQL loss of eq. 4: L = L^A + L^B, each averaged over the transition's N preferences.

    ``L^A = ||y - Q(s, a, w)||_2^2`` (vector regression) and the auxiliary scalarised loss
    ``L^B = (w^T y - w^T Q(s, a, w))^2`` (``lb_loss="squared"``, as Yang et al.'s and morl-baselines' code) or
    ``|w^T y - w^T Q(s, a, w)|`` (``"abs"``, as eq. 4 is written). With random transitions the targets of one
    (s, a, w) scatter over the outcomes: the squared form is minimised by their mean, the expected return Q is
    defined as, the absolute one by their median, which is the common outcome's return (a 10 % risk of a penalty
    learns as no risk at all).

    Args:
        q: ``(B, N, m)`` Q(s, a, w) of the taken action.
        y: ``(B, N, m)`` targets (no gradient).
        prefs: ``(B, N, m)`` row preferences.
        lb_weight: Weight of L^B (1 in the paper).
        lb_loss: ``"squared"`` or ``"abs"``.

    Returns:
        ``(loss, l_a, l_b)``, each of shape ``(B,)``.
    """
    diff = y - q
    l_a = objective_sum(diff * diff).mean(1)
    scalar = objective_sum(prefs * diff)
    l_b = (scalar * scalar if lb_loss == "squared" else scalar.abs()).mean(1)
    return l_a + weighted(lb_weight, l_b), l_a, l_b


def weighted(weight: float | torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """``weight * x``, without the multiplication when ``weight`` is the number 1 (the same values and gradients,
    one tensor operation and its backward fewer)."""
    if not torch.is_tensor(weight) and weight == 1.0:
        return x
    return weight * x


def component_loss(components: torch.Tensor, y: torch.Tensor, anchor_weight: float = 0.0) -> torch.Tensor:
    """Convex head (not in the paper): each target also pulls the return vector nearest to it.

    ``min_c ||y_i - v_c(s, a)||^2``, averaged over the transition's N targets. The component a preference
    selects is trained through eq. 4; this term lets the other components settle on the other targets, so the
    C vectors spread over the distinct returns reachable from (s, a).

    With ``anchor_weight`` > 0, each component is also pulled toward the target nearest to it,
    ``anchor_weight * mean_c min_i ||y_i - v_c(s, a)||^2`` (the other half of a Chamfer distance). A component
    that no target is nearest to is otherwise trained only when a preference selects it, so it drifts with the
    shared layers; the max over components in the next target then picks up the drift.

    Args:
        components: ``(B, C, m)`` the return vectors of the taken action.
        y: ``(B, N, m)`` targets (no gradient).
        anchor_weight: Weight of the pull of every component toward its nearest target.

    Returns:
        ``(B,)`` per-transition losses.
    """
    dist = None  # (B, N, C), summed objective by objective: m small (B, N, C) tensors, not one (B, N, C, m)
    for k in range(components.shape[-1]):
        d = components[..., k].unsqueeze(1) - y[..., k].unsqueeze(2)
        dist = d * d if dist is None else dist + d * d
    loss = dist.min(dim=2).values.mean(dim=1)
    if anchor_weight:
        loss = loss + anchor_weight * dist.min(dim=1).values.mean(dim=1)
    return loss


def preference_interval_td(q: torch.Tensor, y: torch.Tensor, prefs: torch.Tensor) -> torch.Tensor:
    """Preference-interval TD error of eq. 5: ``delta = 1/N sum_i (w_i^T y - w_i^T Q(s, a, w_i))``.

    The mean is taken with signs, as eq. 5 is written; the priority uses its magnitude (see
    :func:`priority`).

    Returns:
        ``(B,)`` signed mean scalarised TD errors.
    """
    return objective_sum(prefs * (y - q)).mean(1)


def mutual_information_bonus(log_q: torch.Tensor, log_p: torch.Tensor) -> torch.Tensor:
    """The per-sample term of the variational bound of eq. 6: ``log q_phi(w | s) - log p(w)``."""
    return log_q - log_p


def priority(td: torch.Tensor, mi_bonus: torch.Tensor | None, alpha: float, eps: float,
             per_alpha: float = 1.0) -> np.ndarray:
    """Replay priority of eq. 7, made a valid positive PER priority, raised to the PER exponent.

    ``q(s_i) = |delta| + alpha * (log q_phi(w|s) - log p(w))``. eq. 7 can be negative (a state whose preference
    the discriminator finds unlikely); it is clipped at 0, then ``eps`` is added so every transition keeps a
    chance to be replayed, and the result is raised to ``per_alpha`` (Schaul et al. 2016). Without a
    discriminator (EQL, PE) the priority is ``(|delta| + eps) ** per_alpha``.

    Returns:
        ``(B,)`` priorities as stored in the (numpy) sum tree; the exponent is applied in numpy, the sum tree's
        own arithmetic.
    """
    p = td.abs()
    if mi_bonus is not None:
        p = p + alpha * mi_bonus
    return (p.clamp_min(0.0) + eps).detach().cpu().numpy() ** per_alpha


def large_margin_loss(q: torch.Tensor, demo_actions: torch.Tensor, margin: float,
                      mask: torch.Tensor | None = None) -> torch.Tensor:
    """DQfD's supervised large-margin loss ``J_E`` per row (Hester et al. 2018, sec. 3, eq. for ``J_E(Q)``).

    ::

        J_E = max_a [Q(s, a) + l(a_E, a)] - Q(s, a_E),    l(a_E, a) = margin if a != a_E else 0

    ``J_E >= 0``, and it is 0 only when the demonstrator's action ``a_E`` beats every other action by at least
    ``margin``; a tie with another action costs ``margin``. The loss pushes the values of the actions the
    demonstrator did not take below ``Q(s, a_E)``, so the greedy policy imitates it on its states.

    The agent passes the scalarised Q-values ``w^T Q(s, ., w)`` of its rows. If ``demo_actions`` has fewer
    dimensions than the rows (one action per transition, ``(B,)``, against ``(B, N, A)``), the caller expands
    it, e.g. ``demo_actions[:, None].expand(-1, N)``.

    Args:
        q: ``(..., A)`` scalarised Q-values (``(B, A)`` or ``(B, N, A)``).
        demo_actions: ``q.shape[:-1]`` integer demonstrator actions in ``[0, A)``; on rows that ``mask`` leaves
            out any value is accepted (e.g. -1) and ignored.
        margin: ``l`` for ``a != a_E``, at least 0 (DQfD uses 0.8).
        mask: ``q.shape[:-1]`` bool (or 0/1) selection of the demonstration rows; ``None`` selects every row.

    Returns:
        ``q.shape[:-1]`` per-row losses, 0 on rows outside ``mask``, so that the caller can weight them (e.g. by
        importance-sampling weights) before taking the mean.

    Raises:
        ValueError: for mismatched shapes or a negative margin.
    """
    if margin < 0:
        raise ValueError(f"large_margin_loss: margin={margin} is out of range: must be >= 0")
    lead = q.shape[:-1]
    if demo_actions.shape != lead:
        raise ValueError(f"large_margin_loss: demo_actions has shape {tuple(demo_actions.shape)}, q has "
                         f"{tuple(q.shape)}: expand the actions to q's leading shape {tuple(lead)}")
    if mask is not None and mask.shape != lead:
        raise ValueError(f"large_margin_loss: mask has shape {tuple(mask.shape)}: need q's leading shape "
                         f"{tuple(lead)}")
    sel = torch.ones(lead, dtype=torch.bool, device=q.device) if mask is None else mask.to(torch.bool)
    actions = torch.where(sel, demo_actions.long(), torch.zeros_like(demo_actions, dtype=torch.long))
    q_demo = q.gather(-1, actions.unsqueeze(-1)).squeeze(-1)
    others = torch.full_like(q, float(margin))
    others.scatter_(-1, actions.unsqueeze(-1), 0.0)
    loss = (q + others).max(dim=-1).values - q_demo
    return torch.where(sel, loss, torch.zeros_like(loss))
