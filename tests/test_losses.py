"""Tests of mope.agent.losses on tiny cases worked out by hand (eq. 4-7 of the paper)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from mope.agent.losses import (
    clip_targets,
    component_loss,
    envelope_set,
    envelope_target,
    eql_loss,
    greedy_tail_returns,
    large_margin_loss,
    mix_behaviour_returns,
    mutual_information_bonus,
    objective_sum,
    preference_interval_td,
    priority,
    taken_action_q,
    watkins_n_step_targets,
    weighted,
)

# Envelope preferences (K = 2) and the designed Q_target(s'_b, a, w') for A = 3 actions, m = 2 objectives.
ENV_PREFS = [[1.0, 0.0], [0.0, 1.0]]
# transition 0
Q0 = [
    [[1.0, 0.0], [0.0, 1.0], [0.4, 0.4]],  # w' = (1, 0)
    [[2.0, -1.0], [0.0, 0.0], [0.6, 0.6]],  # w' = (0, 1)
]
# transition 1: a different table, so a row mix-up between transitions shows
Q1 = [
    [[0.0, 3.0], [1.0, 1.0], [0.2, 0.0]],
    [[0.5, 0.5], [4.0, -2.0], [0.0, 0.0]],
]
# transition 2 (terminated): huge values that must never reach the target
Q2 = [
    [[100.0, 100.0], [100.0, 100.0], [100.0, 100.0]],
    [[100.0, 100.0], [100.0, 100.0], [100.0, 100.0]],
]
# training-row preferences (N = 3), the same for every transition
ROW_PREFS = [[1.0, 0.0], [0.0, 1.0], [0.5, 0.5]]


ENV_PREFS_T = torch.tensor(ENV_PREFS)


def run_target(gamma: float, terminated: list[float] | None = None) -> torch.Tensor:
    q_next = torch.tensor([Q0, Q1, Q2])  # (B, K, A, m): Q_target(s'_b, a, w'_k)
    b = 3
    rewards = torch.tensor([[1.0, -1.0], [0.0, -1.0], [3.0, -1.0]])
    term = torch.tensor(terminated if terminated is not None else [0.0, 0.0, 1.0])
    row_prefs = torch.tensor(ROW_PREFS).unsqueeze(0).expand(b, -1, -1)
    return envelope_target(q_next, rewards, term, row_prefs, gamma)


def test_envelope_target_hand_values() -> None:
    y = run_target(gamma=0.5)
    assert y.shape == (3, 3, 2)
    # transition 0, reward (1, -1):
    #   w=(1,0): scalarised k0 [1, 0, .4], k1 [2, 0, .6] -> (k1, a0) -> Q* (2, -1)  -> y = (2, -1.5)
    #   w=(0,1): k0 [0, 1, .4], k1 [-1, 0, .6]          -> (k0, a1) -> Q* (0, 1)   -> y = (1, -0.5)
    #   w=(.5,.5): k0 [.5, .5, .4], k1 [.5, 0, .6]      -> (k1, a2) -> Q* (.6, .6) -> y = (1.3, -0.7)
    torch.testing.assert_close(y[0], torch.tensor([[2.0, -1.5], [1.0, -0.5], [1.3, -0.7]]))
    # transition 1, reward (0, -1):
    #   w=(1,0): k0 [0, 1, .2], k1 [.5, 4, 0]   -> (k1, a1) -> Q* (4, -2) -> y = (2, -2)
    #   w=(0,1): k0 [3, 1, 0], k1 [.5, -2, 0]   -> (k0, a0) -> Q* (0, 3)  -> y = (0, 0.5)
    #   w=(.5,.5): k0 [1.5, 1, .1], k1 [.5, 1, 0] -> (k0, a0) -> Q* (0, 3) -> y = (0, 0.5)
    torch.testing.assert_close(y[1], torch.tensor([[2.0, -2.0], [0.0, 0.5], [0.0, 0.5]]))
    # transition 2 is terminated: only the reward
    torch.testing.assert_close(y[2], torch.tensor([[3.0, -1.0]] * 3))


def test_envelope_target_max_is_joint_over_actions_and_envelope_prefs() -> None:
    # With the max over actions only at the row's own preference, row w=(1,0) of transition 0 would get
    # Q(s', a0, (1,0)) = (1, 0); the envelope finds (2, -1) under the other preference.
    y = run_target(gamma=1.0)
    torch.testing.assert_close(y[0, 0], torch.tensor([1.0 + 2.0, -1.0 - 1.0]))
    assert not torch.allclose(y[0, 0], torch.tensor([1.0 + 1.0, -1.0 + 0.0]))


def test_envelope_off_maxes_over_actions_at_the_row_preference_only() -> None:
    # envelope=False: rows are the envelope set (K = N = 2, the two one-hot preferences); row i uses only k = i.
    q_next = torch.tensor([Q0, Q1])
    rewards = torch.tensor([[1.0, -1.0], [0.0, -1.0]])
    prefs = ENV_PREFS_T.unsqueeze(0).expand(2, -1, -1)
    y = envelope_target(q_next, rewards, torch.zeros(2), prefs, 1.0, envelope=False)
    # transition 0: w=(1,0) at k0: [1, 0, .4] -> a0 (1, 0); w=(0,1) at k1: [-1, 0, .6] -> a2 (.6, .6)
    torch.testing.assert_close(y[0], torch.tensor([[2.0, -1.0], [1.6, -0.4]]))
    # transition 1: w=(1,0) at k0: [0, 1, .2] -> a1 (1, 1); w=(0,1) at k1: [.5, -2, 0] -> a0 (.5, .5)
    torch.testing.assert_close(y[1], torch.tensor([[1.0, 0.0], [0.5, -0.5]]))


@pytest.mark.parametrize("gamma", [0.5, 0.9, 0.99])
def test_envelope_target_applies_gamma(gamma: float) -> None:
    y = run_target(gamma=gamma)
    q_star_0 = torch.tensor([[2.0, -1.0], [0.0, 1.0], [0.6, 0.6]])
    torch.testing.assert_close(y[0], torch.tensor([1.0, -1.0]) + gamma * q_star_0)
    torch.testing.assert_close(y[2], torch.tensor([[3.0, -1.0]] * 3))


def test_envelope_target_terminated_rows_get_only_reward() -> None:
    y = run_target(gamma=0.9, terminated=[1.0, 1.0, 1.0])
    torch.testing.assert_close(y[0], torch.tensor([[1.0, -1.0]] * 3))
    torch.testing.assert_close(y[1], torch.tensor([[0.0, -1.0]] * 3))
    torch.testing.assert_close(y[2], torch.tensor([[3.0, -1.0]] * 3))


def test_double_q_selects_with_one_table_and_reads_the_other() -> None:
    q_next = torch.tensor([Q0])
    q_select = torch.tensor([Q1])  # the online network's view: its argmax picks the (k, a) read from q_next
    rows = torch.tensor([ROW_PREFS])
    y = envelope_target(q_next, torch.zeros(1, 2), torch.zeros(1), rows, 1.0, q_select=q_select)
    # on Q1: w=(1,0) -> (k1, a1); w=(0,1) -> (k0, a0); w=(.5,.5) -> (k0, a0); read at those indices of Q0
    torch.testing.assert_close(y[0], torch.tensor([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0]]))


def test_envelope_target_with_different_k_and_n() -> None:
    # K = 1: the envelope collapses to a max over actions at that single preference
    q_next = torch.tensor([[Q0[1]]])  # (1, 1, 3, 2): Q under w' = (0, 1)
    rows = torch.tensor([[[1.0, 0.0], [0.0, 1.0], [0.5, 0.5], [0.25, 0.75]]])
    y = envelope_target(q_next, torch.zeros(1, 2), torch.zeros(1), rows, 1.0)
    # Q = [(2,-1), (0,0), (.6,.6)]; w=(1,0) -> a0; w=(0,1) -> a2; w=(.5,.5) -> a2 (.6 > .5); w=(.25,.75) -> a2
    torch.testing.assert_close(y[0], torch.tensor([[2.0, -1.0], [0.6, 0.6], [0.6, 0.6], [0.6, 0.6]]))


def test_envelope_target_with_real_network_shapes() -> None:
    import gymnasium as gym

    from mope.agent.networks import QNetwork

    torch.manual_seed(0)
    net = QNetwork(gym.spaces.Box(0.0, 1.0, (3,)), n_actions=4, n_objectives=2, hidden=(8,))
    b, n, k = 5, 6, 7
    obs = torch.rand(b, 3)
    rows = torch.softmax(torch.randn(b, n, 2), -1)
    env = torch.softmax(torch.randn(b, k, 2), -1)
    q_next = net.forward_prefs(obs, env)
    assert q_next.shape == (b, k, 4, 2)
    y = envelope_target(q_next, torch.zeros(b, 2), torch.zeros(b), rows, 1.0)
    assert y.shape == (b, n, 2)
    # brute force: for every row, the best (a, w') of w^T Q(s', a, w')
    for bi in range(b):
        q = net(obs[bi].expand(k, 3), env[bi])  # (K, A, m)
        torch.testing.assert_close(q, q_next[bi])
        for i in range(n):
            scal = (q * rows[bi, i]).sum(-1)
            kk, aa = divmod(int(scal.argmax()), 4)
            torch.testing.assert_close(y[bi, i], q[kk, aa])


def test_envelope_set_modes() -> None:
    rows = torch.rand(2, 3, 2)
    acting = torch.tensor([[0.2, 0.8], [0.6, 0.4]])
    same, env = envelope_set("relabel", rows, acting)
    assert same is rows and env
    own, env = envelope_set("own", rows, acting)
    assert own is rows and not env
    batch, env = envelope_set("batch", rows, acting)
    assert batch.shape == (2, 2, 2) and env and torch.equal(batch[0], acting) and torch.equal(batch[1], acting)
    both, _ = envelope_set("both", rows, acting)
    assert both.shape == (2, 5, 2) and torch.equal(both[:, :3], rows)


def test_clip_targets_and_taken_action_q() -> None:
    y = torch.tensor([[[5.0, -200.0], [-1.0, 0.5]]])
    torch.testing.assert_close(clip_targets(y, torch.tensor([0.0, -100.0]), torch.tensor([3.0, -1.0])),
                               torch.tensor([[[3.0, -100.0], [0.0, -1.0]]]))
    q_all = torch.arange(2 * 3 * 4 * 2, dtype=torch.float32).view(2, 3, 4, 2)
    q = taken_action_q(q_all, torch.tensor([1, 3]))
    assert q.shape == (2, 3, 2)
    torch.testing.assert_close(q[0], q_all[0, :, 1])
    torch.testing.assert_close(q[1], q_all[1, :, 3])


# ------------------------------------------------------------------------------------------- EQL loss
Q = torch.tensor([[[1.0, 2.0], [0.0, 0.0]]])  # (B=1, N=2, m=2)
Y = torch.tensor([[[2.0, 0.0], [1.0, 1.0]]])
W = torch.tensor([[[0.5, 0.5], [1.0, 0.0]]])


def test_eql_loss_hand_values() -> None:
    # y - Q: row 0 (1, -2), row 1 (1, 1); w^T (y - Q): -0.5 and 1
    # L^A = mean(1 + 4, 1 + 1) = 3.5;  L^B = mean(0.25, 1) = 0.625 squared, mean(0.5, 1) = 0.75 absolute
    loss, l_a, l_b = eql_loss(Q, Y, W)
    torch.testing.assert_close(l_a, torch.tensor([3.5]))
    torch.testing.assert_close(l_b, torch.tensor([0.625]))
    torch.testing.assert_close(loss, torch.tensor([4.125]))
    loss2, _, _ = eql_loss(Q, Y, W, lb_weight=2.0)
    torch.testing.assert_close(loss2, torch.tensor([4.75]))
    loss0, _, _ = eql_loss(Q, Y, W, lb_weight=0.0)
    torch.testing.assert_close(loss0, torch.tensor([3.5]))
    loss_abs, _, l_b_abs = eql_loss(Q, Y, W, lb_loss="abs")
    torch.testing.assert_close(l_b_abs, torch.tensor([0.75]))
    torch.testing.assert_close(loss_abs, torch.tensor([4.25]))


def test_eql_loss_is_per_transition() -> None:
    q = torch.cat([Q, torch.zeros(1, 2, 2)])
    y = torch.cat([Y, torch.tensor([[[3.0, 4.0], [0.0, 0.0]]])])
    w = torch.cat([W, torch.tensor([[[0.0, 1.0], [0.5, 0.5]]])])
    loss, l_a, l_b = eql_loss(q, y, w)
    # transition 1: rows (3, 4) and (0, 0): L^A = mean(25, 0) = 12.5, L^B = mean(4^2, 0) = 8
    torch.testing.assert_close(l_a, torch.tensor([3.5, 12.5]))
    torch.testing.assert_close(l_b, torch.tensor([0.625, 8.0]))
    torch.testing.assert_close(loss, torch.tensor([4.125, 20.5]))


def _fit_to_random_targets(lb_loss: str) -> torch.Tensor:
    """Q (one row, w = (0.5, 0.5)) fitted by gradient descent to a risky action's targets: (-1, 0) with
    probability 0.1 (killed), (0, 1) with 0.9, in equal batches of both as the replay gives them."""
    w = torch.tensor([[[0.5, 0.5]]]).expand(10, 1, 2)
    y = torch.tensor([[[-1.0, 0.0]]] + [[[0.0, 1.0]]] * 9)  # (10, 1, 2): the outcomes in their proportions
    q = torch.zeros(1, 1, 2, requires_grad=True)
    opt = torch.optim.SGD([q], lr=0.05)
    for _ in range(3000):
        opt.zero_grad()
        loss, _, _ = eql_loss(q.expand(10, 1, 2), y, w, lb_loss=lb_loss)
        loss.mean().backward()
        opt.step()
    return q.detach()[0, 0]


def test_squared_lb_learns_the_expected_return_of_random_outcomes() -> None:
    # The expected return is (-0.1, 0.9). L^A alone is minimised there; the squared L^B keeps that minimum. The
    # absolute L^B (eq. 4 as written) pulls w^T Q to the median outcome's utility, 0.5, and the fitted vector
    # follows it: the 10 % risk of the penalty is learnt as far smaller (resource-gathering's enemy cells).
    torch.testing.assert_close(_fit_to_random_targets("squared"), torch.tensor([-0.1, 0.9]), atol=1e-3, rtol=0)
    q_abs = _fit_to_random_targets("abs")
    assert q_abs[0] > -0.05 and q_abs.sum() > 0.85  # the scalarised value far above the expected 0.8


def test_eql_loss_zero_at_target_and_gradient_flows_to_q() -> None:
    q = Y.clone().requires_grad_(True)
    loss, _, _ = eql_loss(q, Y, W)
    assert loss.item() == 0.0
    q = Q.clone().requires_grad_(True)
    loss, _, _ = eql_loss(q, Y, W, lb_weight=0.0)
    loss.sum().backward()
    # d/dQ mean_i ||y_i - Q_i||^2 = -2 (y - Q) / N
    torch.testing.assert_close(q.grad, -2.0 * (Y - Q) / 2.0)


def test_weighted_skips_only_a_unit_weight_and_keeps_values_and_gradients() -> None:
    x = torch.tensor([1.5, -2.0], requires_grad=True)
    assert weighted(1.0, x) is x and weighted(1, x) is x
    torch.testing.assert_close(weighted(0.5, x), torch.tensor([0.75, -1.0]))
    torch.testing.assert_close(weighted(torch.tensor([2.0, 1.0]), x), torch.tensor([3.0, -2.0]))
    weighted(3.0, x).sum().backward()
    torch.testing.assert_close(x.grad, torch.tensor([3.0, 3.0]))


# ------------------------------------------------------------------------------------------- eq. 5
def test_preference_interval_td_is_signed_mean() -> None:
    # scalarised errors: row 0 0.5 * 1 + 0.5 * (-2) = -0.5, row 1 1 -> mean 0.25 (the mean of |.| would be 0.75)
    td = preference_interval_td(Q, Y, W)
    torch.testing.assert_close(td, torch.tensor([0.25]))


def test_preference_interval_td_cancels_opposite_errors() -> None:
    q = torch.zeros(1, 2, 2)
    y = torch.tensor([[[1.0, 0.0], [-1.0, 0.0]]])
    w = torch.tensor([[[1.0, 0.0], [1.0, 0.0]]])
    torch.testing.assert_close(preference_interval_td(q, y, w), torch.tensor([0.0]))
    torch.testing.assert_close(preference_interval_td(q, -y[:, :1], w[:, :1]), torch.tensor([-1.0]))


# ------------------------------------------------------------------------------------------- eq. 6-7
def test_mutual_information_bonus() -> None:
    log_q = torch.log(torch.tensor([0.5, 0.1, 0.02]))
    log_p = torch.log(torch.tensor([0.1, 0.1, 0.1]))
    bonus = mutual_information_bonus(log_q, log_p)
    torch.testing.assert_close(bonus, torch.tensor([math.log(5.0), 0.0, math.log(0.2)]))


def test_priority_hand_values_with_bonus_and_clipping() -> None:
    td = torch.tensor([0.25, -2.0, 0.5])
    bonus = torch.tensor([1.0, 0.5, -10.0])
    p = priority(td, bonus, alpha=0.1, eps=0.01)
    # |td| + 0.1 * bonus = [0.35, 2.05, -0.5] -> clip at 0 -> + 0.01
    np.testing.assert_allclose(p, [0.36, 2.06, 0.01], rtol=1e-6)


def test_priority_without_discriminator() -> None:
    td = torch.tensor([0.25, -2.0, 0.5, 0.0])
    p = priority(td, None, alpha=0.1, eps=0.01)
    np.testing.assert_allclose(p, [0.26, 2.01, 0.51, 0.01], rtol=1e-6)


def test_priority_alpha_zero_ignores_bonus() -> None:
    td = torch.tensor([-0.3, 0.7])
    p = priority(td, torch.tensor([-100.0, 100.0]), alpha=0.0, eps=1e-3)
    np.testing.assert_allclose(p, [0.301, 0.701], rtol=1e-6)


def test_priority_applies_the_per_exponent() -> None:
    td = torch.tensor([0.99, 3.99])
    p = priority(td, None, alpha=0.1, eps=0.01, per_alpha=0.5)
    np.testing.assert_allclose(p, [1.0, 2.0], rtol=1e-6)  # (|td| + eps) ** 0.5


def test_component_loss_anchor_pulls_every_component_toward_its_nearest_target() -> None:
    comps = torch.tensor([[[0.0], [10.0]]])  # (B=1, C=2, m=1)
    y = torch.tensor([[[1.0], [2.0]]])  # (B=1, N=2, m=1)
    # each target's nearest component is 0: (1 + 4) / 2; each component's nearest target: 0 -> 1, 10 -> 2: (1 + 64) / 2
    torch.testing.assert_close(component_loss(comps, y), torch.tensor([2.5]))
    torch.testing.assert_close(component_loss(comps, y, anchor_weight=0.5), torch.tensor([2.5 + 0.5 * 32.5]))


def test_greedy_tail_returns_hand_values() -> None:
    r = np.array([[0.0, -1.0], [0.0, -1.0], [5.0, -1.0]], dtype=np.float32)
    v = np.array([[10.0, 0.0], [20.0, 0.0], [30.0, 0.0]], dtype=np.float32)  # V(s1), V(s2), V(s3)
    all_greedy = greedy_tail_returns(r, v, np.array([True, True, True]), terminated=True, gamma=0.5)
    np.testing.assert_allclose(all_greedy, [[1.25, -1.75], [2.5, -1.5], [5.0, -1.0]])
    # a random action at step 1 cuts the trace: s1's value for step 0 is V(s1), not G_1
    cut = greedy_tail_returns(r, v, np.array([True, False, True]), terminated=True, gamma=0.5)
    np.testing.assert_allclose(cut, [[5.0, -1.0], [2.5, -1.5], [5.0, -1.0]])
    # the time limit, not termination, ended it: the last step bootstraps from V(s3)
    trunc = greedy_tail_returns(r, v, np.array([True, True, True]), terminated=False, gamma=0.5)
    np.testing.assert_allclose(trunc[-1], [20.0, -1.0])
    np.testing.assert_allclose(trunc[0], [0.0 + 0.5 * (0.0 + 0.5 * 20.0), -1.0 + 0.5 * (-1.0 + 0.5 * -1.0)])


def test_mix_behaviour_returns_blends_only_the_own_row_of_fresh_transitions() -> None:
    y = torch.arange(2 * 3 * 2, dtype=torch.float32).view(2, 3, 2)
    g = torch.tensor([[100.0, 100.0], [-100.0, -100.0]])
    out = mix_behaviour_returns(y, g, torch.tensor([True, False]), 0.25)
    torch.testing.assert_close(out[0, 0], 0.75 * y[0, 0] + 25.0)
    torch.testing.assert_close(out[0, 1:], y[0, 1:])
    torch.testing.assert_close(out[1], y[1])


def test_watkins_n_step_targets_hand_values() -> None:
    """Three steps of rewards 1, 2, 3 (one objective), values after each step 10, 20, 30, gamma 0.5. Row 0 follows
    every step; row 1 is cut before step 1 (its greedy action differs from the stored one); row 2 before step 2."""
    rewards = torch.tensor([[[1.0], [2.0], [3.0]]])
    values = torch.tensor([10.0, 20.0, 30.0]).view(1, 3, 1, 1).expand(1, 3, 3, 1)
    cont = torch.tensor([[[True, True, True], [True, False, True], [True, True, False]]])
    y = watkins_n_step_targets(rewards, values, cont, 0.5)
    assert y.shape == (1, 3, 1)
    full = 1 + 0.5 * (2 + 0.5 * (3 + 0.5 * 30))
    torch.testing.assert_close(y[0, :, 0], torch.tensor([full, 1 + 0.5 * 10, 1 + 0.5 * (2 + 0.5 * 20)]))
    # one step, or nothing continued: the one-step target r + gamma V of eq. 4
    torch.testing.assert_close(watkins_n_step_targets(rewards[:, :1], values[:, :1], cont[:, :1], 0.5),
                               torch.full((1, 3, 1), 1 + 0.5 * 10))
    # a row cut at step 1 ignores a "continue" flag at step 2 (its later steps are not read)
    cut_then_on = torch.tensor([[[True] * 3, [False] * 3, [True] * 3]])
    torch.testing.assert_close(watkins_n_step_targets(rewards, values, cut_then_on, 0.5),
                               torch.full((1, 3, 1), 1 + 0.5 * 10))


# DQfD's J_E = max_a [Q(s, a) + l(a_E, a)] - Q(s, a_E), l = margin off the demonstrated action.
MARGIN_Q = torch.tensor([
    [1.0, 2.0, 3.0],  # a_E = 2 leads by 1 > margin: J_E = 0
    [0.0, 2.0, 1.0],  # a_E = 0 trails: J_E = (2 + 0.5) - 0 = 2.5
    [1.0, 1.0, 0.0],  # a_E = 0 ties with a = 1: J_E = (1 + 0.5) - 1 = 0.5
    [3.0, 2.8, 0.0],  # a_E = 0 leads by 0.2 < margin: J_E = (2.8 + 0.5) - 3 = 0.3
])
MARGIN_A = torch.tensor([2, 0, 0, 0])


def test_large_margin_loss_hand_values() -> None:
    loss = large_margin_loss(MARGIN_Q, MARGIN_A, margin=0.5)
    torch.testing.assert_close(loss, torch.tensor([0.0, 2.5, 0.5, 0.3]))


def test_large_margin_loss_margin_zero_is_the_gap_to_the_best_action() -> None:
    # without a margin a tie costs nothing and J_E = max_a Q - Q(a_E)
    loss = large_margin_loss(MARGIN_Q, MARGIN_A, margin=0.0)
    torch.testing.assert_close(loss, torch.tensor([0.0, 2.0, 0.0, 0.0]))


def test_large_margin_loss_mask_zeroes_other_rows_and_ignores_their_actions() -> None:
    actions = torch.tensor([-1, 0, 7, 0])  # rows 0 and 2 are not demonstrations: their actions are junk
    mask = torch.tensor([False, True, False, True])
    loss = large_margin_loss(MARGIN_Q, actions, margin=0.5, mask=mask)
    torch.testing.assert_close(loss, torch.tensor([0.0, 2.5, 0.0, 0.3]))
    # a 0/1 float mask selects the same rows
    loss_f = large_margin_loss(MARGIN_Q, actions, margin=0.5, mask=mask.float())
    torch.testing.assert_close(loss_f, loss)


def test_large_margin_loss_rows_of_preferences_and_gradient() -> None:
    # (B, N, A) = (2, 2, 3): transition 0 has rows 0 and 1 of MARGIN_Q, transition 1 rows 2 and 3
    q = MARGIN_Q.view(2, 2, 3).clone().requires_grad_(True)
    actions = torch.tensor([2, 0])[:, None].expand(-1, 2)  # one action per transition, expanded by the caller
    loss = large_margin_loss(q, actions, margin=0.5)
    # row (0, 1) now has a_E = 2 on [0, 2, 1]: (2 + 0.5) - 1 = 1.5
    torch.testing.assert_close(loss, torch.tensor([[0.0, 1.5], [0.5, 0.3]]))
    loss.sum().backward()
    # d J_E / d Q: +1 on the maximising action, -1 on a_E; none where a_E itself is the max (row (0, 0))
    expected = torch.tensor([[[0.0, 0.0, 0.0], [0.0, 1.0, -1.0]], [[-1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]])
    torch.testing.assert_close(q.grad, expected)


def test_large_margin_loss_rejects_bad_shapes_and_negative_margin() -> None:
    with pytest.raises(ValueError, match="expand the actions"):
        large_margin_loss(MARGIN_Q.view(2, 2, 3), torch.tensor([0, 1]), margin=0.5)
    with pytest.raises(ValueError, match="mask has shape"):
        large_margin_loss(MARGIN_Q, MARGIN_A, margin=0.5, mask=torch.ones(3, dtype=torch.bool))
    with pytest.raises(ValueError, match="margin=-0.1"):
        large_margin_loss(MARGIN_Q, MARGIN_A, margin=-0.1)


@pytest.mark.parametrize("m", [1, 2, 3, 6])
def test_objective_sum_is_the_sum_over_the_last_axis(m: int) -> None:
    x = torch.randn(7, 5, m, generator=torch.Generator().manual_seed(m))
    torch.testing.assert_close(objective_sum(x), x.sum(-1))
    if m <= 2:
        assert torch.equal(objective_sum(x), x.sum(-1))


def test_denormals_are_flushed_inside_the_block_and_the_mode_restored() -> None:
    from mope.agent.agent import denormals_are_flushed, flushed_denormals

    assert not denormals_are_flushed()
    tiny = torch.tensor([1e-39])
    assert tiny.mul(1.0)[0] > 0  # a denormal survives arithmetic outside
    with flushed_denormals():
        assert denormals_are_flushed()
        assert tiny.mul(1.0)[0] == 0
    assert not denormals_are_flushed() and tiny.mul(1.0)[0] > 0


def test_consistent_values_replace_only_the_self_transitions_by_the_taken_actions_value() -> None:
    """Bellemare et al.'s consistent operator: where s' = s, the value after the step is Q_target(s, a_taken, w) (w's
    own component of that action); elsewhere the double-Q value stays."""
    from types import SimpleNamespace

    from mope.agent.targets import consistent_values

    buffer = SimpleNamespace(obs=np.array([[0.0, 1.0], [0.0, 1.0]]), next_obs=np.array([[0.0, 1.0], [1.0, 1.0]]),
                             actions=np.array([1, 0]))
    v_target = torch.tensor([[[[9.0, 9.0], [9.0, 9.0]], [[2.0, 0.0], [0.0, 3.0]]],  # row 0: action 1 has (2, 0), (0, 3)
                             [[[5.0, 5.0], [5.0, 5.0]], [[5.0, 5.0], [5.0, 5.0]]]])
    w = torch.tensor([[[1.0, 0.0], [0.0, 1.0]], [[1.0, 0.0], [0.0, 1.0]]])
    values = torch.full((2, 2, 2), 7.0)  # what double Q gave (the greedy action's values)
    out = consistent_values(values, v_target, buffer, np.array([0, 1]), w)
    assert torch.equal(out[0], torch.tensor([[2.0, 0.0], [0.0, 3.0]]))  # each preference's component of action 1
    assert torch.equal(out[1], values[1]) and torch.equal(values, torch.full((2, 2, 2), 7.0))  # moved, not in place
