"""Fused CPU kernels of :mod:`wise.filters.watercolor`: the wet-in-wet bleeding and the gaps and
overlaps at edges, each forward and analytic backward in one loop over pixels.

Both sample the image bilinearly (border clamped, as ``grid_sample``) at offsets along a
per-pixel direction. The PyTorch path builds a full-image sampling grid and a full-image sample
per offset, and its backward goes through ``grid_sample``'s backward once per sample; here every
pixel reads its samples and keeps its sums in registers, and backward scatters the image's
gradient into one private accumulator per thread (summed in a fixed order).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, chunks, full, kernel_threads, reduce_to
from wise.filters.fused.bilinear import interpolate, interpolate_with_slopes, locate, scatter, slopes


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _wet_forward(image, step, edges, weights, out):
    """``out = C + e (bled - C)``, ``bled = (w_0 C + sum_j w_j (C(p + j s) + C(p - j s))) / W`` with
    ``W = w_0 + 2 sum_j w_j``, for ``image`` ``(B, C, H, W)``, ``step`` ``s`` ``(B, 2, H, W)``, ``edges``
    ``e`` ``(B, 1, H, W)`` and ``weights`` ``w_0 .. w_n``."""
    batch, channels, height, width = image.shape
    samples = weights.shape[0] - 1
    weight_total = weights[0] + 2.0 * weights[1:].sum()
    for task in prange(batch * height):
        b, y = task // height, task % height
        sums = np.empty(channels, dtype=image.dtype)
        for x in range(width):
            sx, sy = step[b, 0, y, x], step[b, 1, y, x]
            sums[:] = 0.0
            for j in range(1, samples + 1):
                weight = weights[j]
                xa0, xa1, fxa, _ = locate(x + j * sx, width)
                ya0, ya1, fya, _ = locate(y + j * sy, height)
                xb0, xb1, fxb, _ = locate(x - j * sx, width)
                yb0, yb1, fyb, _ = locate(y - j * sy, height)
                for c in range(channels):
                    sums[c] += weight * (
                        interpolate(image, b, c, ya0, ya1, xa0, xa1, fya, fxa)
                        + interpolate(image, b, c, yb0, yb1, xb0, xb1, fyb, fxb)
                    )
            blend = edges[b, 0, y, x]
            for c in range(channels):
                value = image[b, c, y, x]
                bled = (value * weights[0] + sums[c]) / weight_total
                out[b, c, y, x] = value + blend * (bled - value)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _wet_backward(image, step, edges, weights, grad, g_image_parts, g_step, g_edges):
    """Gradients of :func:`_wet_forward`: the image's (the centre term gathered, the samples
    scattered into part ``k`` of ``g_image_parts`` ``(K, B, C, H, W)`` for the rows of part ``k``),
    the step's ``sum_j j w_j sum_c g_c e / W (dC/dx(p + j s) - dC/dx(p - j s))`` (zero along a
    clamped coordinate) and the edges' ``sum_c g_c (bled_c - C_c)``."""
    batch, channels, height, width = image.shape
    samples = weights.shape[0] - 1
    weight_total = weights[0] + 2.0 * weights[1:].sum()
    parts = g_image_parts.shape[0]
    tasks = batch * height
    for part in prange(parts):
        g_image = g_image_parts[part]
        g_image[:] = 0.0
        sums = np.empty(channels, dtype=image.dtype)
        g_sums = np.empty(channels, dtype=image.dtype)
        for task in range(part * tasks // parts, (part + 1) * tasks // parts):
            b, y = task // height, task % height
            for x in range(width):
                sx, sy = step[b, 0, y, x], step[b, 1, y, x]
                blend = edges[b, 0, y, x]
                for c in range(channels):
                    sums[c] = 0.0
                    g_sums[c] = grad[b, c, y, x] * blend / weight_total
                g_sx = g_sy = 0.0
                for j in range(1, samples + 1):
                    weight = weights[j]
                    xa0, xa1, fxa, moves_xa = locate(x + j * sx, width)
                    ya0, ya1, fya, moves_ya = locate(y + j * sy, height)
                    xb0, xb1, fxb, moves_xb = locate(x - j * sx, width)
                    yb0, yb1, fyb, moves_yb = locate(y - j * sy, height)
                    ahead_x = ahead_y = behind_x = behind_y = 0.0
                    for c in range(channels):
                        g_sample = g_sums[c] * weight
                        ahead, slope_xa, slope_ya = interpolate_with_slopes(image, b, c, ya0, ya1, xa0, xa1, fya, fxa)
                        behind, slope_xb, slope_yb = interpolate_with_slopes(image, b, c, yb0, yb1, xb0, xb1, fyb, fxb)
                        sums[c] += weight * (ahead + behind)
                        scatter(g_image, b, c, ya0, ya1, xa0, xa1, fya, fxa, g_sample)
                        scatter(g_image, b, c, yb0, yb1, xb0, xb1, fyb, fxb, g_sample)
                        ahead_x += g_sample * slope_xa
                        ahead_y += g_sample * slope_ya
                        behind_x += g_sample * slope_xb
                        behind_y += g_sample * slope_yb
                    g_sx += j * (ahead_x * moves_xa - behind_x * moves_xb)
                    g_sy += j * (ahead_y * moves_ya - behind_y * moves_yb)
                g_blend = 0.0
                for c in range(channels):
                    value = image[b, c, y, x]
                    g = grad[b, c, y, x]
                    bled = (value * weights[0] + sums[c]) / weight_total
                    g_blend += g * (bled - value)
                    g_image[b, c, y, x] += g * (1.0 - blend) + g_sums[c] * weights[0]
                g_step[b, 0, y, x] = g_sx
                g_step[b, 1, y, x] = g_sy
                g_edges[b, 0, y, x] = g_blend


class WetInWet(torch.autograd.Function):
    """:func:`wise.filters.watercolor.wet_in_wet` once the step ``(B, 2, H, W)`` between samples
    (direction times spacing, pixels) and the blend map ``edges`` (broadcasting to ``(B, 1, H, W)``)
    are known; ``weights`` are the Gaussian weights ``w_0 .. w_n`` of the samples. Gradients reach
    the image, the step and the edges."""

    @staticmethod
    def forward(ctx, image: torch.Tensor, step: torch.Tensor, edges: torch.Tensor, weights: Sequence[float]):  # type: ignore[override]
        b, c, h, w = image.shape
        pixels = full(image, image.shape)
        weight_array = np.asarray(weights, dtype=pixels.dtype)
        out = np.empty_like(pixels)
        with kernel_threads():
            _wet_forward(pixels, full(step, (b, 2, h, w)), full(edges, (b, 1, h, w)), weight_array, out)
        ctx.save_for_backward(image, step, edges)
        ctx.weights = weight_array
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, step, edges = ctx.saved_tensors
        b, c, h, w = image.shape
        pixels = full(image, image.shape)
        g_image_parts = np.empty((chunks(), b, c, h, w), dtype=pixels.dtype)
        g_step = np.empty((b, 2, h, w), dtype=pixels.dtype)
        g_edges = np.empty((b, 1, h, w), dtype=pixels.dtype)
        with kernel_threads():
            _wet_backward(
                pixels,
                full(step, (b, 2, h, w)),
                full(edges, (b, 1, h, w)),
                ctx.weights,
                full(grad, image.shape),
                g_image_parts,
                g_step,
                g_edges,
            )
        need = ctx.needs_input_grad
        return (
            torch.from_numpy(g_image_parts).sum(dim=0) if need[0] else None,
            reduce_to(torch.from_numpy(g_step), step.shape) if need[1] else None,
            reduce_to(torch.from_numpy(g_edges), edges.shape) if need[2] else None,
            None,
        )


@njit(inline="always")
def _sides(image, b, y, x, offset_x, offset_y, channels, height, width, ahead, behind):
    """The differences to the centre of the samples at ``p + offset`` (into ``ahead``) and
    ``p - offset`` (into ``behind``) and their squared lengths."""
    xa0, xa1, fxa, _ = locate(x + offset_x, width)
    ya0, ya1, fya, _ = locate(y + offset_y, height)
    xb0, xb1, fxb, _ = locate(x - offset_x, width)
    yb0, yb1, fyb, _ = locate(y - offset_y, height)
    ahead_sq = behind_sq = 0.0
    for c in range(channels):
        value = image[b, c, y, x]
        ahead[c] = interpolate(image, b, c, ya0, ya1, xa0, xa1, fya, fxa) - value
        behind[c] = interpolate(image, b, c, yb0, yb1, xb0, xb1, fyb, fxb) - value
        ahead_sq += ahead[c] * ahead[c]
        behind_sq += behind[c] * behind[c]
    return ahead_sq, behind_sq


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _gaps_forward(image, direction, band, gap, overlap, distance, paper, eps, out):
    """``out = C + b (g (paper - C) + o (C C_other - C))`` with
    ``C_other = C + (A |A|^2 + B |B|^2) / (|A|^2 + |B|^2 + eps)``, ``A`` and ``B`` the samples at
    ``p +- distance u`` minus ``C``; ``band`` ``b``, ``gap`` ``g``, ``overlap`` ``o`` ``(B, 1, H, W)``."""
    batch, channels, height, width = image.shape
    for task in prange(batch * height):
        b, y = task // height, task % height
        ahead = np.empty(channels, dtype=image.dtype)
        behind = np.empty(channels, dtype=image.dtype)
        for x in range(width):
            offset_x, offset_y = distance * direction[b, 0, y, x], distance * direction[b, 1, y, x]
            ahead_sq, behind_sq = _sides(image, b, y, x, offset_x, offset_y, channels, height, width, ahead, behind)
            norm = ahead_sq + behind_sq + eps
            strength, g, o = band[b, 0, y, x], gap[b, 0, y, x], overlap[b, 0, y, x]
            for c in range(channels):
                value = image[b, c, y, x]
                other = value + (ahead[c] * ahead_sq + behind[c] * behind_sq) / norm
                out[b, c, y, x] = value + strength * (g * (paper - value) + o * (value * other - value))


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _gaps_backward(
    image,
    direction,
    band,
    gap,
    overlap,
    distance,
    paper,
    eps,
    grad,
    g_image_parts,
    g_direction,
    g_band,
    g_gap,
    g_overlap,
):
    """Gradients of :func:`_gaps_forward`. With ``q = dL/dC_other / n`` (``n`` the norm):
    ``dL/dA = q |A|^2 + 2 A (q.A - (q.A |A|^2 + q.B |B|^2) / n)`` (``B`` alike); ``A`` and ``B``
    pass their gradient to the samples (scattered into part ``k`` of ``g_image_parts`` for the rows
    of part ``k``, and along ``u`` to the direction) and minus it to the centre."""
    batch, channels, height, width = image.shape
    parts = g_image_parts.shape[0]
    tasks = batch * height
    for part in prange(parts):
        g_image = g_image_parts[part]
        g_image[:] = 0.0
        ahead = np.empty(channels, dtype=image.dtype)
        behind = np.empty(channels, dtype=image.dtype)
        q = np.empty(channels, dtype=image.dtype)
        for task in range(part * tasks // parts, (part + 1) * tasks // parts):
            b, y = task // height, task % height
            for x in range(width):
                offset_x, offset_y = distance * direction[b, 0, y, x], distance * direction[b, 1, y, x]
                ahead_sq, behind_sq = _sides(image, b, y, x, offset_x, offset_y, channels, height, width, ahead, behind)
                norm = ahead_sq + behind_sq + eps
                strength, gap_strength, overlap_strength = band[b, 0, y, x], gap[b, 0, y, x], overlap[b, 0, y, x]
                g_band_sum = g_gap_sum = g_overlap_sum = 0.0
                q_ahead = q_behind = 0.0
                for c in range(channels):
                    value = image[b, c, y, x]
                    other = value + (ahead[c] * ahead_sq + behind[c] * behind_sq) / norm
                    g = grad[b, c, y, x]
                    g_change = g * strength
                    to_paper = paper - value
                    mixed = value * other - value
                    g_band_sum += g * (gap_strength * to_paper + overlap_strength * mixed)
                    g_gap_sum += g_change * to_paper
                    g_overlap_sum += g_change * mixed
                    g_other = g_change * overlap_strength * value
                    q[c] = g_other / norm
                    q_ahead += q[c] * ahead[c]
                    q_behind += q[c] * behind[c]
                    # the centre's own terms: out's, change's and C_other's
                    centre = 1.0 + strength * (overlap_strength * (other - 1.0) - gap_strength)
                    g_image[b, c, y, x] += g * centre + g_other
                q_mean = (q_ahead * ahead_sq + q_behind * behind_sq) / norm
                xa0, xa1, fxa, moves_xa = locate(x + offset_x, width)
                ya0, ya1, fya, moves_ya = locate(y + offset_y, height)
                xb0, xb1, fxb, moves_xb = locate(x - offset_x, width)
                yb0, yb1, fyb, moves_yb = locate(y - offset_y, height)
                ahead_x = ahead_y = behind_x = behind_y = 0.0
                for c in range(channels):
                    g_ahead = q[c] * ahead_sq + 2.0 * ahead[c] * (q_ahead - q_mean)
                    g_behind = q[c] * behind_sq + 2.0 * behind[c] * (q_behind - q_mean)
                    g_image[b, c, y, x] -= g_ahead + g_behind
                    scatter(g_image, b, c, ya0, ya1, xa0, xa1, fya, fxa, g_ahead)
                    scatter(g_image, b, c, yb0, yb1, xb0, xb1, fyb, fxb, g_behind)
                    slope_x, slope_y = slopes(image, b, c, ya0, ya1, xa0, xa1, fya, fxa)
                    ahead_x += g_ahead * slope_x
                    ahead_y += g_ahead * slope_y
                    slope_x, slope_y = slopes(image, b, c, yb0, yb1, xb0, xb1, fyb, fxb)
                    behind_x += g_behind * slope_x
                    behind_y += g_behind * slope_y
                g_direction[b, 0, y, x] = distance * (ahead_x * moves_xa - behind_x * moves_xb)
                g_direction[b, 1, y, x] = distance * (ahead_y * moves_ya - behind_y * moves_yb)
                g_band[b, 0, y, x] = g_band_sum
                g_gap[b, 0, y, x] = g_gap_sum
                g_overlap[b, 0, y, x] = g_overlap_sum


class GapsOverlaps(torch.autograd.Function):
    """:func:`wise.filters.watercolor.gaps_overlaps` once its maps are known: ``image``
    ``(B, C, H, W)``, ``direction`` ``(B, 2, H, W)``, ``band``, ``gap`` and ``overlap`` broadcasting
    to ``(B, 1, H, W)``, the other side ``distance`` pixels away, the ``paper`` colour and the
    selection's ``eps``. Gradients reach the image, the direction and the three maps."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx,
        image: torch.Tensor,
        direction: torch.Tensor,
        band: torch.Tensor,
        gap: torch.Tensor,
        overlap: torch.Tensor,
        distance: float,
        paper: float,
        eps: float,
    ) -> torch.Tensor:
        b, c, h, w = image.shape
        pixels = full(image, image.shape)
        maps = [full(m, (b, 1, h, w)) for m in (band, gap, overlap)]
        out = np.empty_like(pixels)
        with kernel_threads():
            _gaps_forward(pixels, full(direction, (b, 2, h, w)), *maps, distance, paper, eps, out)
        ctx.save_for_backward(image, direction, band, gap, overlap)
        ctx.settings = (distance, paper, eps)
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, direction, band, gap, overlap = ctx.saved_tensors
        b, c, h, w = image.shape
        pixels = full(image, image.shape)
        g_image_parts = np.empty((chunks(), b, c, h, w), dtype=pixels.dtype)
        g_direction = np.empty((b, 2, h, w), dtype=pixels.dtype)
        g_maps = [np.empty((b, 1, h, w), dtype=pixels.dtype) for _ in range(3)]
        with kernel_threads():
            _gaps_backward(
                pixels,
                full(direction, (b, 2, h, w)),
                *[full(m, (b, 1, h, w)) for m in (band, gap, overlap)],
                *ctx.settings,
                full(grad, image.shape),
                g_image_parts,
                g_direction,
                *g_maps,
            )
        need = ctx.needs_input_grad
        map_grads = [
            reduce_to(torch.from_numpy(g), m.shape) if wanted else None
            for g, m, wanted in zip(g_maps, (band, gap, overlap), need[2:5])
        ]
        return (
            torch.from_numpy(g_image_parts).sum(dim=0) if need[0] else None,
            reduce_to(torch.from_numpy(g_direction), direction.shape) if need[1] else None,
            *map_grads,
            None,
            None,
            None,
        )
