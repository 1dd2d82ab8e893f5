"""Fused CPU kernel of :func:`wise.filters.upsample.joint_bilateral_upsample`: the normalized sum
over the low-resolution neighbours (Kopf et al. 2007), forward and analytic backward in one loop
over the output pixels.

Per output pixel ``p`` and neighbour ``q`` (low-resolution pixel ``(r, s)``, the rows and columns
chosen by ``upsample._axis_neighbours``): ``d = guide(p) - guide_low(q)``,
``e = max(max(|d|^2 a_r(p), F_r) + (dy^2 + dx^2) a_s(p), F)`` with the coefficients
``a = -1 / (2 sigma^2)`` and the floors ``F_r``, ``F``; ``w = exp(e)`` and
``out(p) = sum_q w low(q) / sum_q w``.

The PyTorch path gathers every neighbour as a full-resolution tensor (twice in backward, whose
gathers scatter into zero-filled tensors); here a pixel reads its neighbours from one small
channels-last copy of the low-resolution result and guide, and backward scatters into one private
low-resolution accumulator per thread. Most of the work is one exponential per pixel and
neighbour: for three channels and a three-channel guide (RGB or Lab, the effects' case) the
kernels run along rows with an exponential that the compiler vectorizes (Numba calls the C
library's scalar ``exp`` otherwise); other channel counts take a generic loop per pixel.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, array, chunks, full, kernel_threads, reduce_to

_LOG2_E = 1.0 / math.log(2.0)
_LN_2 = math.log(2.0)


def powers_of_two(floor: float) -> np.ndarray:
    """``2^-k`` for ``k = 0 .. K``, enough for :func:`_exp_nonpositive` of exponents down to ``floor``."""
    return 2.0 ** -np.arange(math.ceil(-floor * _LOG2_E) + 2, dtype=np.float64)


@njit(inline="always")
def _exp_nonpositive(exponent, powers):
    """``exp(exponent)`` for ``floor <= exponent <= 0`` (``powers`` from :func:`powers_of_two`) with a
    relative error below 1e-14: ``2^n exp(r)`` with ``n = round(exponent / ln 2)`` and ``exp(r)``,
    ``|r| <= ln(2) / 2``, by its Taylor polynomial of degree 12. Unlike a call of the C library's
    ``exp``, a loop of these is vectorized."""
    n = math.floor(exponent * _LOG2_E + 0.5)
    r = exponent - n * _LN_2
    p = 1.0 / 479001600.0
    p = p * r + 1.0 / 39916800.0
    p = p * r + 1.0 / 3628800.0
    p = p * r + 1.0 / 362880.0
    p = p * r + 1.0 / 40320.0
    p = p * r + 1.0 / 5040.0
    p = p * r + 1.0 / 720.0
    p = p * r + 1.0 / 120.0
    p = p * r + 1.0 / 24.0
    p = p * r + 1.0 / 6.0
    p = p * r + 0.5
    p = p * r + 1.0
    p = p * r + 1.0
    return p * powers[min(max(int(-n), 0), powers.shape[0] - 1)]


@njit(inline="always")
def _weight(range_sq, spatial_sq, a_spatial, a_range, range_floor, floor, powers):
    """``(w, dL/de passes, dL/d(range term) passes)`` of one neighbour: the clamps pass the gradient
    where they do not cut, as PyTorch's ``clamp_min``."""
    range_term = range_sq * a_range
    exponent = max(range_term, range_floor) + spatial_sq * a_spatial
    weight = _exp_nonpositive(max(exponent, floor), powers)
    return weight, exponent >= floor, range_term >= range_floor


_RGB = 3
"""Channels of the result and of the guide for which the kernels have a copy with the channel loops
unrolled and every loop over a row's pixels innermost, so that it runs in vector registers (with
:func:`_exp_nonpositive`). The copies are separate kernels: a branch to the generic code in the
same loop keeps the compiler from vectorizing."""


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _forward_rgb(
    packed, guide, a_spatial, a_range, rows, rows_sq, cols, cols_sq, range_floor, floor, powers, out, norm
):
    """:func:`_forward_any` for three channels and a three-channel guide, a row at a time."""
    batch, _, height, width = out.shape
    n = rows.shape[0]
    for task in prange(batch * height):
        b, y = task // height, task % height
        totals = np.zeros((_RGB, width))
        weight_sums = np.zeros(width)
        for j in range(n):
            r = rows[j, y]
            for i in range(n):
                for x in range(width):
                    s = cols[i, x]
                    range_sq = 0.0
                    for k in range(_RGB):
                        difference = guide[b, k, y, x] - packed[b, r, s, _RGB + k]
                        range_sq += difference * difference
                    spatial_sq = rows_sq[j, y] + cols_sq[i, x]
                    weight, _, _ = _weight(
                        range_sq, spatial_sq, a_spatial[b, 0, y, x], a_range[b, 0, y, x], range_floor, floor, powers
                    )
                    weight_sums[x] += weight
                    for c in range(_RGB):
                        totals[c, x] += weight * packed[b, r, s, c]
        for x in range(width):
            for c in range(_RGB):
                out[b, c, y, x] = totals[c, x] / weight_sums[x]
            norm[b, 0, y, x] = weight_sums[x]


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _forward_any(
    packed, guide, a_spatial, a_range, rows, rows_sq, cols, cols_sq, range_floor, floor, powers, out, norm
):
    """``out`` ``(B, C, H, W)`` and ``norm = sum_q w`` ``(B, 1, H, W)`` from the channels-last
    ``packed`` ``(B, h, w, C + G)`` (low-resolution result, then downsampled guide), any numbers of
    channels, a pixel at a time."""
    batch, channels, height, width = out.shape
    guide_channels = guide.shape[1]
    n = rows.shape[0]
    for task in prange(batch * height):
        b, y = task // height, task % height
        totals = np.empty(channels)
        for x in range(width):
            totals[:] = 0.0
            weight_sum = 0.0
            for j in range(n):
                r = rows[j, y]
                for i in range(n):
                    s = cols[i, x]
                    range_sq = 0.0
                    for k in range(guide_channels):
                        difference = guide[b, k, y, x] - packed[b, r, s, channels + k]
                        range_sq += difference * difference
                    spatial_sq = rows_sq[j, y] + cols_sq[i, x]
                    weight, _, _ = _weight(
                        range_sq, spatial_sq, a_spatial[b, 0, y, x], a_range[b, 0, y, x], range_floor, floor, powers
                    )
                    weight_sum += weight
                    for c in range(channels):
                        totals[c] += weight * packed[b, r, s, c]
            for c in range(channels):
                out[b, c, y, x] = totals[c] / weight_sum
            norm[b, 0, y, x] = weight_sum


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _backward_rgb(
    packed, guide, a_spatial, a_range, rows, rows_sq, cols, cols_sq, range_floor, floor, powers, out, norm, grad,
    g_packed_parts, g_guide, g_a_spatial, g_a_range,
):  # fmt: skip
    """:func:`_backward_any` for three channels and a three-channel guide, a row at a time: the
    per-pixel gradients in vector loops over the row, then the scatter of each neighbour."""
    batch, _, height, width = out.shape
    n = rows.shape[0]
    parts = g_packed_parts.shape[0]
    tasks = batch * height
    for part in prange(parts):
        g_packed = g_packed_parts[part]
        g_packed[:] = 0.0
        scaled_grad = np.empty((_RGB, width))
        g_dot_out, weights, g_differences = np.empty(width), np.empty(width), np.empty(width)
        g_s, g_r = np.empty(width), np.empty(width)
        for task in range(part * tasks // parts, (part + 1) * tasks // parts):
            b, y = task // height, task % height
            for x in range(width):
                inverse_norm = 1.0 / norm[b, 0, y, x]
                total = 0.0
                for c in range(_RGB):
                    scaled_grad[c, x] = grad[b, c, y, x] * inverse_norm
                    total += scaled_grad[c, x] * out[b, c, y, x]
                g_dot_out[x] = total
                g_s[x] = 0.0
                g_r[x] = 0.0
                for k in range(_RGB):
                    g_guide[b, k, y, x] = 0.0
            for j in range(n):
                r = rows[j, y]
                for i in range(n):
                    for x in range(width):
                        s = cols[i, x]
                        range_sq = 0.0
                        for k in range(_RGB):
                            difference = guide[b, k, y, x] - packed[b, r, s, _RGB + k]
                            range_sq += difference * difference
                        spatial_sq = rows_sq[j, y] + cols_sq[i, x]
                        a_r = a_range[b, 0, y, x]
                        weight, exponent_passes, range_passes = _weight(
                            range_sq, spatial_sq, a_spatial[b, 0, y, x], a_r, range_floor, floor, powers
                        )
                        weights[x] = weight
                        g_weight = -g_dot_out[x]
                        for c in range(_RGB):
                            g_weight += scaled_grad[c, x] * packed[b, r, s, c]
                        g_exponent = g_weight * weight if exponent_passes else 0.0
                        g_s[x] += g_exponent * spatial_sq
                        g_range = g_exponent if range_passes else 0.0
                        g_r[x] += g_range * range_sq
                        g_difference = 2.0 * g_range * a_r
                        g_differences[x] = g_difference
                        for k in range(_RGB):
                            g_guide[b, k, y, x] += g_difference * (guide[b, k, y, x] - packed[b, r, s, _RGB + k])
                    for x in range(width):  # neighbouring pixels share neighbours: a scalar loop
                        s = cols[i, x]
                        for c in range(_RGB):
                            g_packed[b, r, s, c] += weights[x] * scaled_grad[c, x]
                        for k in range(_RGB):
                            difference = guide[b, k, y, x] - packed[b, r, s, _RGB + k]
                            g_packed[b, r, s, _RGB + k] -= g_differences[x] * difference
            for x in range(width):
                g_a_spatial[b, 0, y, x] = g_s[x]
                g_a_range[b, 0, y, x] = g_r[x]


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _backward_any(
    packed, guide, a_spatial, a_range, rows, rows_sq, cols, cols_sq, range_floor, floor, powers, out, norm, grad,
    g_packed_parts, g_guide, g_a_spatial, g_a_range,
):  # fmt: skip
    """Gradients of :func:`_forward_any`. With ``g`` the output's gradient,
    ``dL/dw_q = sum_c g_c (low_c(q) - out_c) / norm``; ``dL/de = w dL/dw`` unless clamped, which
    reaches ``a_s`` (times the squared distance), ``a_r`` (times ``|d|^2``) and, through
    ``2 a_r d``, the guide at ``p`` (gathered) and the downsampled guide at ``q`` (scattered into
    part ``k`` of ``g_packed_parts`` ``(K, B, h, w, C + G)`` for the rows of part ``k``; the
    result's gradient ``w g / norm`` likewise)."""
    batch, channels, height, width = out.shape
    guide_channels = guide.shape[1]
    n = rows.shape[0]
    parts = g_packed_parts.shape[0]
    tasks = batch * height
    for part in prange(parts):
        g_packed = g_packed_parts[part]
        g_packed[:] = 0.0
        scaled_grad = np.empty(channels)
        for task in range(part * tasks // parts, (part + 1) * tasks // parts):
            b, y = task // height, task % height
            for x in range(width):
                a_s, a_r = a_spatial[b, 0, y, x], a_range[b, 0, y, x]
                inverse_norm = 1.0 / norm[b, 0, y, x]
                g_dot_out = 0.0
                for c in range(channels):
                    scaled_grad[c] = grad[b, c, y, x] * inverse_norm
                    g_dot_out += scaled_grad[c] * out[b, c, y, x]
                for k in range(guide_channels):
                    g_guide[b, k, y, x] = 0.0
                g_s = g_r = 0.0
                for j in range(n):
                    r = rows[j, y]
                    for i in range(n):
                        s = cols[i, x]
                        range_sq = 0.0
                        for k in range(guide_channels):
                            difference = guide[b, k, y, x] - packed[b, r, s, channels + k]
                            range_sq += difference * difference
                        spatial_sq = rows_sq[j, y] + cols_sq[i, x]
                        weight, exponent_passes, range_passes = _weight(
                            range_sq, spatial_sq, a_s, a_r, range_floor, floor, powers
                        )
                        g_weight = -g_dot_out
                        for c in range(channels):
                            g_weight += scaled_grad[c] * packed[b, r, s, c]
                            g_packed[b, r, s, c] += weight * scaled_grad[c]
                        g_exponent = g_weight * weight if exponent_passes else 0.0
                        g_s += g_exponent * spatial_sq
                        g_range = g_exponent if range_passes else 0.0
                        g_r += g_range * range_sq
                        g_difference = 2.0 * g_range * a_r
                        for k in range(guide_channels):
                            g = g_difference * (guide[b, k, y, x] - packed[b, r, s, channels + k])
                            g_guide[b, k, y, x] += g
                            g_packed[b, r, s, channels + k] -= g
                g_a_spatial[b, 0, y, x] = g_s
                g_a_range[b, 0, y, x] = g_r


def _geometry(rows: torch.Tensor, rows_sq: torch.Tensor, cols: torch.Tensor, cols_sq: torch.Tensor, dtype):
    return (
        array(rows),
        array(rows_sq.to(dtype)),
        array(cols),
        array(cols_sq.to(dtype)),
    )


class JointBilateralSum(torch.autograd.Function):
    """``sum_q w_q low(q) / sum_q w_q`` of :func:`wise.filters.upsample.joint_bilateral_upsample`
    for ``low`` ``(B, C, h, w)``, ``guide_low`` ``(B, G, h, w)`` (the guide area-downsampled),
    ``guide`` ``(B, G, H, W)`` and the coefficients ``a_spatial``, ``a_range`` (``-1 / (2 sigma^2)``,
    broadcasting to ``(B, 1, H, W)``); ``rows``/``cols`` ``(N, H)``/``(N, W)`` are the
    low-resolution neighbours of every output row and column and ``rows_sq``/``cols_sq`` their
    squared distances. Gradients reach ``low``, both guides and both coefficients."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx,
        low: torch.Tensor,
        guide_low: torch.Tensor,
        guide: torch.Tensor,
        a_spatial: torch.Tensor,
        a_range: torch.Tensor,
        rows: torch.Tensor,
        rows_sq: torch.Tensor,
        cols: torch.Tensor,
        cols_sq: torch.Tensor,
        range_floor: float,
        floor: float,
    ) -> torch.Tensor:
        b, c = low.shape[:2]
        height, width = guide.shape[-2:]
        packed = array(torch.cat((low, guide_low), dim=1).permute(0, 2, 3, 1))
        maps = [full(a, (b, 1, height, width)) for a in (a_spatial, a_range)]
        geometry = _geometry(rows, rows_sq, cols, cols_sq, low.dtype)
        out = np.empty((b, c, height, width), dtype=packed.dtype)
        norm = np.empty((b, 1, height, width), dtype=packed.dtype)
        kernel = _forward_rgb if c == _RGB and guide.shape[1] == _RGB else _forward_any
        with kernel_threads():
            kernel(packed, array(guide), *maps, *geometry, range_floor, floor, powers_of_two(floor), out, norm)
        result = torch.from_numpy(out)
        ctx.save_for_backward(low, guide_low, guide, a_spatial, a_range, rows, rows_sq, cols, cols_sq, result)
        ctx.norm = norm
        ctx.floors = (range_floor, floor)
        return result

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        low, guide_low, guide, a_spatial, a_range, rows, rows_sq, cols, cols_sq, out = ctx.saved_tensors
        b, c, h, w = low.shape
        g_channels, height, width = guide.shape[1:]
        packed = array(torch.cat((low, guide_low), dim=1).permute(0, 2, 3, 1))
        g_packed_parts = np.empty((chunks(), b, h, w, c + g_channels), dtype=packed.dtype)
        g_guide = np.empty((b, g_channels, height, width), dtype=packed.dtype)
        g_a_spatial = np.empty((b, 1, height, width), dtype=packed.dtype)
        g_a_range = np.empty((b, 1, height, width), dtype=packed.dtype)
        kernel = _backward_rgb if c == _RGB and g_channels == _RGB else _backward_any
        with kernel_threads():
            kernel(
                packed,
                array(guide),
                *[full(a, (b, 1, height, width)) for a in (a_spatial, a_range)],
                *_geometry(rows, rows_sq, cols, cols_sq, low.dtype),
                *ctx.floors,
                powers_of_two(ctx.floors[1]),
                array(out),
                ctx.norm,
                full(grad, (b, c, height, width)),
                g_packed_parts,
                g_guide,
                g_a_spatial,
                g_a_range,
            )
        g_packed = torch.from_numpy(g_packed_parts).sum(dim=0).permute(0, 3, 1, 2)
        need = ctx.needs_input_grad
        return (
            g_packed[:, :c].contiguous() if need[0] else None,
            g_packed[:, c:].contiguous() if need[1] else None,
            torch.from_numpy(g_guide) if need[2] else None,
            reduce_to(torch.from_numpy(g_a_spatial), a_spatial.shape) if need[3] else None,
            reduce_to(torch.from_numpy(g_a_range), a_range.shape) if need[4] else None,
            None,
            None,
            None,
            None,
            None,
            None,
        )
