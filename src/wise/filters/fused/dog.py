"""Fused CPU kernels of :mod:`wise.filters.dog`: the line-integral smoothing along the flow and
the difference of Gaussians across it.

:class:`DogTaps` sums the samples across the flow for the narrow and the wide Gaussian of
:func:`wise.filters.dog.flow_dog` (Winnemöller et al. 2012) in one pass over the pixels, with
the analytic backward of :class:`wise.filters.dog._DogTaps`.

:func:`wise.filters.dog.flow_smoothing` sums Gaussian-weighted bilinear samples along each
pixel's streamline (line integral convolution, Cabral & Leedom 1993): Euler steps of
``step_length`` pixels along the tangent, each step's tangent sampled where the last one
landed and flipped to agree with it. The PyTorch path traces every streamline as
``2 * steps`` full-image grids and sums one full-image tensor per sample; here each pixel
traces its own streamline and keeps its sums in registers. Backward traces again and gives
the gradients of the image and of the Gaussian's coefficient ``-1 / (2 sigma^2)`` (the
streamline geometry is fixed, as on the PyTorch path).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, chunks, full, kernel_threads, reduce_to
from wise.filters.fused.bilinear import interpolate, interpolate_with_slopes, locate, scatter

_MIN_TANGENT_LENGTH = 1e-6


@njit(inline="always")
def _weight_recurrence(coefficient: float, step_length: float) -> tuple[float, float, float]:
    """``w_1``, ``w_2 / w_1`` and the constant ratio of successive ratios of the weights
    ``w_k = exp((k L)^2 a)``: each next weight is a product, not an exponential."""
    unit = step_length * step_length * coefficient
    return math.exp(unit), math.exp(3.0 * unit), math.exp(2.0 * unit)


LANES = 16
"""Pixels of a row whose streamlines are traced together: each streamline is a long chain of
dependent steps (a step's heading is sampled where the last one landed), so the processor
needs several independent ones at once to keep busy."""


@njit(inline="always")
def _step(image, tangent, b, px, py, hx, hy, step_length, width, height):
    """One Euler step: the new position, its bilinear corners and the next heading."""
    px += hx * step_length
    py += hy * step_length
    x0, x1, fx, _ = locate(px, width)
    y0, y1, fy, _ = locate(py, height)
    sx = interpolate(tangent, b, 0, y0, y1, x0, x1, fy, fx)
    sy = interpolate(tangent, b, 1, y0, y1, x0, x1, fy, fx)
    flip = -1.0 if sx * hx + sy * hy < 0.0 else 1.0
    scale = flip / max(math.sqrt(sx * sx + sy * sy), _MIN_TANGENT_LENGTH)
    return px, py, x0, x1, fx, y0, y1, fy, sx * scale, sy * scale


@njit(inline="always")
def _samples_needed(sigma, b, y, start, count, steps, step_length, support) -> int:
    """Steps within the support of the widest Gaussian of a group of pixels (at least one)."""
    widest = 0.0
    for i in range(count):
        widest = max(widest, support * sigma[b, 0, y, start + i])
    needed = max(1, min(steps, int(widest / step_length)))
    # the quotient may round below a step that the comparison of each sample still takes
    while needed < steps and (needed + 1) * step_length <= widest:
        needed += 1
    return needed


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _smoothing_forward(image, tangent, sigma, coefficient, steps, step_length, support, total, norm):
    batch, channels, height, width = image.shape
    for row in prange(batch * height):
        b, y = row // height, row % height
        px, py, hx, hy = np.empty(LANES), np.empty(LANES), np.empty(LANES), np.empty(LANES)
        weight, growth, ratio_step, reach = np.empty(LANES), np.empty(LANES), np.empty(LANES), np.empty(LANES)
        sums, weight_sums = np.empty((channels, LANES)), np.empty(LANES)
        for start in range(0, width, LANES):
            count = min(LANES, width - start)
            needed = _samples_needed(sigma, b, y, start, count, steps, step_length, support)
            sums[:] = 0.0
            weight_sums[:] = 0.0
            for sign in (1.0, -1.0):
                for i in range(count):
                    x = start + i
                    px[i], py[i] = x, y
                    hx[i], hy[i] = sign * tangent[b, 0, y, x], sign * tangent[b, 1, y, x]
                    weight[i], growth[i], ratio_step[i] = _weight_recurrence(coefficient[b, 0, y, x], step_length)
                    reach[i] = support * sigma[b, 0, y, x]
                for k in range(needed):
                    distance = (k + 1) * step_length
                    for i in range(count):
                        px[i], py[i], x0, x1, fx, y0, y1, fy, hx_next, hy_next = _step(
                            image, tangent, b, px[i], py[i], hx[i], hy[i], step_length, width, height
                        )
                        hx[i], hy[i] = hx_next, hy_next
                        if k == 0 or distance <= reach[i]:
                            for c in range(channels):
                                sums[c, i] += weight[i] * interpolate(image, b, c, y0, y1, x0, x1, fy, fx)
                            weight_sums[i] += weight[i]
                        weight[i] *= growth[i]
                        growth[i] *= ratio_step[i]
            for i in range(count):
                for c in range(channels):
                    total[b, c, y, start + i] = sums[c, i]
                norm[b, 0, y, start + i] = weight_sums[i]


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _smoothing_backward(
    image, tangent, sigma, coefficient, steps, step_length, support, grad_total, grad_norm, g_image_parts, g_coefficient
):
    batch, channels, height, width = image.shape
    parts = g_image_parts.shape[0]
    rows = batch * height
    for part in prange(parts):
        g_image = g_image_parts[part]
        g_image[:] = 0.0
        px, py, hx, hy = np.empty(LANES), np.empty(LANES), np.empty(LANES), np.empty(LANES)
        weight, growth, ratio_step, reach = np.empty(LANES), np.empty(LANES), np.empty(LANES), np.empty(LANES)
        g_a = np.empty(LANES)
        for row in range(part * rows // parts, (part + 1) * rows // parts):
            b, y = row // height, row % height
            for start in range(0, width, LANES):
                count = min(LANES, width - start)
                needed = _samples_needed(sigma, b, y, start, count, steps, step_length, support)
                g_a[:] = 0.0
                for sign in (1.0, -1.0):
                    for i in range(count):
                        x = start + i
                        px[i], py[i] = x, y
                        hx[i], hy[i] = sign * tangent[b, 0, y, x], sign * tangent[b, 1, y, x]
                        weight[i], growth[i], ratio_step[i] = _weight_recurrence(coefficient[b, 0, y, x], step_length)
                        reach[i] = support * sigma[b, 0, y, x]
                    for k in range(needed):
                        distance = (k + 1) * step_length
                        for i in range(count):
                            x = start + i
                            px[i], py[i], x0, x1, fx, y0, y1, fy, hx_next, hy_next = _step(
                                image, tangent, b, px[i], py[i], hx[i], hy[i], step_length, width, height
                            )
                            hx[i], hy[i] = hx_next, hy_next
                            if k == 0 or distance <= reach[i]:
                                g_weight = grad_norm[b, 0, y, x]
                                for c in range(channels):
                                    g = grad_total[b, c, y, x]
                                    g_weight += g * interpolate(image, b, c, y0, y1, x0, x1, fy, fx)
                                    scatter(g_image, b, c, y0, y1, x0, x1, fy, fx, g * weight[i])
                                g_a[i] += g_weight * weight[i] * distance * distance
                            weight[i] *= growth[i]
                            growth[i] *= ratio_step[i]
                for i in range(count):
                    g_coefficient[b, 0, y, start + i] = g_a[i]


class FlowSmoothingTaps(torch.autograd.Function):
    """``sum_k w_k v_k`` and ``sum_k w_k`` over the samples of :func:`wise.filters.dog.flow_smoothing`
    on both streamlines of every pixel, ``w_k = exp(d_k^2 a)`` cut off beyond ``support * sigma``
    (the nearest samples always count). Gradients reach the image and ``a``."""

    @staticmethod
    def forward(ctx, image, tangent, sigma, coefficient, steps: int, step_length: float, support: float):  # type: ignore[override]
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        total = np.empty_like(pixels)
        norm = np.empty((b, 1, h, w), dtype=pixels.dtype)
        maps = [full(v.to(image.dtype), (b, 1, h, w)) for v in (sigma, coefficient)]
        with kernel_threads():
            _smoothing_forward(
                pixels, full(tangent.to(image.dtype), (b, 2, h, w)), *maps, steps, step_length, support, total, norm
            )
        ctx.save_for_backward(image, tangent, sigma, coefficient)
        ctx.settings = (steps, step_length, support)
        return torch.from_numpy(total), torch.from_numpy(norm)

    @staticmethod
    def backward(ctx, grad_total, grad_norm):  # type: ignore[override]
        image, tangent, sigma, coefficient = ctx.saved_tensors
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        need_image = ctx.needs_input_grad[0]
        g_image_parts = np.empty((chunks(), b, c, h, w), dtype=pixels.dtype)
        g_coefficient = np.empty((b, 1, h, w), dtype=pixels.dtype)
        with kernel_threads():
            _smoothing_backward(
                pixels,
                full(tangent.to(image.dtype), (b, 2, h, w)),
                *[full(v.to(image.dtype), (b, 1, h, w)) for v in (sigma, coefficient)],
                *ctx.settings,
                full(grad_total, (b, c, h, w)),
                full(grad_norm, (b, 1, h, w)),
                g_image_parts,
                g_coefficient,
            )
        return (
            torch.from_numpy(g_image_parts).sum(dim=0) if need_image else None,
            None,
            None,
            reduce_to(torch.from_numpy(g_coefficient), coefficient.shape) if ctx.needs_input_grad[3] else None,
            None,
            None,
            None,
        )


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _dog_forward(image, direction, step, wide, narrow_coefficient, wide_coefficient, steps, support, sums, norms):
    batch, channels, height, width = image.shape
    for row in prange(batch * height):
        b, y = row // height, row % height
        for x in range(width):
            for c in range(channels):
                sums[0, b, c, y, x] = 0.0
                sums[1, b, c, y, x] = 0.0
            norm_narrow = norm_wide = 0.0
            ux, uy = direction[b, 0, y, x], direction[b, 1, y, x]
            spacing, reach = step[b, 0, y, x], support * wide[b, 0, y, x]
            w_narrow, growth_narrow, ratio_narrow = _weight_recurrence(narrow_coefficient[b, 0, y, x], spacing)
            w_wide, growth_wide, ratio_wide = _weight_recurrence(wide_coefficient[b, 0, y, x], spacing)
            for i in range(1, steps + 1):
                distance = i * spacing
                if i > 1 and distance > reach:
                    break
                xa0, xa1, fxa, _ = locate(x + distance * ux, width)
                ya0, ya1, fya, _ = locate(y + distance * uy, height)
                xb0, xb1, fxb, _ = locate(x - distance * ux, width)
                yb0, yb1, fyb, _ = locate(y - distance * uy, height)
                for c in range(channels):
                    both = interpolate(image, b, c, ya0, ya1, xa0, xa1, fya, fxa) + interpolate(
                        image, b, c, yb0, yb1, xb0, xb1, fyb, fxb
                    )
                    sums[0, b, c, y, x] += w_narrow * both
                    sums[1, b, c, y, x] += w_wide * both
                norm_narrow += 2.0 * w_narrow
                norm_wide += 2.0 * w_wide
                w_narrow *= growth_narrow
                growth_narrow *= ratio_narrow
                w_wide *= growth_wide
                growth_wide *= ratio_wide
            norms[0, b, 0, y, x] = norm_narrow
            norms[1, b, 0, y, x] = norm_wide


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _dog_backward(
    image,
    direction,
    step,
    wide,
    narrow_coefficient,
    wide_coefficient,
    steps,
    support,
    grad_sums,
    grad_norms,
    need_image,
    g_image_parts,
    g_maps,
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
                a_narrow, a_wide = narrow_coefficient[b, 0, y, x], wide_coefficient[b, 0, y, x]
                spacing, reach = step[b, 0, y, x], support * wide[b, 0, y, x]
                w_narrow, growth_narrow, ratio_narrow = _weight_recurrence(a_narrow, spacing)
                w_wide, growth_wide, ratio_wide = _weight_recurrence(a_wide, spacing)
                g_norm_narrow, g_norm_wide = grad_norms[0, b, 0, y, x], grad_norms[1, b, 0, y, x]
                g_ux = g_uy = g_step = g_a_narrow = g_a_wide = 0.0
                for i in range(1, steps + 1):
                    distance = i * spacing
                    if i > 1 and distance > reach:
                        break
                    xa0, xa1, fxa, clamp_xa = locate(x + distance * ux, width)
                    ya0, ya1, fya, clamp_ya = locate(y + distance * uy, height)
                    xb0, xb1, fxb, clamp_xb = locate(x - distance * ux, width)
                    yb0, yb1, fyb, clamp_yb = locate(y - distance * uy, height)
                    g_w_narrow = 2.0 * g_norm_narrow
                    g_w_wide = 2.0 * g_norm_wide
                    g_offset_x = g_offset_y = 0.0
                    for c in range(channels):
                        g_narrow, g_wide = grad_sums[0, b, c, y, x], grad_sums[1, b, c, y, x]
                        ahead, slope_xa, slope_ya = interpolate_with_slopes(image, b, c, ya0, ya1, xa0, xa1, fya, fxa)
                        behind, slope_xb, slope_yb = interpolate_with_slopes(image, b, c, yb0, yb1, xb0, xb1, fyb, fxb)
                        g_w_narrow += g_narrow * (ahead + behind)
                        g_w_wide += g_wide * (ahead + behind)
                        g_value = g_narrow * w_narrow + g_wide * w_wide
                        if need_image:
                            scatter(g_image, b, c, ya0, ya1, xa0, xa1, fya, fxa, g_value)
                            scatter(g_image, b, c, yb0, yb1, xb0, xb1, fyb, fxb, g_value)
                        g_offset_x += g_value * (slope_xa * clamp_xa - slope_xb * clamp_xb)
                        g_offset_y += g_value * (slope_ya * clamp_ya - slope_yb * clamp_yb)
                    g_log_narrow, g_log_wide = g_w_narrow * w_narrow, g_w_wide * w_wide
                    g_a_narrow += g_log_narrow * distance * distance
                    g_a_wide += g_log_wide * distance * distance
                    g_ux += g_offset_x * distance
                    g_uy += g_offset_y * distance
                    g_distance = (
                        g_offset_x * ux
                        + g_offset_y * uy
                        + 2.0 * distance * (g_log_narrow * a_narrow + g_log_wide * a_wide)
                    )
                    g_step += g_distance * i
                    w_narrow *= growth_narrow
                    growth_narrow *= ratio_narrow
                    w_wide *= growth_wide
                    growth_wide *= ratio_wide
                g_maps[0, b, 0, y, x] = g_ux
                g_maps[1, b, 0, y, x] = g_uy
                g_maps[2, b, 0, y, x] = g_step
                g_maps[3, b, 0, y, x] = g_a_narrow
                g_maps[4, b, 0, y, x] = g_a_wide


class DogTaps(torch.autograd.Function):
    """The fused :class:`wise.filters.dog._DogTaps`: ``sum w_n v``, ``sum w_n``, ``sum w_w v`` and
    ``sum w_w`` over the samples across the flow, for the narrow and the wide Gaussian."""

    @staticmethod
    def forward(
        ctx, image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq, steps: int, support: float
    ):  # type: ignore[override]
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        sums = np.empty((2, b, c, h, w), dtype=pixels.dtype)
        norms = np.empty((2, b, 1, h, w), dtype=pixels.dtype)
        maps = [full(v.to(image.dtype), (b, 1, h, w)) for v in (step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq)]
        with kernel_threads():
            _dog_forward(pixels, full(direction, (b, 2, h, w)), *maps, steps, support, sums, norms)
        ctx.save_for_backward(image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq)
        ctx.steps, ctx.support = steps, support
        sums_t, norms_t = torch.from_numpy(sums), torch.from_numpy(norms)
        return sums_t[0], norms_t[0], sums_t[1], norms_t[1]

    @staticmethod
    def backward(ctx, g_sum_narrow, g_norm_narrow, g_sum_wide, g_norm_wide):  # type: ignore[override]
        image, direction, step, wide, neg_narrow, neg_wide = ctx.saved_tensors
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        need_image = ctx.needs_input_grad[0]
        g_image_parts = np.empty((chunks(), *((b, c, h, w) if need_image else (1, 1, 1, 1))), dtype=pixels.dtype)
        g_maps = np.empty((5, b, 1, h, w), dtype=pixels.dtype)
        grad_sums = torch.stack((g_sum_narrow.expand(b, c, h, w), g_sum_wide.expand(b, c, h, w))).contiguous()
        grad_norms = torch.stack((g_norm_narrow.expand(b, 1, h, w), g_norm_wide.expand(b, 1, h, w))).contiguous()
        maps = [full(v.to(image.dtype), (b, 1, h, w)) for v in (step, wide, neg_narrow, neg_wide)]
        with kernel_threads():
            _dog_backward(
                pixels,
                full(direction, (b, 2, h, w)),
                *maps,
                ctx.steps,
                ctx.support,
                grad_sums.numpy(),
                grad_norms.numpy(),
                need_image,
                g_image_parts,
                g_maps,
            )
        grads = torch.from_numpy(g_maps)
        wanted = ctx.needs_input_grad
        return (
            torch.from_numpy(g_image_parts).sum(dim=0) if need_image else None,
            reduce_to(grads[:2].squeeze(2).transpose(0, 1), direction.shape) if wanted[1] else None,
            reduce_to(grads[2], step.shape) if wanted[2] else None,
            None,
            reduce_to(grads[3], neg_narrow.shape) if wanted[4] else None,
            reduce_to(grads[4], neg_wide.shape) if wanted[5] else None,
            None,
            None,
        )
