"""One gradient step's optimizer calls without torch's per-call bookkeeping (issue: fast training).

``Optimizer.zero_grad``, ``nn.utils.clip_grad_norm_`` and ``Adam(fused=True).step`` each spend more time in Python
(hooks, profiler records, per-parameter checks, grouping by device) than in arithmetic on a small network: about
1.3 of the 2 ms of DST's backward-and-step. The functions here issue the same kernels with the same arguments in
the same order, so the parameters, gradients and optimizer states are bit for bit those of the torch calls
(``tests/test_optim.py``), and the optimizer object (its ``state_dict``, checkpoints, learning-rate changes)
is untouched. Anything they do not cover falls back to the torch call.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch.optim import optimizer as torch_optimizer


def zero_grads(params: Sequence[torch.Tensor]) -> None:
    """``Optimizer.zero_grad(set_to_none=True)`` for ``params``: every gradient to None."""
    for p in params:
        p.grad = None


@torch.no_grad()
def clip_grad_norm(params: Sequence[torch.Tensor], max_norm: float) -> torch.Tensor:
    """``nn.utils.clip_grad_norm_(params, max_norm)`` (2-norm, CPU or one device): the same foreach norm, total
    and scaling; returns the total norm before clipping."""
    grads = [p.grad for p in params if p.grad is not None]
    if not grads:
        return torch.tensor(0.0)
    if len({(g.device, g.dtype) for g in grads}) > 1:  # torch groups by device and dtype; so does it here
        return torch.nn.utils.clip_grad_norm_(params, max_norm)
    total = torch.linalg.vector_norm(torch.stack(torch._foreach_norm(grads, 2.0)), 2.0)
    torch._foreach_mul_(grads, torch.clamp(float(max_norm) / (total + 1e-6), max=1.0))
    return total


def adam_step(opt: torch.optim.Optimizer) -> None:
    """``opt.step()`` for a fused Adam (``torch.optim.Adam(..., fused=True)``) with one parameter group whose
    parameters all have gradients and already have state: the step counters' increment and the fused kernel, as
    torch's ``_fused_adam`` calls them. Any other case (the first step, a missing gradient, amsgrad, several
    groups or devices, step hooks on the optimizer or global ones) is ``opt.step()`` itself."""
    groups = opt.param_groups
    group = groups[0]
    if (len(groups) != 1 or not group.get("fused") or group["amsgrad"] or group.get("differentiable")
            or group.get("decoupled_weight_decay") or isinstance(group["lr"], torch.Tensor)
            or opt._optimizer_step_pre_hooks or opt._optimizer_step_post_hooks
            or torch_optimizer._global_optimizer_pre_hooks or torch_optimizer._global_optimizer_post_hooks
            or getattr(opt, "grad_scale", None) is not None or getattr(opt, "found_inf", None) is not None):
        opt.step()
        return
    params = group["params"]
    state = opt.state
    try:
        grads = [p.grad for p in params]
        states = [state[p] for p in params]
        exp_avgs = [s["exp_avg"] for s in states]
        exp_avg_sqs = [s["exp_avg_sq"] for s in states]
        steps = [s["step"] for s in states]
    except KeyError:  # the first step creates the state
        opt.step()
        return
    if any(g is None for g in grads) or len({(p.device, p.dtype) for p in params}) > 1:
        opt.step()
        return
    beta1, beta2 = group["betas"]
    with torch.no_grad():
        torch._foreach_add_(steps, 1)
        torch._fused_adam_(params, grads, exp_avgs, exp_avg_sqs, [], steps, amsgrad=False, lr=group["lr"],
                           beta1=beta1, beta2=beta2, weight_decay=group["weight_decay"], eps=group["eps"],
                           maximize=group["maximize"], grad_scale=None, found_inf=None)


def gradient_step(optimizers: Sequence[torch.optim.Optimizer], loss: torch.Tensor, clipped: Sequence[torch.Tensor],
                  max_norm: float | None) -> None:
    """Zero every optimizer's gradients, backpropagate ``loss``, clip the gradient norm of ``clipped`` to
    ``max_norm`` (None: no clip) and step each optimizer: the torch calls' kernels without their bookkeeping."""
    for opt in optimizers:
        zero_grads([p for group in opt.param_groups for p in group["params"]])
    loss.backward()
    if max_norm is not None:
        clip_grad_norm(clipped, max_norm)
    for opt in optimizers:
        adam_step(opt)
