"""Per-pixel operations in Dr.Jit, differentiated by Dr.Jit's automatic differentiation.

A chain of per-pixel arithmetic (a colour conversion, a threshold, a blend) costs PyTorch one
full-image tensor per step; traced by Dr.Jit it is one kernel that reads each input once and
writes each output once. Its backward is per pixel too (the adjoint of a per-pixel function
needs no scatter), so Dr.Jit's automatic differentiation is as fast as a hand-written one.

:func:`apply` takes a function of channel planes (one flat Dr.Jit array per channel of every
input) that returns the output's channel planes. Inputs are ``(B, C, H, W)`` images or maps of one
value per picture ``(B, C, 1, 1)`` (a batch of 1 broadcasts), which enter as single values.
"""

from __future__ import annotations

from typing import Callable, Sequence

import drjit as dr
import torch

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import kernel_threads

Planes = list
PlaneFunction = Callable[..., Sequence[object]]


def _ad_type(dtype: torch.dtype):
    import drjit.llvm.ad as backend

    return backend.Float64 if dtype == torch.float64 else backend.Float32


_ALIGNMENT = 64
"""Bytes to which a plane's memory is aligned: Dr.Jit's code for reading an array depends on the
alignment of its address, so planes at other offsets would compile the kernel again."""


def _plane(value: torch.Tensor, Float):
    """A contiguous tensor as a flat array sharing its memory, copied where it is not aligned."""
    value = value.contiguous().view(-1)
    if value.data_ptr() % _ALIGNMENT:
        value = value.clone()
    return Float(value)


def _planes(tensor: torch.Tensor, size: tuple[int, int, int], Float) -> Planes:
    """A tensor's channels as flat arrays over ``size`` (B, H, W) pixels: a single value where the
    tensor holds one for all pixels, else one per pixel (shared with the tensor where contiguous)."""
    batch, height, width = size
    value = tensor.detach()
    if value.shape[0] == 1 and value.shape[-1] * value.shape[-2] == 1:
        return [Float(value[0, c].reshape(1)) for c in range(value.shape[1])]
    value = value.expand(batch, -1, height, width)
    return [_plane(value[:, c], Float) for c in range(value.shape[1])]


def _tensor(planes: Sequence[object], size: tuple[int, int, int]) -> torch.Tensor:
    """Evaluated planes stacked as ``(B, C, H, W)``, or ``(1, C, 1, 1)`` when each is a single value
    (the gradient of an input that was one)."""
    if all(dr.width(p) == 1 for p in planes):
        return torch.stack([p.torch().view(1, 1, 1) for p in planes], dim=1)
    return torch.stack(
        [p.torch().view(1, 1, 1).expand(size) if dr.width(p) == 1 else p.torch().view(size) for p in planes], dim=1
    )


class _Pointwise(torch.autograd.Function):
    @staticmethod
    def forward(ctx, function: PlaneFunction, size: tuple[int, int, int], *inputs: torch.Tensor):  # type: ignore[override]
        Float = _ad_type(inputs[0].dtype)
        with kernel_threads():
            outputs = list(function(*[_planes(x, size, Float) for x in inputs]))
            dr.eval(*outputs)
            result = _tensor(outputs, size)
        ctx.function, ctx.size = function, size
        ctx.save_for_backward(*inputs)
        return result

    @staticmethod
    def backward(ctx, grad_output: torch.Tensor):  # type: ignore[override]
        inputs = ctx.saved_tensors
        Float = _ad_type(inputs[0].dtype)
        wanted = ctx.needs_input_grad[2:]
        with kernel_threads():
            planes = [_planes(x, ctx.size, Float) for x in inputs]
            for x_planes, want in zip(planes, wanted):
                if want:
                    dr.enable_grad(*x_planes)
            outputs = list(ctx.function(*planes))
            for c, output in enumerate(outputs):
                if dr.grad_enabled(output):
                    dr.set_grad(output, _plane(grad_output[:, c], Float))
            dr.enqueue(dr.ADMode.Backward, *outputs)
            dr.traverse(dr.ADMode.Backward)
            grads = [[dr.grad(p) for p in x_planes] if want else None for x_planes, want in zip(planes, wanted)]
            dr.eval(*[g for x_grads in grads if x_grads for g in x_grads])
            results = [
                reduce_to(_tensor(x_grads, ctx.size), x.shape) if x_grads is not None else None
                for x_grads, x in zip(grads, inputs)
            ]
        return (None, None, *results)


def apply(function: PlaneFunction, *inputs: torch.Tensor) -> torch.Tensor:
    """``function`` of the inputs' channel planes, returning ``(B, C_out, H, W)``; the first input
    is an image and gives the batch and size."""
    batch, _, height, width = inputs[0].shape
    return _Pointwise.apply(function, (batch, height, width), *inputs)
