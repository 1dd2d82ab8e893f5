"""Fused CPU kernel of the sample sums of :func:`wise.filters.log.flow_log`, the Laplacian of
Gaussian across the flow (Kyprianidis 2011).

For sample ``k`` of a pixel, ``k + 1`` pixel steps to both sides along the direction, with
``u`` the distance in sigmas, ``g = exp(-u^2 / 2)`` (0 beyond ``extent`` but for the nearest
samples) and ``g'' = (u^2 - 1) g``, the sums of ``g'' v``, ``g v`` (``v`` the two samples
added), ``2 g''``, ``2 g``, ``2 g'' u^2`` and ``2 g u^2``, as ``_log_tap`` of the PyTorch path.
Backward gives the gradients of the image, the direction, the pixel step and ``1 / sigma``.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, chunks, full, kernel_threads, reduce_to
from wise.filters.fused.bilinear import interpolate, interpolate_with_slopes, locate, scatter


@njit(inline="always")
def _gauss_recurrence(inv_sigma: float, step: float) -> tuple[float, float, float]:
    """``g_1``, ``g_2 / g_1`` and the constant ratio of successive ratios of the weights
    ``g_k = exp(-(k step / sigma)^2 / 2)``: each next weight is a product, not an exponential."""
    unit = -0.5 * (step * inv_sigma) ** 2
    return math.exp(unit), math.exp(3.0 * unit), math.exp(2.0 * unit)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _log_forward(image, direction, step, inv_sigma, steps, extent, second_v, gauss_v, moments):
    batch, channels, height, width = image.shape
    for row in prange(batch * height):
        b, y = row // height, row % height
        for x in range(width):
            for c in range(channels):
                second_v[b, c, y, x] = 0.0
                gauss_v[b, c, y, x] = 0.0
            second_sum = gauss_sum = second_u2 = gauss_u2 = 0.0
            ux, uy = direction[b, 0, y, x], direction[b, 1, y, x]
            spacing, inverse = step[b, 0, y, x], inv_sigma[b, 0, y, x]
            gauss, growth, ratio = _gauss_recurrence(inverse, spacing)
            for k in range(steps):
                distance = (k + 1) * spacing
                u = distance * inverse
                if k > 0 and u > extent:
                    break
                u_sq = u * u
                second = (u_sq - 1.0) * gauss
                xa0, xa1, fxa, _ = locate(x + distance * ux, width)
                ya0, ya1, fya, _ = locate(y + distance * uy, height)
                xb0, xb1, fxb, _ = locate(x - distance * ux, width)
                yb0, yb1, fyb, _ = locate(y - distance * uy, height)
                for c in range(channels):
                    both = interpolate(image, b, c, ya0, ya1, xa0, xa1, fya, fxa) + interpolate(
                        image, b, c, yb0, yb1, xb0, xb1, fyb, fxb
                    )
                    second_v[b, c, y, x] += second * both
                    gauss_v[b, c, y, x] += gauss * both
                second_sum += 2.0 * second
                gauss_sum += 2.0 * gauss
                second_u2 += 2.0 * second * u_sq
                gauss_u2 += 2.0 * gauss * u_sq
                gauss *= growth
                growth *= ratio
            moments[0, b, 0, y, x] = second_sum
            moments[1, b, 0, y, x] = gauss_sum
            moments[2, b, 0, y, x] = second_u2
            moments[3, b, 0, y, x] = gauss_u2


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _log_backward(
    image,
    direction,
    step,
    inv_sigma,
    steps,
    extent,
    grad_second_v,
    grad_gauss_v,
    grad_moments,
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
                s, inverse = step[b, 0, y, x], inv_sigma[b, 0, y, x]
                g_second_sum, g_gauss_sum = grad_moments[0, b, 0, y, x], grad_moments[1, b, 0, y, x]
                g_second_u2, g_gauss_u2 = grad_moments[2, b, 0, y, x], grad_moments[3, b, 0, y, x]
                g_ux = g_uy = g_step = g_inverse = 0.0
                gauss, growth, ratio = _gauss_recurrence(inverse, s)
                for k in range(steps):
                    distance = (k + 1) * s
                    u = distance * inverse
                    if k > 0 and u > extent:
                        break
                    u_sq = u * u
                    second = (u_sq - 1.0) * gauss
                    xa0, xa1, fxa, clamp_xa = locate(x + distance * ux, width)
                    ya0, ya1, fya, clamp_ya = locate(y + distance * uy, height)
                    xb0, xb1, fxb, clamp_xb = locate(x - distance * ux, width)
                    yb0, yb1, fyb, clamp_yb = locate(y - distance * uy, height)
                    g_second = 2.0 * g_second_sum + 2.0 * g_second_u2 * u_sq
                    g_gauss = 2.0 * g_gauss_sum + 2.0 * g_gauss_u2 * u_sq
                    g_offset_x = g_offset_y = 0.0
                    for c in range(channels):
                        g_s, g_g = grad_second_v[b, c, y, x], grad_gauss_v[b, c, y, x]
                        ahead, slope_xa, slope_ya = interpolate_with_slopes(image, b, c, ya0, ya1, xa0, xa1, fya, fxa)
                        behind, slope_xb, slope_yb = interpolate_with_slopes(image, b, c, yb0, yb1, xb0, xb1, fyb, fxb)
                        g_second += g_s * (ahead + behind)
                        g_gauss += g_g * (ahead + behind)
                        g_both = g_s * second + g_g * gauss
                        if need_image:
                            scatter(g_image, b, c, ya0, ya1, xa0, xa1, fya, fxa, g_both)
                            scatter(g_image, b, c, yb0, yb1, xb0, xb1, fyb, fxb, g_both)
                        g_offset_x += g_both * (slope_xa * clamp_xa - slope_xb * clamp_xb)
                        g_offset_y += g_both * (slope_ya * clamp_ya - slope_yb * clamp_yb)
                    # g'' = (u^2 - 1) g and g = exp(-u^2 / 2): back to u^2, then to u
                    g_gauss_total = g_gauss + g_second * (u_sq - 1.0)
                    g_u_sq = (
                        2.0 * g_second_u2 * second
                        + 2.0 * g_gauss_u2 * gauss
                        + g_second * gauss
                        - 0.5 * g_gauss_total * gauss
                    )
                    g_u = 2.0 * u * g_u_sq
                    g_distance = g_u * inverse + g_offset_x * ux + g_offset_y * uy
                    g_inverse += g_u * distance
                    g_ux += g_offset_x * distance
                    g_uy += g_offset_y * distance
                    g_step += g_distance * (k + 1)
                    gauss *= growth
                    growth *= ratio
                g_maps[0, b, 0, y, x] = g_ux
                g_maps[1, b, 0, y, x] = g_uy
                g_maps[2, b, 0, y, x] = g_step
                g_maps[3, b, 0, y, x] = g_inverse


class LogTaps(torch.autograd.Function):
    """The six sums of ``_log_tap`` over ``steps`` samples; see the module docstring."""

    @staticmethod
    def forward(ctx, image, direction, step, inv_sigma, steps: int, extent: float):  # type: ignore[override]
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        second_v, gauss_v = np.empty_like(pixels), np.empty_like(pixels)
        moments = np.empty((4, b, 1, h, w), dtype=pixels.dtype)
        with kernel_threads():
            _log_forward(
                pixels,
                full(direction.to(image.dtype), (b, 2, h, w)),
                full(step.to(image.dtype), (b, 1, h, w)),
                full(inv_sigma.to(image.dtype), (b, 1, h, w)),
                steps,
                extent,
                second_v,
                gauss_v,
                moments,
            )
        ctx.save_for_backward(image, direction, step, inv_sigma)
        ctx.steps, ctx.extent = steps, extent
        sums = torch.from_numpy(moments)
        return (torch.from_numpy(second_v), torch.from_numpy(gauss_v), *sums.unbind(0))

    @staticmethod
    def backward(ctx, grad_second_v, grad_gauss_v, *grad_moments):  # type: ignore[override]
        image, direction, step, inv_sigma = ctx.saved_tensors
        b, c, h, w = image.shape
        pixels = np.ascontiguousarray(image.detach().numpy())
        need_image = ctx.needs_input_grad[0]
        g_image_parts = np.empty((chunks(), *((b, c, h, w) if need_image else (1, 1, 1, 1))), dtype=pixels.dtype)
        g_maps = np.empty((4, b, 1, h, w), dtype=pixels.dtype)
        moments = torch.stack([g.expand(b, 1, h, w) for g in grad_moments]).contiguous().numpy()
        with kernel_threads():
            _log_backward(
                pixels,
                full(direction.to(image.dtype), (b, 2, h, w)),
                full(step.to(image.dtype), (b, 1, h, w)),
                full(inv_sigma.to(image.dtype), (b, 1, h, w)),
                ctx.steps,
                ctx.extent,
                full(grad_second_v, (b, c, h, w)),
                full(grad_gauss_v, (b, c, h, w)),
                moments,
                need_image,
                g_image_parts,
                g_maps,
            )
        g_direction = torch.from_numpy(g_maps[:2]).squeeze(2).transpose(0, 1)
        wanted = ctx.needs_input_grad
        return (
            torch.from_numpy(g_image_parts).sum(dim=0) if need_image else None,
            reduce_to(g_direction, direction.shape) if wanted[1] else None,
            reduce_to(torch.from_numpy(g_maps[2]), step.shape) if wanted[2] else None,
            reduce_to(torch.from_numpy(g_maps[3]), inv_sigma.shape) if wanted[3] else None,
            None,
            None,
        )
