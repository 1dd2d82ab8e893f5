"""A clamp whose gradient can bring saturated values back into range."""

from __future__ import annotations

import torch


class _InwardClamp(torch.autograd.Function):
    @staticmethod
    def forward(ctx, image: torch.Tensor, low: float, high: float) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(image)
        ctx.low, ctx.high = low, high
        return image.clamp(low, high)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        (image,) = ctx.saved_tensors
        # a descent step moves the input by -grad: keep only the steps that head back into range
        outward = ((image > ctx.high) & (grad < 0)) | ((image < ctx.low) & (grad > 0))
        return grad.masked_fill(outward, 0.0), None, None


def inward_clamp(image: torch.Tensor, low: float = 0.0, high: float = 1.0) -> torch.Tensor:
    """``image.clamp(low, high)`` whose backward also passes the gradient of a value beyond the
    range when following it (a descent step) moves the value back towards the range.

    A plain clamp gives saturated pixels no gradient, so a per-pixel parameter that pushed its
    pixels to white (brightness, contrast) can never bring them back: optimization is stuck
    there. The forward result is exactly the plain clamp's.

    Args:
        image: any shape.
        low, high: the range.

    Returns:
        ``image`` clamped, same shape.
    """
    if not image.requires_grad:
        return image.clamp(low, high)
    return _InwardClamp.apply(image, low, high)
