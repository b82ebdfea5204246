"""Tests of mope.agent.networks: observation encoding, the multi-head Q-network and the preference discriminator."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from torch import nn

from mope.agent.networks import ConvexQNetwork, Discriminator, ObsEncoder, QNetwork, mlp
from mope.errors import EnvironmentError_

DST_SPACE = gym.spaces.Box(low=0, high=11, shape=(2,), dtype=np.int32)


def linears(module: nn.Module) -> list[nn.Linear]:
    return [m for m in module.modules() if isinstance(m, nn.Linear)]


# ------------------------------------------------------------------------------------------- ObsEncoder
def test_encoder_scales_bounded_box_to_unit_interval() -> None:
    enc = ObsEncoder(gym.spaces.Box(low=np.float32([0.0, -1.0]), high=np.float32([10.0, 1.0]), dtype=np.float32))
    assert enc.out_dim == 2
    x = torch.tensor([[0.0, -1.0], [5.0, 0.0], [10.0, 1.0], [2.5, 0.5]])
    torch.testing.assert_close(enc(x), torch.tensor([[0.0, 0.0], [0.5, 0.5], [1.0, 1.0], [0.25, 0.75]]))


def test_encoder_scales_integer_box() -> None:
    enc = ObsEncoder(DST_SPACE)
    out = enc(torch.tensor([[0, 0], [11, 5], [3, 11]], dtype=torch.int32))
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, torch.tensor([[0.0, 0.0], [1.0, 5 / 11], [3 / 11, 1.0]]))


def test_encoder_flattens_multidimensional_box() -> None:
    enc = ObsEncoder(gym.spaces.Box(low=0.0, high=2.0, shape=(2, 3), dtype=np.float32))
    assert enc.out_dim == 6
    x = torch.arange(12, dtype=torch.float32).reshape(2, 2, 3) / 6.0
    torch.testing.assert_close(enc(x), x.reshape(2, 6) / 2.0)


def test_encoder_one_hot_for_discrete() -> None:
    enc = ObsEncoder(gym.spaces.Discrete(4))
    assert enc.out_dim == 4
    out = enc(torch.tensor([0, 3, 1]))
    torch.testing.assert_close(out, torch.tensor([[1.0, 0, 0, 0], [0, 0, 0, 1.0], [0, 1.0, 0, 0]]))
    # observations arriving as (B, 1) floats are encoded the same way
    torch.testing.assert_close(enc(torch.tensor([[0.0], [3.0], [1.0]])), out)


def test_encoder_one_hot_respects_discrete_start() -> None:
    enc = ObsEncoder(gym.spaces.Discrete(3, start=5))
    torch.testing.assert_close(enc(torch.tensor([5, 7, 6])), torch.tensor([[1.0, 0, 0], [0, 0, 1.0], [0, 1.0, 0]]))


def test_encoder_passes_unbounded_box_through() -> None:
    enc = ObsEncoder(gym.spaces.Box(low=-np.inf, high=np.inf, shape=(3,), dtype=np.float32))
    x = torch.tensor([[-100.0, 0.0, 12.5], [1.0, 2.0, 3.0]])
    torch.testing.assert_close(enc(x), x)


def test_encoder_mixed_bounds_scale_only_bounded_dims() -> None:
    space = gym.spaces.Box(low=np.float32([0.0, -np.inf, 2.0]), high=np.float32([4.0, np.inf, 2.0]), dtype=np.float32)
    enc = ObsEncoder(space)
    # dim 0 bounded [0, 4] -> scaled; dim 1 unbounded -> unchanged; dim 2 degenerate (high == low) -> unchanged
    x = torch.tensor([[1.0, -7.0, 2.0]])
    torch.testing.assert_close(enc(x), torch.tensor([[0.25, -7.0, 2.0]]))


@pytest.mark.parametrize(
    "space",
    [
        gym.spaces.MultiDiscrete([2, 3]),
        gym.spaces.Dict({"a": gym.spaces.Discrete(2)}),
        gym.spaces.Tuple((gym.spaces.Discrete(2), gym.spaces.Discrete(3))),
        gym.spaces.MultiBinary(4),
    ],
)
def test_encoder_rejects_unsupported_space(space: gym.Space) -> None:
    with pytest.raises(EnvironmentError_, match="not supported"):
        ObsEncoder(space)
    with pytest.raises(EnvironmentError_):
        QNetwork(space, 4, 2)
    with pytest.raises(EnvironmentError_):
        Discriminator(space, 10)


# ------------------------------------------------------------------------------------------- QNetwork
def test_qnetwork_default_hidden_sizes_from_paper() -> None:
    net = QNetwork(DST_SPACE, n_actions=4, n_objectives=2)
    shapes = [(lin.in_features, lin.out_features) for lin in linears(net)]
    # input: 2 encoded state features + 2 preference weights; output: |A| x m = 4 x 2
    assert shapes == [(4, 64), (64, 128), (128, 128), (128, 64), (64, 8)]
    assert sum(isinstance(mod, nn.ReLU) for mod in net.modules()) == 4


def test_qnetwork_custom_hidden_and_discrete_obs() -> None:
    net = QNetwork(gym.spaces.Discrete(5), n_actions=3, n_objectives=4, hidden=(16, 8))
    assert [(lin.in_features, lin.out_features) for lin in linears(net)] == [(9, 16), (16, 8), (8, 12)]
    q = net(torch.tensor([0, 4]), torch.full((2, 4), 0.25))
    assert q.shape == (2, 3, 4)


@pytest.mark.parametrize(("rows", "a", "m"), [(1, 4, 2), (7, 4, 2), (5, 2, 3), (3, 6, 6)])
def test_qnetwork_output_shape(rows: int, a: int, m: int) -> None:
    net = QNetwork(gym.spaces.Box(0.0, 1.0, (3,), dtype=np.float32), n_actions=a, n_objectives=m, hidden=(8, 8))
    q = net(torch.rand(rows, 3), torch.softmax(torch.randn(rows, m), -1))
    assert q.shape == (rows, a, m)


def test_qnetwork_forward_features_equals_forward() -> None:
    torch.manual_seed(0)
    net = QNetwork(DST_SPACE, 4, 2, hidden=(16, 16))
    obs = torch.tensor([[0, 0], [3, 2], [10, 9]], dtype=torch.int32)
    w = torch.tensor([[1.0, 0.0], [0.3, 0.7], [0.5, 0.5]])
    torch.testing.assert_close(net(obs, w), net.forward_features(net.encoder(obs), w))


def test_qnetwork_depends_on_preference() -> None:
    torch.manual_seed(0)
    net = QNetwork(DST_SPACE, 4, 2)
    obs = torch.tensor([[1, 1], [1, 1]], dtype=torch.int32)
    q = net(obs, torch.tensor([[1.0, 0.0], [0.0, 1.0]]))
    assert not torch.allclose(q[0], q[1])


def test_qnetwork_heads_layout() -> None:
    # Output unit a * m + j is the head of action a, objective j.
    net = QNetwork(gym.spaces.Box(0.0, 1.0, (1,), dtype=np.float32), n_actions=3, n_objectives=2, hidden=(4,))
    last = linears(net)[-1]
    with torch.no_grad():
        for lin in linears(net):
            lin.weight.zero_()
        last.bias.copy_(torch.arange(6, dtype=torch.float32))
    q = net(torch.zeros(1, 1), torch.tensor([[0.5, 0.5]]))
    torch.testing.assert_close(q[0], torch.tensor([[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]]))


def test_mlp_structure() -> None:
    net = mlp(3, [5, 7], 2)
    kinds = [type(mod).__name__ for mod in net]
    assert kinds == ["Linear", "ReLU", "Linear", "ReLU", "Linear"]
    assert mlp(3, [], 2)[0].in_features == 3


# ------------------------------------------------------------------------------------------- Discriminator
def test_discriminator_shapes() -> None:
    d = Discriminator(DST_SPACE, n_cells=10)
    assert [(lin.in_features, lin.out_features) for lin in linears(d)] == [(2, 64), (64, 64), (64, 10)]
    obs = torch.tensor([[0, 0], [5, 5], [10, 10]], dtype=torch.int32)
    assert d(obs).shape == (3, 10)
    lp = d.log_prob(obs, torch.tensor([0, 9, 3]))
    assert lp.shape == (3,)
    assert (lp <= 0).all()
    # log_prob is the log-softmax entry of the given cell
    expected = torch.log_softmax(d(obs), 1)[torch.arange(3), torch.tensor([0, 9, 3])]
    torch.testing.assert_close(lp, expected)
    # the probabilities over all cells sum to 1
    all_lp = torch.stack([d.log_prob(obs, torch.full((3,), c)) for c in range(10)], 1)
    torch.testing.assert_close(all_lp.exp().sum(1), torch.ones(3))


def test_discriminator_learns_to_separate_two_groups() -> None:
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(0)
    space = gym.spaces.Box(low=-1.0, high=2.0, shape=(2,), dtype=np.float32)
    d = Discriminator(space, n_cells=10)
    opt = torch.optim.Adam(d.parameters(), lr=1e-2)

    def batch(n: int) -> tuple[torch.Tensor, torch.Tensor]:
        near0 = 0.1 * torch.randn(n, 2, generator=gen)
        near1 = 1.0 + 0.1 * torch.randn(n, 2, generator=gen)
        obs = torch.cat([near0, near1])
        cells = torch.cat([torch.zeros(n, dtype=torch.long), torch.full((n,), 9, dtype=torch.long)])
        return obs, cells

    for _ in range(300):
        obs, cells = batch(32)
        loss = -d.log_prob(obs, cells).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()

    obs, cells = batch(500)
    with torch.no_grad():
        pred = d(obs).argmax(1)
        lp = d.log_prob(obs, cells)
    assert (pred == cells).float().mean().item() > 0.95
    assert lp.mean().item() > math.log(0.5)
    assert (lp > math.log(0.5)).float().mean().item() > 0.95


def test_onehot_encoding_of_an_integer_box() -> None:
    from mope.agent.networks import ObsEncoder

    space = gym.spaces.Box(low=0, high=3, shape=(2,), dtype=np.int32)
    enc = ObsEncoder(space, "onehot")
    assert enc.out_dim == 8
    out = enc(torch.tensor([[0, 3], [2, 1]]))
    expected = torch.tensor([[1, 0, 0, 0, 0, 0, 0, 1], [0, 0, 1, 0, 0, 1, 0, 0]], dtype=torch.float32)
    assert torch.equal(out, expected)
    # coordinates of different sizes, and out-of-range values clamped to the edge indicators
    enc = ObsEncoder(gym.spaces.Box(low=np.array([0, -1]), high=np.array([1, 2]), dtype=np.int64), "onehot")
    out = enc(torch.tensor([[1, -1], [0, 2], [5, -4]]))
    expected = torch.tensor([[0, 1, 1, 0, 0, 0], [1, 0, 0, 0, 0, 1], [0, 1, 1, 0, 0, 0]], dtype=torch.float32)
    assert torch.equal(out, expected)


def test_onehot_encoding_refuses_a_float_box() -> None:
    from mope.agent.networks import ObsEncoder
    from mope.errors import EnvironmentError_

    with pytest.raises(EnvironmentError_, match="integer Box"):
        ObsEncoder(gym.spaces.Box(low=0.0, high=1.0, shape=(2,)), "onehot")


# ------------------------------------------------------------------------------------------- ConvexQNetwork
def test_convex_head_selects_the_component_the_preference_prefers() -> None:
    v = torch.tensor([[[[[1.0, 0.0], [0.0, 1.0], [0.4, 0.4]]]]])  # (B=1, H=1, A=1, C=3, m=2)
    prefs = torch.tensor([[[0.9, 0.1], [0.1, 0.9], [0.5, 0.5]]])  # (B=1, K=3, m)
    q = ConvexQNetwork.select(v, prefs)  # (1, 1, 3, 1, 2)
    torch.testing.assert_close(q[0, 0, :, 0], torch.tensor([[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]]))


def test_maxmin_heads_take_the_lowest_scalarised_head_per_preference_and_action() -> None:
    # two heads, one row, two preferences, two actions
    q = torch.tensor([[[[[3.0, 0.0], [1.0, 1.0]], [[3.0, 0.0], [1.0, 1.0]]],     # head 0: (K=2, A=2, m=2)
                       [[[2.0, 2.0], [0.0, 3.0]], [[2.0, 2.0], [0.0, 3.0]]]]])   # head 1
    prefs = torch.tensor([[[1.0, 0.0], [0.0, 1.0]]])
    low = ConvexQNetwork.pessimistic(q, prefs)  # (1, K, A, m)
    # w = (1, 0): action 0 -> min(3, 2) is head 1's (2, 2); action 1 -> min(1, 0) is head 1's (0, 3)
    # w = (0, 1): action 0 -> min(0, 2) is head 0's (3, 0); action 1 -> min(1, 3) is head 0's (1, 1)
    torch.testing.assert_close(low, torch.tensor([[[[2.0, 2.0], [0.0, 3.0]], [[3.0, 0.0], [1.0, 1.0]]]]))
    torch.testing.assert_close(ConvexQNetwork.pessimistic(q[:, :1], prefs), q[:, 0])  # one head: itself


def test_maxmin_network_acts_on_the_minimum_of_its_heads() -> None:
    torch.manual_seed(0)
    net = ConvexQNetwork(DST_SPACE, 4, 2, (16,), "onehot", n_components=3, n_critics=2)
    assert net.net[-1].out_features == 2 * 4 * 3 * 2
    obs, w = torch.tensor([[0, 0], [3, 5]]), torch.tensor([[0.3, 0.7], [0.8, 0.2]])
    per_head = ConvexQNetwork.select(net.components(obs), w.unsqueeze(1))[:, :, 0]  # (B, H, A, m)
    scal = (per_head * w[:, None, None]).sum(-1)  # (B, H, A)
    q = net(obs, w)
    torch.testing.assert_close((q * w[:, None]).sum(-1), scal.min(dim=1).values)


def test_joint_encoding_gives_each_cell_its_own_indicator() -> None:
    space = gym.spaces.Box(low=np.array([0, 1]), high=np.array([2, 4]), dtype=np.int64)  # 3 x 4 cells
    enc = ObsEncoder(space, "joint")
    assert enc.out_dim == 12
    x = enc(torch.tensor([[0, 1], [0, 4], [2, 4], [1, 2], [9, -3]]))  # out-of-range clamps to the edge cells
    torch.testing.assert_close(x.sum(1), torch.ones(5))
    assert x.argmax(1).tolist() == [0, 3, 11, 5, 8]
    with pytest.raises(EnvironmentError_, match="joint"):
        ObsEncoder(gym.spaces.Box(low=0.0, high=1.0, shape=(2,), dtype=np.float32), "joint")
    with pytest.raises(EnvironmentError_, match="at most"):
        ObsEncoder(gym.spaces.Box(low=0, high=1000, shape=(2,), dtype=np.int64), "joint")


def test_encoder_state_holds_only_what_earlier_checkpoints_hold() -> None:
    """Checkpoints of mope 0.2.0 hold an encoder's ``low`` and ``scale`` only: a new saved buffer would make every
    earlier checkpoint fail to load (``strides`` is derived from the space and not saved)."""
    for encoding in ("onehot", "joint", "scale"):
        assert set(ObsEncoder(DST_SPACE, encoding).state_dict()) == {"low", "scale"}


def test_convex_double_q_values_equal_the_general_path():
    """The fused n-step path (online picks the action, target reads its own preferred component) gives the same
    values and greedy actions as both networks' forward_prefs followed by eq. 4's target without an envelope."""
    from mope.agent.losses import envelope_target

    gen = torch.Generator().manual_seed(0)
    x, a, c, m, n = 7, 4, 5, 3, 6
    v_on, v_tg = torch.randn(x, 1, a, c, m, generator=gen), torch.randn(x, 1, a, c, m, generator=gen)
    prefs = torch.rand(x, n, m, generator=gen)
    prefs = prefs / prefs.sum(-1, keepdim=True)
    values, greedy = ConvexQNetwork.double_q_values(v_on[:, 0], v_tg[:, 0], prefs)
    q_on, q_tg = (ConvexQNetwork.select(v, prefs)[:, 0] for v in (v_on, v_tg))
    expect = envelope_target(q_tg, torch.zeros(x, m), torch.zeros(x), prefs, 1.0, q_select=q_on, envelope=False)
    torch.testing.assert_close(values, expect)
    torch.testing.assert_close(greedy, torch.einsum("xim,xiam->xia", prefs, q_on).argmax(dim=2))
    assert len(set(greedy.flatten().tolist())) > 1


def test_select_one_is_select_at_the_taken_action_and_trains_the_same_component() -> None:
    torch.manual_seed(0)
    v = torch.randn(16, 1, 5, 7, 3, requires_grad=True)
    prefs = torch.distributions.Dirichlet(torch.ones(3)).sample((16, 9))
    actions = torch.randint(0, 5, (16,))
    want = ConvexQNetwork.select(v, prefs)[:, 0][torch.arange(16), :, actions]  # (16, 9, 3)
    got = ConvexQNetwork.select_one(v[torch.arange(16), 0, actions], prefs)
    assert torch.equal(got, want)
    grad_want, = torch.autograd.grad(want.sum(), v)
    grad_got, = torch.autograd.grad(got.sum(), v)
    assert torch.allclose(grad_got, grad_want) and (grad_got != 0).sum() == (grad_want != 0).sum()


def test_the_fast_double_q_target_equals_the_general_envelope_target(monkeypatch) -> None:
    """The default target (convex head, double Q, no envelope) takes a one-pass path; it must give the numbers of
    the general path (forward_prefs of both networks, then losses.envelope_target)."""
    from mope import make_agent, targets

    agent = make_agent("mope", "deep-sea-treasure-v0", seed=3, eval_every=0, checkpoint_every=0, learning_starts=50)
    agent.train(400)
    c = agent.config
    batch = agent.buffer.sample(c.batch_size, agent.rng, 0.5)
    w = torch.as_tensor(agent.relabel(batch.prefs), dtype=torch.float32)
    acting = torch.as_tensor(batch.prefs, dtype=torch.float32)
    assert targets._one_pass(agent.q_net, c)
    fast = targets.one_step_target(agent.q_net, agent.target_net, agent.buffer, batch.indices, w, acting, c, scale=1.0)
    monkeypatch.setattr(targets, "_one_pass", lambda q_net, cfg: False)
    general = targets.one_step_target(agent.q_net, agent.target_net, agent.buffer, batch.indices, w, acting, c,
                                      scale=1.0)
    assert fast.shape == general.shape == w.shape
    assert torch.allclose(fast, general, atol=1e-5)


@pytest.mark.parametrize("head", ["convex", "convex2", "conditioned"])
def test_greedy_is_the_argmax_of_the_scalarised_q(head: str) -> None:
    """``greedy`` (acting, evaluation) is ``argmax_a w^T Q(s, a, w)`` of ``forward``: the convex head's one-head
    shortcut scores every (a, c) at once instead of selecting components first."""
    torch.manual_seed(3)
    space = gym.spaces.Box(low=0.0, high=1.0, shape=(4,), dtype=np.float32)
    heads = 2 if head == "convex2" else 1
    net: nn.Module = (QNetwork(space, 5, 3, (32, 32)) if head == "conditioned"
                      else ConvexQNetwork(space, 5, 3, (32, 32), n_components=6, n_critics=heads))
    obs = torch.rand(200, 4)
    w = torch.distributions.Dirichlet(torch.ones(3)).sample((200,))
    with torch.no_grad():
        want = torch.einsum("bm,bam->ba", w, net(obs, w)).argmax(dim=1)
        got = net.greedy(obs, w)
    assert got.shape == (200,) and torch.equal(got, want)
    assert len(set(got.tolist())) > 1
