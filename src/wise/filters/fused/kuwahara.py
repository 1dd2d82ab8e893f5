"""Fused CPU kernel of the sector blend that ends :func:`wise.filters.kuwahara.anisotropic_kuwahara`
(Kyprianidis, Kang & Döllner 2009).

From the weighted sums per sector ``n`` of the offsets ``d`` (sample - centre) and of ``|d|^2``,
with ``T`` the weight of a sector: means ``m_n = S_n / T``, variances
``s_n^2 = Q_n / T - |m_n|^2``, weights ``a_n = 1 / (1 + (K s_n^2)^(q / 2))`` normalised (a
softmax of ``log a_n = -softplus(q / 2 log(K s_n^2 + eps))``), and the output
``I + sum_n a_n m_n / sum_n a_n``. The PyTorch path holds every step as a tensor of all
sectors, channels and pixels; here each pixel's sectors stay in registers.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, full, kernel_threads, reduce_to

_MAX_EXPONENT = 700.0
"""``(K s^2 + eps)^(q / 2)`` is taken as ``exp`` of at most this, so that a weight never underflows to 0."""


@njit(inline="always")
def _sector_weight(square_sum: float, mean_sq: float, weight: float, sharpness: float, scale: float, eps: float):
    """``a_n = 1 / (1 + (K s_n^2 + eps)^(q / 2))``, whether the variance is not clamped, and
    ``K s_n^2 + eps`` and its log. ``a_n / sum a`` is the softmax of ``log a_n`` of the PyTorch path."""
    variance = square_sum / weight - mean_sq
    deviation = max(variance, 0.0) * scale + eps
    log_deviation = math.log(deviation)
    share = 1.0 / (1.0 + math.exp(min(0.5 * sharpness * log_deviation, _MAX_EXPONENT)))
    return share, variance >= 0.0, log_deviation, deviation


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _blend_forward(image, sums, square_sums, sharpness, weight, scale, eps, out):
    sectors, batch, channels, height, width = sums.shape
    for row in prange(batch * height):
        b, y = row // height, row % height
        for x in range(width):
            q = sharpness[b, 0, y, x]
            for c in range(channels):
                out[b, c, y, x] = 0.0
            normaliser = 0.0
            for n in range(sectors):
                mean_sq = 0.0
                for c in range(channels):
                    mean = sums[n, b, c, y, x] / weight
                    mean_sq += mean * mean
                share = _sector_weight(square_sums[n, b, 0, y, x], mean_sq, weight, q, scale, eps)[0]
                normaliser += share
                for c in range(channels):
                    out[b, c, y, x] += share * sums[n, b, c, y, x]
            for c in range(channels):
                out[b, c, y, x] = image[b, c, y, x] + out[b, c, y, x] / (normaliser * weight)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _blend_backward(sums, square_sums, sharpness, weight, scale, eps, grad, g_sums, g_square_sums, g_sharpness):
    sectors, batch, channels, height, width = sums.shape
    for row in prange(batch * height):
        b, y = row // height, row % height
        shares = np.empty(sectors)
        unclamped = np.empty(sectors, dtype=np.bool_)
        log_deviations = np.empty(sectors)
        deviations = np.empty(sectors)
        g_shares = np.empty(sectors)
        for x in range(width):
            q = sharpness[b, 0, y, x]
            normaliser = 0.0
            for n in range(sectors):
                mean_sq = 0.0
                for c in range(channels):
                    mean = sums[n, b, c, y, x] / weight
                    mean_sq += mean * mean
                shares[n], unclamped[n], log_deviations[n], deviations[n] = _sector_weight(
                    square_sums[n, b, 0, y, x], mean_sq, weight, q, scale, eps
                )
                normaliser += shares[n]
            mean_g = 0.0  # sum_n w_n dL/dw_n, for the softmax's backward
            for n in range(sectors):
                g_share = 0.0
                for c in range(channels):
                    g_share += grad[b, c, y, x] * sums[n, b, c, y, x]
                g_shares[n] = g_share / weight
                mean_g += shares[n] * g_shares[n]
            mean_g /= normaliser
            g_q = 0.0
            for n in range(sectors):
                share = shares[n] / normaliser
                g_logit = share * (g_shares[n] - mean_g)
                # log a = -softplus(t) with t = q / 2 log(K v + eps): d log a / dt = -(1 - a)
                g_t = -g_logit * (1.0 - shares[n])
                g_q += g_t * 0.5 * log_deviations[n]
                g_variance = 0.0
                if unclamped[n]:
                    g_variance = g_t * 0.5 * q * scale / deviations[n]
                g_square_sums[n, b, 0, y, x] = g_variance / weight
                for c in range(channels):
                    mean = sums[n, b, c, y, x] / weight
                    g_sums[n, b, c, y, x] = (share * grad[b, c, y, x] - 2.0 * mean * g_variance) / weight
            g_sharpness[b, 0, y, x] = g_q


class SectorBlend(torch.autograd.Function):
    """``image + sum_n a_n m_n`` from the sector sums; gradients reach the image, both sums and ``q``."""

    @staticmethod
    def forward(ctx, image, sums, square_sums, sharpness, weight: float, scale: float, eps: float):  # type: ignore[override]
        b, c, h, w = image.shape
        sums_array = np.ascontiguousarray(sums.detach().numpy())
        square_array = np.ascontiguousarray(square_sums.detach().numpy())
        out = np.empty((b, c, h, w), dtype=sums_array.dtype)
        with kernel_threads():
            _blend_forward(
                full(image, (b, c, h, w)),
                sums_array,
                square_array,
                full(sharpness.to(image.dtype), (b, 1, h, w)),
                weight,
                scale,
                eps,
                out,
            )
        ctx.save_for_backward(sums, square_sums, sharpness)
        ctx.settings = (weight, scale, eps)
        ctx.image_shape = image.shape
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx, grad):  # type: ignore[override]
        sums, square_sums, sharpness = ctx.saved_tensors
        b, c, h, w = ctx.image_shape
        sums_array = np.ascontiguousarray(sums.detach().numpy())
        g_sums = np.empty_like(sums_array)
        g_square_sums = np.empty(square_sums.shape, dtype=sums_array.dtype)
        g_sharpness = np.empty((b, 1, h, w), dtype=sums_array.dtype)
        with kernel_threads():
            _blend_backward(
                sums_array,
                np.ascontiguousarray(square_sums.detach().numpy()),
                full(sharpness.to(sums.dtype), (b, 1, h, w)),
                *ctx.settings,
                full(grad, (b, c, h, w)),
                g_sums,
                g_square_sums,
                g_sharpness,
            )
        return (
            grad if ctx.needs_input_grad[0] else None,
            torch.from_numpy(g_sums),
            torch.from_numpy(g_square_sums),
            reduce_to(torch.from_numpy(g_sharpness), sharpness.shape) if ctx.needs_input_grad[3] else None,
            None,
            None,
            None,
        )
