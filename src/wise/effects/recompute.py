"""Recompute a pipeline stage during backward instead of keeping its intermediate tensors.

A small stand-in for :func:`torch.utils.checkpoint.checkpoint` (which imports the compiler
stack on first use, a second or two per process): forward runs the stage without autograd
and keeps only its inputs; backward runs it again with autograd and differentiates it.
"""

from __future__ import annotations

import contextvars
from typing import Any, Callable

import torch


class _Recompute(torch.autograd.Function):
    @staticmethod
    def forward(ctx, run: Callable[..., torch.Tensor], *tensors: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        ctx.run = run
        ctx.context = contextvars.copy_context()  # recompute under the settings of the forward pass
        ctx.save_for_backward(*tensors)
        return run(*tensors)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        tensors = ctx.saved_tensors
        wanted = ctx.needs_input_grad[1:]
        leaves = [t.detach().requires_grad_(w) for t, w in zip(tensors, wanted)]
        with torch.enable_grad():
            output = ctx.context.run(ctx.run, *leaves)
        targets = [t for t, w in zip(leaves, wanted) if w]
        grads = iter(torch.autograd.grad(output, targets, grad, allow_unused=True) if targets else ())
        return (None, *[next(grads) if w else None for w in wanted])


def recompute(fn: Callable[..., torch.Tensor], *args: Any, **kwargs: Any) -> torch.Tensor:
    """``fn(*args, **kwargs)``, keeping only its tensor arguments for backward."""
    if not torch.is_grad_enabled():
        return fn(*args, **kwargs)
    slots = list(args) + list(kwargs.values())
    positions = [i for i, value in enumerate(slots) if isinstance(value, torch.Tensor)]
    names = list(kwargs)

    def run(*tensors: torch.Tensor) -> torch.Tensor:
        filled = list(slots)
        for i, t in zip(positions, tensors):
            filled[i] = t
        return fn(*filled[: len(args)], **dict(zip(names, filled[len(args) :])))

    return _Recompute.apply(run, *[slots[i] for i in positions])
