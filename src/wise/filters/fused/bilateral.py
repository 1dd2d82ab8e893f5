"""Fused CPU kernel of :class:`wise.filters.bilateral._BilateralTaps`: the samples of one pass of
the orientation-aligned bilateral filter (Kyprianidis & Döllner 2008, in the grid-sampling form
of Lötzsch et al. 2022, supplement Eq. 3-5), forward and analytic backward.

Per pixel ``p`` (colour ``I(p)``, unit direction ``u``, pixel step ``s``) and merged sample
``j = 1..n`` covering the pixel steps ``2j - 1`` and ``2j`` at the distances ``near = (2j - 1) s``
and ``far = 2j s``:

- spatial weights ``w_near = exp(near^2 a)``, ``w_far = exp(far^2 a)`` with ``a = -1 / (2 sigma_d^2)``,
  the pair's weight ``w_pair = w_near + w_far`` and its weighted mean distance
  ``d_j = (near w_near + far w_far) / w_pair`` (linear sampling: one bilinear read for two steps);
- on each side ``+-``: the bilinear sample ``v = I(p +- d_j u)`` and its range weight
  ``exp(|v - I(p)|^2 r)`` with ``r = -1 / (2 sigma_r^2)`` (Euclidean distance over channels);
- samples with ``near > support * sigma_d`` are left out, except the nearest pair (``j = 1``).

Returns ``sum w v`` (``(B, C, H, W)``) and ``sum w`` (``(B, 1, H, W)``) with
``w = w_pair * exp(|v - I(p)|^2 r)``. The spatial weights of all steps follow from one
exponential per pixel (:func:`_first_weight`). Arithmetic is in float64 between the loads and
stores of float32 arrays. Backward recomputes every sample; it gathers the
gradients of the direction, the pixel step and both coefficients per pixel and scatters the
image's gradient (through the bilinear samples and the centre pixel) into one private
accumulator per chunk of rows.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, chunks, full, kernel_threads, reduce_to
from wise.filters.fused.bilinear import interpolate, interpolate_with_slopes, locate, scatter

_MIN_PAIR_WEIGHT = 1e-30
"""Floor of ``w_near + w_far`` as on the PyTorch path: both may underflow far out in a narrow Gaussian."""

_SIDES = (1.0, -1.0)

LANES = 16
"""Neighbouring pixels of a row processed together, one step of the sample loop at a time: the
samples of one pixel form a chain (position, corners, exponential, weighted sum), and
independent chains side by side keep the processor busy (x1.3 to x1.8 on the forward)."""


@njit(inline="always")
def _first_weight(step: float, spatial_coefficient: float) -> tuple[float, float, float]:
    """``w_1``, ``w_2 / w_1`` and ``E^2`` for the spatial weights ``w_k = exp(k^2 s^2 a) = E^(k^2)`` of the
    pixel steps: ``w_(k+1) / w_k = E^(2k + 1)`` grows by ``E^2`` per step, so the weights follow by products."""
    first = math.exp(float(step) * step * spatial_coefficient)  # in float64 also for float32 maps, as the rest
    growth = first * first
    return first, growth * first, growth


@njit(inline="always")
def _pair(j: int, step: float, weight: float, ratio: float, growth: float):
    """Merged sample ``j`` from ``weight = w_(2j-1)`` and ``ratio = w_(2j) / w_(2j-1)``: ``near``, ``far``,
    ``w_near``, ``w_far``, ``w_pair``, the merged distance ``d_j``, and ``weight`` and ``ratio`` for ``j + 1``."""
    near = (2 * j - 1) * step
    far = 2 * j * step
    w_near = weight
    w_far = weight * ratio
    w_pair = max(w_near + w_far, _MIN_PAIR_WEIGHT)
    distance = (near * w_near + far * w_far) / w_pair
    return near, far, w_near, w_far, w_pair, distance, w_far * ratio * growth, ratio * growth * growth


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _forward(image, direction, step, spatial, spatial_coefficient, range_coefficient, samples, support, total, norm):
    batch, channels, height, width = image.shape
    for row in prange(batch * height):
        b, y = row // height, row % height
        # per lane: the spatial weights' recurrence, the current merged sample and its bilinear corners
        next_weight, ratio, growth = np.empty(LANES), np.empty(LANES), np.empty(LANES)
        w_pair, offset_x, offset_y = np.empty(LANES), np.empty(LANES), np.empty(LANES)
        x0s, x1s = np.empty(LANES, np.int64), np.empty(LANES, np.int64)
        y0s, y1s = np.empty(LANES, np.int64), np.empty(LANES, np.int64)
        fxs, fys, range_sq, weights = np.empty(LANES), np.empty(LANES), np.empty(LANES), np.empty(LANES)
        values, sums, weight_sums = np.empty((channels, LANES)), np.empty((channels, LANES)), np.empty(LANES)
        for start in range(0, width, LANES):
            count = min(LANES, width - start)
            for i in range(count):
                x = start + i
                next_weight[i], ratio[i], growth[i] = _first_weight(step[b, 0, y, x], spatial_coefficient[b, 0, y, x])
                weight_sums[i] = 0.0
            sums[:, :count] = 0.0
            for j in range(1, samples + 1):
                any_inside = False
                for i in range(count):
                    x = start + i
                    near, _, _, _, pair_weight, distance, next_weight[i], ratio[i] = _pair(
                        j, step[b, 0, y, x], next_weight[i], ratio[i], growth[i]
                    )
                    inside = j == 1 or near <= support * spatial[b, 0, y, x]
                    any_inside |= inside
                    w_pair[i] = pair_weight if inside else 0.0
                    offset_x[i] = distance * direction[b, 0, y, x]
                    offset_y[i] = distance * direction[b, 1, y, x]
                if not any_inside:  # the support only shrinks the farther the sample
                    break
                for sign in _SIDES:
                    for i in range(count):
                        x0s[i], x1s[i], fxs[i], _ = locate(start + i + sign * offset_x[i], width)
                        y0s[i], y1s[i], fys[i], _ = locate(y + sign * offset_y[i], height)
                        range_sq[i] = 0.0
                    for c in range(channels):
                        for i in range(count):
                            value = interpolate(image, b, c, y0s[i], y1s[i], x0s[i], x1s[i], fys[i], fxs[i])
                            values[c, i] = value
                            difference = value - image[b, c, y, start + i]
                            range_sq[i] += difference * difference
                    for i in range(count):
                        weights[i] = w_pair[i] * math.exp(range_sq[i] * range_coefficient[b, 0, y, start + i])
                        weight_sums[i] += weights[i]
                    for c in range(channels):
                        for i in range(count):
                            sums[c, i] += weights[i] * values[c, i]
            for i in range(count):
                norm[b, 0, y, start + i] = weight_sums[i]
            for c in range(channels):
                for i in range(count):
                    total[b, c, y, start + i] = sums[c, i]


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
    g_spatial_coefficient,
    g_range_coefficient,
):
    batch, channels, height, width = image.shape
    parts = g_image_parts.shape[0]
    rows = batch * height
    for part in prange(parts):
        g_image = g_image_parts[part]
        g_image[:] = 0.0
        # per lane: the recurrence and geometry of the current merged sample (inside: 1 or 0 beyond the support),
        # the gradients it gathers, the current side's bilinear corners and its sums over channels
        next_weight, ratio, growth = np.empty(LANES), np.empty(LANES), np.empty(LANES)
        w_near, w_far, w_pair = np.empty(LANES), np.empty(LANES), np.empty(LANES)
        inside, distance = np.empty(LANES), np.empty(LANES)
        g_w_pair, g_offset_x, g_offset_y = np.empty(LANES), np.empty(LANES), np.empty(LANES)
        x0s, x1s = np.empty(LANES, np.int64), np.empty(LANES, np.int64)
        y0s, y1s = np.empty(LANES, np.int64), np.empty(LANES, np.int64)
        fxs, fys, moves_x, moves_y = np.empty(LANES), np.empty(LANES), np.empty(LANES), np.empty(LANES)
        range_sq, g_weight, weights, g_per_difference = (
            np.empty(LANES),
            np.empty(LANES),
            np.empty(LANES),
            np.empty(LANES),
        )
        g_ux, g_uy, g_s = np.empty(LANES), np.empty(LANES), np.empty(LANES)
        g_a, g_r = np.empty(LANES), np.empty(LANES)
        # per channel and lane: the sample's difference to the centre, its slopes, its gradient, the centre's gradient
        differences, slopes_x, slopes_y = (
            np.empty((channels, LANES)),
            np.empty((channels, LANES)),
            np.empty((channels, LANES)),
        )
        g_values, g_centre = np.empty((channels, LANES)), np.empty((channels, LANES))
        for row in range(part * rows // parts, (part + 1) * rows // parts):
            b, y = row // height, row % height
            for start in range(0, width, LANES):
                count = min(LANES, width - start)
                for i in range(count):
                    x = start + i
                    next_weight[i], ratio[i], growth[i] = _first_weight(
                        step[b, 0, y, x], spatial_coefficient[b, 0, y, x]
                    )
                    g_ux[i] = g_uy[i] = g_s[i] = g_a[i] = g_r[i] = 0.0
                g_centre[:, :count] = 0.0
                for j in range(1, samples + 1):
                    any_inside = False
                    for i in range(count):
                        x = start + i
                        near, _, w_near[i], w_far[i], w_pair[i], distance[i], next_weight[i], ratio[i] = _pair(
                            j, step[b, 0, y, x], next_weight[i], ratio[i], growth[i]
                        )
                        is_inside = j == 1 or near <= support * spatial[b, 0, y, x]
                        any_inside |= is_inside
                        inside[i] = 1.0 if is_inside else 0.0
                        g_w_pair[i] = g_offset_x[i] = g_offset_y[i] = 0.0
                    if not any_inside:
                        break
                    for sign in _SIDES:
                        for i in range(count):
                            x = start + i
                            x0s[i], x1s[i], fxs[i], moves_x[i] = locate(
                                x + sign * distance[i] * direction[b, 0, y, x], width
                            )
                            y0s[i], y1s[i], fys[i], moves_y[i] = locate(
                                y + sign * distance[i] * direction[b, 1, y, x], height
                            )
                            range_sq[i] = 0.0
                            g_weight[i] = grad_norm[b, 0, y, x]
                        for c in range(channels):
                            for i in range(count):
                                value, slopes_x[c, i], slopes_y[c, i] = interpolate_with_slopes(
                                    image, b, c, y0s[i], y1s[i], x0s[i], x1s[i], fys[i], fxs[i]
                                )
                                difference = value - image[b, c, y, start + i]
                                differences[c, i] = difference
                                range_sq[i] += difference * difference
                                g_weight[i] += grad_total[b, c, y, start + i] * value
                        for i in range(count):
                            r = range_coefficient[b, 0, y, start + i]
                            range_weight = inside[i] * math.exp(range_sq[i] * r)
                            weights[i] = w_pair[i] * range_weight
                            g_log_range = g_weight[i] * weights[i]
                            g_r[i] += g_log_range * range_sq[i]
                            g_w_pair[i] += g_weight[i] * range_weight
                            g_per_difference[i] = 2.0 * g_log_range * r
                        for c in range(channels):
                            for i in range(count):
                                through_range = g_per_difference[i] * differences[c, i]
                                g_value = grad_total[b, c, y, start + i] * weights[i] + through_range
                                g_values[c, i] = g_value
                                g_centre[c, i] -= through_range
                                g_offset_x[i] += sign * moves_x[i] * g_value * slopes_x[c, i]
                                g_offset_y[i] += sign * moves_y[i] * g_value * slopes_y[c, i]
                        if need_image:
                            for i in range(count):
                                for c in range(channels):
                                    scatter(
                                        g_image, b, c, y0s[i], y1s[i], x0s[i], x1s[i], fys[i], fxs[i], g_values[c, i]
                                    )
                    # the chain rule through the geometry both sides share: d_j(near, far), near and far of s and a
                    for i in range(count):
                        x = start + i
                        s, a = step[b, 0, y, x], spatial_coefficient[b, 0, y, x]
                        ux, uy = direction[b, 0, y, x], direction[b, 1, y, x]
                        near, far = (2 * j - 1) * s, 2 * j * s
                        g_ux[i] += g_offset_x[i] * distance[i]
                        g_uy[i] += g_offset_y[i] * distance[i]
                        g_distance_per_pair = (g_offset_x[i] * ux + g_offset_y[i] * uy) / w_pair[i]
                        g_w_near = g_w_pair[i] + g_distance_per_pair * (near - distance[i])
                        g_w_far = g_w_pair[i] + g_distance_per_pair * (far - distance[i])
                        g_near = g_w_near * w_near[i] * 2.0 * near * a + g_distance_per_pair * w_near[i]
                        g_far = g_w_far * w_far[i] * 2.0 * far * a + g_distance_per_pair * w_far[i]
                        g_a[i] += g_w_near * w_near[i] * near * near + g_w_far * w_far[i] * far * far
                        g_s[i] += g_near * (2 * j - 1) + g_far * (2 * j)
                for i in range(count):
                    x = start + i
                    g_direction[b, 0, y, x] = g_ux[i]
                    g_direction[b, 1, y, x] = g_uy[i]
                    g_step[b, 0, y, x] = g_s[i]
                    g_spatial_coefficient[b, 0, y, x] = g_a[i]
                    g_range_coefficient[b, 0, y, x] = g_r[i]
                    if need_image:
                        for c in range(channels):
                            g_image[b, c, y, x] += g_centre[c, i]


def _kernel_inputs(inputs: tuple[torch.Tensor, ...]) -> list[np.ndarray]:
    """The image, direction and the four per-pixel maps as contiguous full-size arrays."""
    image, direction, *maps = inputs
    b, _, h, w = image.shape
    return [full(image, image.shape), full(direction, (b, 2, h, w))] + [full(m, (b, 1, h, w)) for m in maps]


class BilateralTaps(torch.autograd.Function):
    """The fused :class:`wise.filters.bilateral._BilateralTaps`; ``support`` is the cut-off in sigmas
    (:data:`wise.filters.gaussian.SUPPORT`), passed in to keep this module free of the PyTorch filters."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx, image, direction, step, spatial, neg_inv_two_spatial_sq, neg_inv_two_range_sq, n: int, support: float
    ):
        inputs = (image, direction, step, spatial, neg_inv_two_spatial_sq, neg_inv_two_range_sq)
        b, c, h, w = image.shape
        arrays = _kernel_inputs(inputs)
        total = np.empty((b, c, h, w), dtype=arrays[0].dtype)
        norm = np.empty((b, 1, h, w), dtype=arrays[0].dtype)
        with kernel_threads():
            _forward(*arrays, n, support, total, norm)
        ctx.save_for_backward(*inputs)
        ctx.n, ctx.support = n, support
        return torch.from_numpy(total), torch.from_numpy(norm)

    @staticmethod
    def backward(ctx, grad_total, grad_norm):  # type: ignore[override]
        inputs = ctx.saved_tensors
        image, direction, step, _, neg_a, neg_r = inputs
        b, c, h, w = image.shape
        arrays = _kernel_inputs(inputs)
        dtype = arrays[0].dtype
        need = ctx.needs_input_grad
        g_image_parts = np.empty((chunks(), *((b, c, h, w) if need[0] else (0, 0, 0, 0))), dtype=dtype)
        g_direction = np.empty((b, 2, h, w), dtype=dtype)
        g_step, g_a, g_r = (np.empty((b, 1, h, w), dtype=dtype) for _ in range(3))
        with kernel_threads():
            _backward(
                *arrays,
                ctx.n,
                ctx.support,
                full(grad_total, (b, c, h, w)),
                full(grad_norm, (b, 1, h, w)),
                need[0],
                g_image_parts,
                g_direction,
                g_step,
                g_a,
                g_r,
            )
        return (
            torch.from_numpy(g_image_parts).sum(dim=0) if need[0] else None,
            reduce_to(torch.from_numpy(g_direction), direction.shape) if need[1] else None,
            reduce_to(torch.from_numpy(g_step), step.shape) if need[2] else None,
            None,
            reduce_to(torch.from_numpy(g_a), neg_a.shape) if need[4] else None,
            reduce_to(torch.from_numpy(g_r), neg_r.shape) if need[5] else None,
            None,
            None,
        )
