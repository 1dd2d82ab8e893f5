"""Fused CPU kernel of the sampled Sobel derivatives of :func:`wise.filters.structure.structure_tensor`.

For every pixel the eight neighbours of a 3x3 Sobel stencil, ``distance`` pixels away
(bilinear samples, borders clamped), summed with the stencil's weights for d/dx and d/dy.
Backward gives the gradients of the image (scattered into private accumulators) and of the
per-pixel distance.
"""

from __future__ import annotations

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, chunks, full, kernel_threads, reduce_to
from wise.filters.fused.bilinear import interpolate, locate, scatter, slopes


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _sobel_forward(image, distance, stencil, sum_x, sum_y):
    batch, channels, height, width = image.shape
    for row in prange(batch * height):
        b, y = row // height, row % height
        for x in range(width):
            for c in range(channels):
                sum_x[b, c, y, x] = 0.0
                sum_y[b, c, y, x] = 0.0
            reach = distance[b, 0, y, x]
            for k in range(stencil.shape[0]):
                x0, x1, fx, _ = locate(x + stencil[k, 0] * reach, width)
                y0, y1, fy, _ = locate(y + stencil[k, 1] * reach, height)
                for c in range(channels):
                    value = interpolate(image, b, c, y0, y1, x0, x1, fy, fx)
                    sum_x[b, c, y, x] += stencil[k, 2] * value
                    sum_y[b, c, y, x] += stencil[k, 3] * value


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _sobel_backward(image, distance, stencil, grad_x, grad_y, need_image, g_image_parts, g_distance):
    batch, channels, height, width = image.shape
    parts = g_image_parts.shape[0]
    rows = batch * height
    for part in prange(parts):
        g_image = g_image_parts[part]
        g_image[:] = 0.0
        for row in range(part * rows // parts, (part + 1) * rows // parts):
            b, y = row // height, row % height
            for x in range(width):
                reach = distance[b, 0, y, x]
                g_reach = 0.0
                for k in range(stencil.shape[0]):
                    dx, dy = stencil[k, 0], stencil[k, 1]
                    x0, x1, fx, clamp_x = locate(x + dx * reach, width)
                    y0, y1, fy, clamp_y = locate(y + dy * reach, height)
                    for c in range(channels):
                        g_value = stencil[k, 2] * grad_x[b, c, y, x] + stencil[k, 3] * grad_y[b, c, y, x]
                        if need_image:
                            scatter(g_image, b, c, y0, y1, x0, x1, fy, fx, g_value)
                        slope_x, slope_y = slopes(image, b, c, y0, y1, x0, x1, fy, fx)
                        g_reach += g_value * (dx * slope_x * clamp_x + dy * slope_y * clamp_y)
                g_distance[b, 0, y, x] = g_reach


class SobelTaps(torch.autograd.Function):
    """``sum_k w_x,k v_k`` and ``sum_k w_y,k v_k`` over the Sobel neighbours ``v_k`` at
    ``distance * (dx_k, dy_k)``; ``stencil`` is a ``(8, 4)`` tensor of (dx, dy, w_x, w_y)."""

    @staticmethod
    def forward(ctx, image: torch.Tensor, distance: torch.Tensor, stencil: torch.Tensor):  # type: ignore[override]
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        sum_x, sum_y = np.empty_like(pixels), np.empty_like(pixels)
        with kernel_threads():
            _sobel_forward(pixels, full(distance, (b, 1, h, w)), stencil.numpy(), sum_x, sum_y)
        ctx.save_for_backward(image, distance, stencil)
        return torch.from_numpy(sum_x), torch.from_numpy(sum_y)

    @staticmethod
    def backward(ctx, grad_x: torch.Tensor, grad_y: torch.Tensor):  # type: ignore[override]
        image, distance, stencil = ctx.saved_tensors
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        need_image = ctx.needs_input_grad[0]
        g_image_parts = np.empty((chunks(), *((b, c, h, w) if need_image else (1, 1, 1, 1))), dtype=pixels.dtype)
        g_distance = np.empty((b, 1, h, w), dtype=pixels.dtype)
        with kernel_threads():
            _sobel_backward(
                pixels,
                full(distance, (b, 1, h, w)),
                stencil.numpy(),
                full(grad_x, (b, c, h, w)),
                full(grad_y, (b, c, h, w)),
                need_image,
                g_image_parts,
                g_distance,
            )
        return (
            torch.from_numpy(g_image_parts).sum(dim=0) if need_image else None,
            reduce_to(torch.from_numpy(g_distance), distance.shape) if ctx.needs_input_grad[1] else None,
            None,
        )
