"""Fused CPU kernel of :class:`wise.filters.gaussian._FixedBlurAxis`: one axis of a fixed,
symmetric Gaussian with replicated borders, and its adjoint for backward.

PyTorch's depthwise ``conv2d`` with a 1-D kernel runs at a few hundred megapixels per second
on the CPU; this loop runs at memory speed.
"""

from __future__ import annotations

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, array, kernel_threads

_COLUMN_BLOCK = 64
"""Columns per task of the vertical pass: the inner loop runs along a row (vectorised) and
the tasks split the image into independent column bands."""


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _correlate_rows(image, kernel, out):
    planes, height, width = image.shape
    taps = kernel.shape[0]
    radius = (taps - 1) // 2
    for task in prange(planes * height):
        plane, y = task // height, task % height
        row = image[plane, y]
        for x in range(width):
            total = row[0] * 0.0
            if radius <= x < width - radius:
                for k in range(taps):
                    total += kernel[k] * row[x + k - radius]
            else:
                for k in range(taps):
                    total += kernel[k] * row[min(max(x + k - radius, 0), width - 1)]
            out[plane, y, x] = total


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _correlate_rows_adjoint(grad, kernel, out):
    planes, height, width = grad.shape
    taps = kernel.shape[0]
    radius = (taps - 1) // 2
    for task in prange(planes * height):
        plane, y = task // height, task % height
        row = grad[plane, y]
        target = out[plane, y]
        target[:] = 0.0
        for x in range(width):
            for k in range(taps):
                target[min(max(x + k - radius, 0), width - 1)] += kernel[k] * row[x]


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _correlate_columns(image, kernel, out, adjoint):
    planes, height, width = image.shape
    taps = kernel.shape[0]
    radius = (taps - 1) // 2
    blocks = (width + _COLUMN_BLOCK - 1) // _COLUMN_BLOCK
    for task in prange(planes * blocks):
        plane, block = task // blocks, task % blocks
        start = block * _COLUMN_BLOCK
        stop = min(start + _COLUMN_BLOCK, width)
        out[plane, :, start:stop] = 0.0
        for y in range(height):
            for k in range(taps):
                other = min(max(y + k - radius, 0), height - 1)
                weight = kernel[k]
                if adjoint:  # scatter row y to the rows it was read from
                    for x in range(start, stop):
                        out[plane, other, x] += weight * image[plane, y, x]
                else:
                    for x in range(start, stop):
                        out[plane, y, x] += weight * image[plane, other, x]


def correlate_axis(image: torch.Tensor, kernel: torch.Tensor, axis: int, adjoint: bool = False) -> torch.Tensor:
    """``kernel`` (odd length, symmetric) correlated with ``image`` ``(B, C, H, W)`` along
    ``axis`` (3: x, 2: y), borders replicated; with ``adjoint`` the transpose of that map."""
    b, c, h, w = image.shape
    source = array(image).reshape(b * c, h, w)
    weights = array(kernel.to(image.dtype))
    out = np.empty_like(source)
    with kernel_threads():
        if axis == 3:
            (_correlate_rows_adjoint if adjoint else _correlate_rows)(source, weights, out)
        else:
            _correlate_columns(source, weights, out, adjoint)
    return torch.from_numpy(out).view(b, c, h, w)


class FixedBlurAxis(torch.autograd.Function):
    """The fused :class:`wise.filters.gaussian._FixedBlurAxis`."""

    @staticmethod
    def forward(ctx, image: torch.Tensor, kernel: torch.Tensor, axis: int) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(kernel)
        ctx.axis = axis
        return correlate_axis(image, kernel, axis)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        (kernel,) = ctx.saved_tensors
        return correlate_axis(grad, kernel, ctx.axis, adjoint=True), None, None
