"""The optimizer calls of a gradient step without torch's bookkeeping (mope.agent.optim) are torch's, bit for bit."""

from __future__ import annotations

import pytest
import torch
from torch import nn
from torch.optim import optimizer as torch_optimizer

from mope.agent import optim


def _net(seed: int) -> nn.Module:
    torch.manual_seed(seed)
    return nn.Sequential(nn.Linear(5, 16), nn.ReLU(), nn.Linear(16, 3))


def _step(net: nn.Module, opt: torch.optim.Optimizer, x: torch.Tensor, max_norm: float | None, fast: bool) -> None:
    params = list(net.parameters())
    optim.zero_grads(params) if fast else opt.zero_grad(set_to_none=True)
    (net(x) ** 2).sum().backward()
    if max_norm is not None:
        optim.clip_grad_norm(params, max_norm) if fast else nn.utils.clip_grad_norm_(params, max_norm)
    optim.adam_step(opt) if fast else opt.step()


@pytest.mark.parametrize("max_norm", [None, 0.05, 1e6])  # no clip, a clip that binds, one that does not
@pytest.mark.parametrize("weight_decay", [0.0, 0.01])
def test_fast_steps_equal_torchs_bit_for_bit(max_norm: float | None, weight_decay: float) -> None:
    nets = [_net(0), _net(0)]
    opts = [torch.optim.Adam(n.parameters(), lr=1e-2, fused=True, weight_decay=weight_decay) for n in nets]
    gen = torch.Generator().manual_seed(1)
    for i in range(6):
        x = torch.randn(32, 5, generator=gen)
        for net, opt, fast in zip(nets, opts, (False, True), strict=True):
            _step(net, opt, x, max_norm, fast)
        if i == 0:  # from the second step on, the fast path runs (the first creates the state)
            opts[1].step = lambda *a, **k: pytest.fail("adam_step fell back to Optimizer.step")
        if i == 3:  # a learning-rate change between steps is read like torch's
            for opt in opts:
                opt.param_groups[0]["lr"] = 3e-3
    for a, b in zip(nets[0].parameters(), nets[1].parameters(), strict=True):
        assert torch.equal(a, b)
        assert torch.equal(a.grad, b.grad)
    sa, sb = opts[0].state_dict()["state"], opts[1].state_dict()["state"]
    for k in sa:
        for name in ("step", "exp_avg", "exp_avg_sq"):
            assert torch.equal(sa[k][name], sb[k][name])


def test_clip_returns_the_total_norm_and_scales_to_max_norm() -> None:
    p = nn.Parameter(torch.zeros(2))
    p.grad = torch.tensor([3.0, 4.0])
    total = optim.clip_grad_norm([p], 1.0)
    assert total.item() == pytest.approx(5.0)
    torch.testing.assert_close(p.grad, torch.tensor([0.6, 0.8]), rtol=1e-5, atol=1e-6)


def test_adam_step_falls_back_to_torch_where_it_does_not_apply() -> None:
    net = _net(0)
    opt = torch.optim.Adam(net.parameters(), lr=1e-2, fused=True)
    calls = []
    opt.register_step_post_hook(lambda *_: calls.append(1))  # hooks: only Optimizer.step runs them
    (net(torch.ones(1, 5)) ** 2).sum().backward()
    optim.adam_step(opt)  # the first step (no state yet) is torch's
    optim.adam_step(opt)
    assert len(calls) == 2
    assert all(int(s["step"]) == 2 for s in opt.state.values())


def test_adam_step_runs_global_optimizer_hooks_through_torch() -> None:
    net = _net(0)
    opt = torch.optim.Adam(net.parameters(), lr=1e-2, fused=True)
    (net(torch.ones(1, 5)) ** 2).sum().backward()
    optim.adam_step(opt)
    calls = []
    handle = torch_optimizer.register_optimizer_step_post_hook(lambda *_: calls.append(1))
    try:
        optim.adam_step(opt)
    finally:
        handle.remove()
    assert calls == [1]
