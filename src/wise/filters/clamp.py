"""A clamp whose gradient can bring saturated values back into range, for per-pixel optimization."""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from typing import Iterator

import torch

_INWARD_GRADIENTS: ContextVar[bool] = ContextVar("inward_gradients", default=False)


class _InwardClamp(torch.autograd.Function):
    @staticmethod
    def forward(ctx, image: torch.Tensor, low: float, high: float) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(image)
        ctx.low, ctx.high = low, high
        return image.clamp(low, high)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        (image,) = ctx.saved_tensors
        # a descent step moves the input by -grad. Beyond the range, a step further out changes
        # nothing in the output: it is turned back towards the range, so that a value does not
        # drift out (an optimizer's momentum would carry it) and has to come all the way back
        outward = ((image > ctx.high) & (grad < 0)) | ((image < ctx.low) & (grad > 0))
        return torch.where(outward, -grad, grad), None, None


@contextmanager
def inward_gradients(enabled: bool = True) -> Iterator[None]:
    """Within this context, :func:`inward_clamp` passes gradients back into range.

    For per-pixel parameter masks: a plain clamp gives saturated pixels no gradient, so a mask
    that pushed its region to white (brightness, contrast) can never bring it back; and a value
    beyond the range that the loss would push further out is pulled back to it instead, so that
    masks stay where they still change the picture (BENCHMARKS.md, "Colours the masks could not
    reach"). Global
    parameters do not need it: every pixel votes on them, and letting the saturated ones vote
    as if unclamped would bias them away from where the others agree.
    """
    token = _INWARD_GRADIENTS.set(enabled)
    try:
        yield
    finally:
        _INWARD_GRADIENTS.reset(token)


def inward_gradients_active() -> bool:
    """Whether :func:`inward_gradients` is in effect here."""
    return _INWARD_GRADIENTS.get()


def inward_clamp(image: torch.Tensor, low: float = 0.0, high: float = 1.0) -> torch.Tensor:
    """``image.clamp(low, high)``; within :func:`inward_gradients` its backward also passes the
    gradient of a value beyond the range when following it (a descent step) moves the value
    back towards the range, and turns it round when it would move the value further out. The
    forward result is always exactly the plain clamp's.

    Args:
        image: any shape.
        low, high: the range.

    Returns:
        ``image`` clamped, same shape.
    """
    if not (image.requires_grad and _INWARD_GRADIENTS.get()):
        return image.clamp(low, high)
    return _InwardClamp.apply(image, low, high)
