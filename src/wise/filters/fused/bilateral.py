"""Fused CPU kernel of the backward pass of :class:`wise.filters.bilateral._BilateralTaps`, the
samples of one pass of the orientation-aligned bilateral filter (Kyprianidis & Döllner 2008, in
the grid-sampling form of the WISE supplement, Eq. 3-5). Its forward stays on the PyTorch path:
vectorised whole-image sampling was as fast as a scalar loop over pixels on the CPU, but the
backward, which recomputes every sample and scatters into the image, is faster fused.

Per pixel ``p`` and merged sample ``j`` (pixel steps ``2j - 1`` and ``2j`` at ``near`` and
``far`` = those steps times the pixel step): spatial weights ``w = exp(d^2 a)`` with
``a = -1 / (2 sigma_d^2)``, the pair's weight ``w_near + w_far`` at their weighted mean distance
``d_j``, one bilinear sample ``v`` at ``p +- d_j u`` on each side (``u`` the direction) and the
range weight ``exp(|v - I(p)|^2 r)`` with ``r = -1 / (2 sigma_r^2)``. Returns
``sum w v`` and ``sum w``.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, chunks, full, kernel_threads, reduce_to
from wise.filters.fused.bilinear import interpolate, locate, scatter, slopes

_MIN_PAIR_WEIGHT = 1e-30


@njit(inline="always")
def _pair(j: int, step: float, spatial_coefficient: float):
    """Distances, spatial weights and the merged distance of merged sample ``j``."""
    near = (2 * j - 1) * step
    far = 2 * j * step
    w_near = math.exp(near * near * spatial_coefficient)
    w_far = math.exp(far * far * spatial_coefficient)
    w_pair = max(w_near + w_far, _MIN_PAIR_WEIGHT)
    return near, far, w_near, w_far, w_pair, (near * w_near + far * w_far) / w_pair


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _backward(
    image,
    direction,
    step,
    spatial,
    spatial_coefficient,
    range_coefficient,
    samples,
    support,
    grad_total,
    grad_norm,
    need_image,
    g_image_parts,
    g_direction,
    g_step,
    g_spatial,
    g_range,
):
    batch, channels, height, width = image.shape
    parts = g_image_parts.shape[0]
    rows = batch * height
    for part in prange(parts):
        g_image = g_image_parts[part]
        g_image[:] = 0.0
        for row in range(part * rows // parts, (part + 1) * rows // parts):
            b, y = row // height, row % height
            for x in range(width):
                ux, uy = direction[b, 0, y, x], direction[b, 1, y, x]
                a, r = spatial_coefficient[b, 0, y, x], range_coefficient[b, 0, y, x]
                reach = support * spatial[b, 0, y, x]
                g_norm = grad_norm[b, 0, y, x]
                g_ux = g_uy = g_a = g_r = g_s = 0.0
                for j in range(1, samples + 1):
                    near, far, w_near, w_far, w_pair, distance = _pair(j, step[b, 0, y, x], a)
                    if j > 1 and near > reach:
                        continue
                    g_w_pair = 0.0
                    g_offset_x = g_offset_y = 0.0
                    for sign in (1.0, -1.0):
                        x0, x1, fx, clamp_x = locate(x + sign * distance * ux, width)
                        y0, y1, fy, clamp_y = locate(y + sign * distance * uy, height)
                        range_sq = 0.0
                        g_weight = g_norm
                        for c in range(channels):
                            value = interpolate(image, b, c, y0, y1, x0, x1, fy, fx)
                            difference = value - image[b, c, y, x]
                            range_sq += difference * difference
                            g_weight += grad_total[b, c, y, x] * value
                        range_weight = math.exp(range_sq * r)
                        weight = w_pair * range_weight
                        g_log_range = g_weight * weight
                        g_r += g_log_range * range_sq
                        g_w_pair += g_weight * range_weight
                        for c in range(channels):
                            difference = interpolate(image, b, c, y0, y1, x0, x1, fy, fx) - image[b, c, y, x]
                            through_range = 2.0 * g_log_range * r * difference
                            g_value = grad_total[b, c, y, x] * weight + through_range
                            if need_image:
                                g_image[b, c, y, x] -= through_range
                                scatter(g_image, b, c, y0, y1, x0, x1, fy, fx, g_value)
                            slope_x, slope_y = slopes(image, b, c, y0, y1, x0, x1, fy, fx)
                            g_offset_x += sign * g_value * slope_x * clamp_x
                            g_offset_y += sign * g_value * slope_y * clamp_y
                    # the chain rule through the sample geometry that both sides share
                    g_ux += g_offset_x * distance
                    g_uy += g_offset_y * distance
                    g_distance_per_pair = (g_offset_x * ux + g_offset_y * uy) / w_pair
                    g_w_near = g_w_pair + g_distance_per_pair * (near - distance)
                    g_w_far = g_w_pair + g_distance_per_pair * (far - distance)
                    g_near = g_w_near * w_near * 2.0 * near * a + g_distance_per_pair * w_near
                    g_far = g_w_far * w_far * 2.0 * far * a + g_distance_per_pair * w_far
                    g_a += g_w_near * w_near * near * near + g_w_far * w_far * far * far
                    g_s += g_near * (2 * j - 1) + g_far * (2 * j)
                g_direction[b, 0, y, x] = g_ux
                g_direction[b, 1, y, x] = g_uy
                g_step[b, 0, y, x] = g_s
                g_spatial[b, 0, y, x] = g_a
                g_range[b, 0, y, x] = g_r


def _maps(image: torch.Tensor, *values: torch.Tensor) -> list[np.ndarray]:
    b, _, h, w = image.shape
    return [full(v.to(image.dtype), (b, 1, h, w)) for v in values]


def bilateral_taps_backward(
    inputs: tuple[torch.Tensor, ...],
    n: int,
    support: float,
    grad_total: torch.Tensor,
    grad_norm: torch.Tensor,
    needs_input_grad: tuple[bool, ...],
) -> tuple[torch.Tensor | None, ...]:
    """The gradients of :class:`wise.filters.bilateral._BilateralTaps` for its saved ``inputs``
    (image, direction, step, spatial, spatial and range coefficients), in the order of its inputs."""
    image, direction, step, spatial, neg_a, neg_r = inputs
    b, c, h, w = image.shape
    pixels = np.ascontiguousarray(image.detach().numpy())
    need_image = needs_input_grad[0]
    g_image_parts = np.empty((chunks(), *((b, c, h, w) if need_image else (1, 1, 1, 1))), dtype=pixels.dtype)
    g_direction = np.empty((b, 2, h, w), dtype=pixels.dtype)
    g_step, g_a, g_r = (np.empty((b, 1, h, w), dtype=pixels.dtype) for _ in range(3))
    with kernel_threads():
        _backward(
            pixels,
            full(direction, (b, 2, h, w)),
            *_maps(image, step, spatial, neg_a, neg_r),
            n,
            support,
            full(grad_total, (b, c, h, w)),
            full(grad_norm, (b, 1, h, w)),
            need_image,
            g_image_parts,
            g_direction,
            g_step,
            g_a,
            g_r,
        )
    return (
        torch.from_numpy(g_image_parts).sum(dim=0) if need_image else None,
        reduce_to(torch.from_numpy(g_direction), direction.shape) if needs_input_grad[1] else None,
        reduce_to(torch.from_numpy(g_step), step.shape) if needs_input_grad[2] else None,
        None,
        reduce_to(torch.from_numpy(g_a), neg_a.shape) if needs_input_grad[4] else None,
        reduce_to(torch.from_numpy(g_r), neg_r.shape) if needs_input_grad[5] else None,
        None,
    )
