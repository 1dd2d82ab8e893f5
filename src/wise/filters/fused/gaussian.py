"""Fused CPU kernel of :class:`wise.filters.gaussian._FixedBlurAxis`: one axis of a fixed,
symmetric Gaussian with replicated borders, and its adjoint for backward.

PyTorch's depthwise ``conv2d`` with a 1-D kernel runs at a few hundred megapixels per second
on the CPU; this loop runs at memory speed.
"""

from __future__ import annotations

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, array, kernel_threads, reduce_to

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


@njit(inline="always")
def _clamp(index: int, size: int) -> int:
    return min(max(index, 0), size - 1)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _varying_lines(image, sigma, radius, support, out):
    """Blur each line (the last axis) of ``image`` ``(B, C, L, N)`` with the per-pixel ``sigma``
    ``(B, 1, L, N)``: ``sum_k w_k v_(n+k) / sum_k w_k``, ``w_k = exp(-k^2 / (2 sigma^2))`` for
    ``|k| <= 1`` or ``|k| <= support * sigma`` (``|k| <= radius``), borders replicated."""
    batch, channels, lines, size = image.shape
    for task in prange(batch * lines):
        b, line = task // lines, task % lines
        for n in range(size):
            deviation = sigma[b, 0, line, n]
            reach = support * deviation
            first = np.exp(-0.5 / (deviation * deviation))  # w_1; w_k = w_(k-1) * first * step^(k-1)
            step = first * first
            for c in range(channels):
                values = image[b, c, line]
                total = values[n]
                norm = 1.0
                weight = 1.0
                ratio = first
                for k in range(1, radius + 1):
                    if k > 1 and k > reach:
                        break
                    weight *= ratio
                    ratio *= step
                    total += weight * (values[_clamp(n - k, size)] + values[_clamp(n + k, size)])
                    norm += 2.0 * weight
                out[b, c, line, n] = total / norm


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _varying_lines_adjoint(image, sigma, radius, support, grad, g_image, g_sigma):
    """Gradients of :func:`_varying_lines`: ``g_image`` scattered along each line (one task owns a
    line) and ``g_sigma = sum_c g_c / (N sigma^3) * sum_k k^2 w_k (v_(n+k) - out)``."""
    batch, channels, lines, size = image.shape
    for task in prange(batch * lines):
        b, line = task // lines, task % lines
        for c in range(channels):
            g_image[b, c, line, :] = 0.0
        for n in range(size):
            deviation = sigma[b, 0, line, n]
            reach = support * deviation
            first = np.exp(-0.5 / (deviation * deviation))
            step = first * first
            g_deviation = 0.0
            for c in range(channels):
                values = image[b, c, line]
                g_values = g_image[b, c, line]
                total = values[n]
                spread = 0.0  # sum_k k^2 w_k v_(n+k)
                norm = 1.0
                moment = 0.0  # sum_k k^2 w_k
                weight = 1.0
                ratio = first
                for k in range(1, radius + 1):
                    if k > 1 and k > reach:
                        break
                    weight *= ratio
                    ratio *= step
                    pair = values[_clamp(n - k, size)] + values[_clamp(n + k, size)]
                    total += weight * pair
                    norm += 2.0 * weight
                    spread += k * k * weight * pair
                    moment += 2.0 * k * k * weight
                g_total = grad[b, c, line, n] / norm
                g_deviation += g_total * (spread - total / norm * moment)
                g_values[n] += g_total
                weight = 1.0
                ratio = first
                for k in range(1, radius + 1):
                    if k > 1 and k > reach:
                        break
                    weight *= ratio
                    ratio *= step
                    g_values[_clamp(n - k, size)] += g_total * weight
                    g_values[_clamp(n + k, size)] += g_total * weight
            g_sigma[b, 0, line, n] = g_deviation / (deviation * deviation * deviation)


def _lines(tensor: torch.Tensor, axis: int) -> np.ndarray:
    """A ``(B, C, H, W)`` tensor with the lines along ``axis`` contiguous on its last axis: the
    tensor itself for x, a transposed copy for y (the kernels then read and scatter along rows)."""
    return array(tensor if axis == 3 else tensor.transpose(2, 3))


def _from_lines(lines: np.ndarray, axis: int) -> torch.Tensor:
    """The inverse of :func:`_lines`."""
    tensor = torch.from_numpy(lines)
    return tensor if axis == 3 else tensor.transpose(2, 3).contiguous()


class VaryingBlurAxis(torch.autograd.Function):
    """The fused :func:`wise.filters.gaussian._blur_axis_varying`: one axis (3: x, 2: y) of a Gaussian
    whose ``sigma`` (pixels, broadcasts to ``(B, 1, H, W)``) varies per pixel, cut off at ``support``
    sigma but always reaching the nearest neighbours, at most ``radius`` pixels; borders replicated."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx, image: torch.Tensor, sigma: torch.Tensor, axis: int, radius: int, support: float
    ) -> torch.Tensor:
        b, _, h, w = image.shape
        pixels = _lines(image, axis)
        out = np.empty_like(pixels)
        with kernel_threads():
            _varying_lines(pixels, _lines(sigma.expand(b, 1, h, w), axis), radius, support, out)
        ctx.save_for_backward(image, sigma)
        ctx.axis, ctx.radius, ctx.support = axis, radius, support
        return _from_lines(out, axis)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, sigma = ctx.saved_tensors
        b, _, h, w = image.shape
        axis = ctx.axis
        pixels = _lines(image, axis)
        g_image = np.empty_like(pixels)
        g_sigma = np.empty((b, 1, *pixels.shape[2:]), dtype=pixels.dtype)
        with kernel_threads():
            _varying_lines_adjoint(
                pixels,
                _lines(sigma.expand(b, 1, h, w), axis),
                ctx.radius,
                ctx.support,
                _lines(grad, axis),
                g_image,
                g_sigma,
            )
        return (
            _from_lines(g_image, axis) if ctx.needs_input_grad[0] else None,
            reduce_to(_from_lines(g_sigma, axis), sigma.shape) if ctx.needs_input_grad[1] else None,
            None,
            None,
            None,
        )
