"""Fused CPU kernel of :func:`wise.filters.structure.structure_tensor`.

For every pixel the eight neighbours of a 3x3 Sobel stencil ``d`` pixels away (bilinear samples,
borders clamped) give the derivatives of each channel, ``f_x = sum_k w_x,k v_k / d`` and
``f_y = sum_k w_y,k v_k / d``, and Di Zenzo's tensor sums their products over the channels:
``(sum_c f_x^2, sum_c f_x f_y, sum_c f_y^2)`` (Brox et al. 2006). Backward gives the gradients
of the image (scattered into private accumulators) and of the per-pixel distance ``d``.
"""

from __future__ import annotations

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, chunks, full, kernel_threads, reduce_to
from wise.filters.fused.bilinear import interpolate, locate, scatter, slopes

_TENSOR_COMPONENTS = 3
"""``(xx, xy, yy)``."""
_SIDE = 3
"""The stencil is a 3x3 grid of samples ``d`` apart..."""
_CENTRE = 1
"""...around the pixel itself, which it does not read."""


@njit  # a call, not inlined: parfor array analysis cannot unpack nested tuples
def _stencil_grid(x: int, y: int, reach: float, width: int, height: int):
    """The columns ``x - d, x, x + d`` and rows ``y - d, y, y + d`` of the stencil, located once per
    pixel: lower and upper neighbours, fractions and clamp derivatives as 3-tuples."""
    left0, left1, left_fraction, left_free = locate(x - reach, width)
    right0, right1, right_fraction, right_free = locate(x + reach, width)
    top0, top1, top_fraction, top_free = locate(y - reach, height)
    bottom0, bottom1, bottom_fraction, bottom_free = locate(y + reach, height)
    columns = (
        (left0, x, right0),
        (left1, x, right1),
        (left_fraction, 0.0, right_fraction),
        (left_free, 0.0, right_free),
    )
    rows = ((top0, y, bottom0), (top1, y, bottom1), (top_fraction, 0.0, bottom_fraction), (top_free, 0.0, bottom_free))
    return columns, rows


@njit(inline="always")
def _derivatives(image, b: int, c: int, weights, columns, rows) -> tuple[float, float]:
    """The stencil sums ``sum_k w_x,k v_k`` and ``sum_k w_y,k v_k`` of channel ``c`` of picture ``b``."""
    sum_x = 0.0
    sum_y = 0.0
    for j in range(_SIDE):
        y0, y1, fy = rows[0][j], rows[1][j], rows[2][j]
        for i in range(_SIDE):
            if i == _CENTRE and j == _CENTRE:
                continue
            x0, x1, fx = columns[0][i], columns[1][i], columns[2][i]
            value = interpolate(image, b, c, y0, y1, x0, x1, fy, fx)
            sum_x += weights[0, j, i] * value
            sum_y += weights[1, j, i] * value
    return sum_x, sum_y


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _tensor_forward(image, distance, weights, tensor):
    batch, channels, height, width = image.shape
    for row in prange(batch * height):
        b, y = row // height, row % height
        for x in range(width):
            reach = distance[b, 0, y, x]
            columns, rows = _stencil_grid(x, y, reach, width, height)
            xx = 0.0
            xy = 0.0
            yy = 0.0
            for c in range(channels):
                sum_x, sum_y = _derivatives(image, b, c, weights, columns, rows)
                fx, fy = sum_x / reach, sum_y / reach
                xx += fx * fx
                xy += fx * fy
                yy += fy * fy
            tensor[b, 0, y, x] = xx
            tensor[b, 1, y, x] = xy
            tensor[b, 2, y, x] = yy


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _tensor_backward(image, distance, weights, grad, need_image, need_distance, g_image_parts, g_distance):
    batch, channels, height, width = image.shape
    parts = g_image_parts.shape[0]
    rows_total = batch * height
    for part in prange(parts):
        g_image = g_image_parts[part]
        if need_image:
            g_image[:] = 0.0
        for row in range(part * rows_total // parts, (part + 1) * rows_total // parts):
            b, y = row // height, row % height
            for x in range(width):
                reach = distance[b, 0, y, x]
                columns, rows = _stencil_grid(x, y, reach, width, height)
                g_xx, g_xy, g_yy = grad[b, 0, y, x], grad[b, 1, y, x], grad[b, 2, y, x]
                g_reach = 0.0
                for c in range(channels):
                    sum_x, sum_y = _derivatives(image, b, c, weights, columns, rows)
                    fx, fy = sum_x / reach, sum_y / reach
                    g_fx = 2.0 * g_xx * fx + g_xy * fy
                    g_fy = g_xy * fx + 2.0 * g_yy * fy
                    g_reach -= (g_fx * fx + g_fy * fy) / reach  # through the division by d
                    g_sum_x, g_sum_y = g_fx / reach, g_fy / reach
                    for j in range(_SIDE):
                        y0, y1, wy, free_y = rows[0][j], rows[1][j], rows[2][j], rows[3][j]
                        for i in range(_SIDE):
                            if i == _CENTRE and j == _CENTRE:
                                continue
                            x0, x1, wx, free_x = columns[0][i], columns[1][i], columns[2][i], columns[3][i]
                            g_value = weights[0, j, i] * g_sum_x + weights[1, j, i] * g_sum_y
                            if need_image:
                                scatter(g_image, b, c, y0, y1, x0, x1, wy, wx, g_value)
                            if need_distance:  # through the positions of the samples, (i - 1, j - 1) * d
                                slope_x, slope_y = slopes(image, b, c, y0, y1, x0, x1, wy, wx)
                                g_reach += g_value * (
                                    (i - _CENTRE) * slope_x * free_x + (j - _CENTRE) * slope_y * free_y
                                )
                if need_distance:
                    g_distance[b, 0, y, x] = g_reach


class StructureTensor(torch.autograd.Function):
    """The structure tensor ``(B, 3, H, W)`` of ``image`` ``(B, C, H, W)`` from the Sobel neighbours
    at ``distance`` (broadcasts to ``(B, 1, H, W)``, pixels); ``weights`` ``(2, 3, 3)`` are the
    stencil's weights of d/dx and d/dy, indexed by ``(dy + 1, dx + 1)``."""

    @staticmethod
    def forward(ctx, image: torch.Tensor, distance: torch.Tensor, weights: torch.Tensor):  # type: ignore[override]
        b, _, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        tensor = np.empty((b, _TENSOR_COMPONENTS, h, w), dtype=pixels.dtype)
        with kernel_threads():
            _tensor_forward(pixels, full(distance, (b, 1, h, w)), weights.numpy(), tensor)
        ctx.save_for_backward(image, distance, weights)
        return torch.from_numpy(tensor)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, distance, weights = ctx.saved_tensors
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        need_image, need_distance = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        unused = (1, 1, 1, 1)
        g_image_parts = np.empty((chunks(), *((b, c, h, w) if need_image else unused)), dtype=pixels.dtype)
        g_distance = np.empty((b, 1, h, w) if need_distance else unused, dtype=pixels.dtype)
        with kernel_threads():
            _tensor_backward(
                pixels,
                full(distance, (b, 1, h, w)),
                weights.numpy(),
                full(grad, (b, _TENSOR_COMPONENTS, h, w)),
                need_image,
                need_distance,
                g_image_parts,
                g_distance,
            )
        return (
            torch.from_numpy(g_image_parts).sum(dim=0) if need_image else None,
            reduce_to(torch.from_numpy(g_distance), distance.shape) if need_distance else None,
            None,
        )
