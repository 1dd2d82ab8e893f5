"""Fused CPU kernel of :func:`wise.filters.kuwahara.anisotropic_kuwahara` after the ellipse is set up:
the sample loop of ``_SectorSums`` and the sector blend that follows it (Kyprianidis, Kang &
Döllner 2009), forward and analytic backward in one loop over pixels.

Per pixel ``p`` (centre value ``I``) and tap ``t`` at unit-disc position ``(u_t, v_t)``: the
bilinear, border-clamped sample ``s_t`` at ``p + u_t M + v_t N`` (``M``, ``N`` the major and minor
axis vectors in pixels), ``d_t = s_t - I``, and per sector ``n`` the sums
``S_n = sum_t w_tn d_t`` and ``Q_n = sum_t w_tn |d_t|^2``. With ``T`` the weight of a sector:
means ``m_n = S_n / T``, variances ``v_n = Q_n / T - |m_n|^2``, logits
``l_n = -softplus(q / 2 log(K max(v_n, 0) + eps))`` and the output ``I + sum_n softmax(l)_n m_n``.

The PyTorch path holds the sums and every step of the blend as ``(sectors, B, C, H, W)`` tensors;
here a pixel's sectors stay in small scratch arrays. When a gradient is wanted, forward keeps the
sums (``sectors * (C + 1)`` numbers a pixel) and backward recomputes the samples once, for the
gradients of the sums; no per-sample value is kept. The image is read channels-last, so that a
tap finds all channels of its four corners together, and the kernels compile for the number of
channels (passed as a tuple of that length), so that the channel loops unroll.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Sequence

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, chunks, full, kernel_threads, reduce_to
from wise.filters.fused.bilinear import locate

_SOFTPLUS_GROWTH_THRESHOLD = math.exp(20.0)
"""``exp`` of the input above which :func:`torch.nn.functional.softplus` returns its input (its
default ``threshold`` is 20)."""
_MAX_INTEGER_POWER = 64
"""Largest whole ``q / 2`` raised by multiplications instead of ``exp`` and ``log``."""
_SHARE, _VARIANCE, _DEVIATION, _SLOPE = range(4)
_BLEND_ROWS = 4
"""Rows of a pixel's blend scratch array, one value per sector each (see :func:`_sector_shares`)."""
_SLOTS = 2
"""Sectors a tap can weigh in: its own and the neighbour it leans towards."""


@lru_cache(maxsize=16)
def tap_arrays(taps: Sequence) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The taps of ``kuwahara._sample_layout`` as arrays: unit-disc positions ``(T, 2)`` (along,
    across), sector indices ``(T, 2)`` and sector weights ``(T, 2)`` (0 in an unused slot)."""
    positions = np.zeros((len(taps), 2))
    sector_index = np.zeros((len(taps), _SLOTS), dtype=np.int64)
    sector_weight = np.zeros((len(taps), _SLOTS))
    for t, tap in enumerate(taps):
        positions[t] = tap.along, tap.across
        for slot, (sector, weight) in enumerate(tap.sector_weights):
            sector_index[t, slot] = sector
            sector_weight[t, slot] = weight
    return positions, sector_index, sector_weight


@njit(inline="always")
def _sample_sectors(
    picture, y, x, major_x, major_y, minor_x, minor_y, positions, index, weight, sums, squares, channels
):
    """``S_n`` into ``sums`` ``(sectors, C)`` and ``Q_n`` into ``squares`` ``(sectors,)`` for pixel
    ``(y, x)`` of a channels-last ``picture`` ``(H, W, C)``; the axes are in pixels."""
    height, width = picture.shape[0], picture.shape[1]
    sums[:] = 0.0
    squares[:] = 0.0
    for t in range(positions.shape[0]):
        along, across = positions[t, 0], positions[t, 1]
        first, second = index[t, 0], index[t, 1]
        first_weight, second_weight = weight[t, 0], weight[t, 1]
        x0, x1, fx, _ = locate(x + along * major_x + across * minor_x, width)
        y0, y1, fy, _ = locate(y + along * major_y + across * minor_y, height)
        square = 0.0
        for c in range(channels):
            top = picture[y0, x0, c] + fx * (picture[y0, x1, c] - picture[y0, x0, c])
            bottom = picture[y1, x0, c] + fx * (picture[y1, x1, c] - picture[y1, x0, c])
            difference = top + fy * (bottom - top) - picture[y, x, c]
            square += difference * difference
            sums[first, c] += first_weight * difference
            sums[second, c] += second_weight * difference
        squares[first] += first_weight * square
        squares[second] += second_weight * square


@njit(inline="always")
def _integer_power(base: float, exponent: int) -> float:
    """``base ** exponent`` for ``exponent >= 1`` by repeated squaring."""
    result = 1.0
    while exponent > 1:
        if exponent & 1:
            result *= base
        base *= base
        exponent >>= 1
    return result * base


@njit(inline="always")
def _sector_shares(sums, squares, sharpness, total_weight, variance_scale, variance_eps, blend, channels):
    """The blend's weights ``softmax(l)_n`` and what their gradients need, into the rows of ``blend``
    ``(_BLEND_ROWS, sectors)``: ``_SHARE``, ``_VARIANCE`` (``v_n``), ``_DEVIATION``
    (``K max(v_n, 0) + eps``) and ``_SLOPE`` (the derivative of the softplus at ``e_n``).

    ``exp(l_n) = 1 / (1 + g_n)`` with ``g_n = (K max(v_n, 0) + eps)^(q / 2) = exp(e_n)``: by
    multiplications where ``q / 2`` is a small whole number (``q = 8``: the fourth power), else
    by ``exp`` and ``log``. Above the softplus threshold ``l_n = -e_n``, ``exp(l_n) = 1 / g_n``;
    where every ``e_n`` lies above it the softmax is taken relative to the smallest, so that no
    weight underflows.
    """
    sectors = sums.shape[0]
    half_sharpness = 0.5 * sharpness
    by_multiplication = 1.0 <= half_sharpness <= _MAX_INTEGER_POWER and half_sharpness == math.floor(half_sharpness)
    smallest = np.inf
    for n in range(sectors):
        mean_square = 0.0
        for c in range(channels):
            mean = sums[n, c] / total_weight
            mean_square += mean * mean
        variance = squares[n] / total_weight - mean_square
        deviation = max(variance, 0.0) * variance_scale + variance_eps
        if by_multiplication:
            growth = _integer_power(deviation, int(half_sharpness))
        else:
            growth = math.exp(half_sharpness * math.log(deviation))
        blend[_VARIANCE, n], blend[_DEVIATION, n], blend[_SHARE, n] = variance, deviation, growth
        smallest = min(smallest, growth)
    normaliser = 0.0
    if smallest > _SOFTPLUS_GROWTH_THRESHOLD:  # every logit is -e_n (g_n may have overflowed)
        least_exponent = np.inf
        for n in range(sectors):
            blend[_SHARE, n] = half_sharpness * math.log(blend[_DEVIATION, n])  # e_n for now
            least_exponent = min(least_exponent, blend[_SHARE, n])
        for n in range(sectors):
            blend[_SHARE, n] = math.exp(least_exponent - blend[_SHARE, n])
            blend[_SLOPE, n] = 1.0
            normaliser += blend[_SHARE, n]
    else:
        for n in range(sectors):
            growth = blend[_SHARE, n]
            if growth > _SOFTPLUS_GROWTH_THRESHOLD:
                blend[_SHARE, n], blend[_SLOPE, n] = 1.0 / growth, 1.0
            else:
                blend[_SHARE, n] = 1.0 / (1.0 + growth)
                blend[_SLOPE, n] = growth * blend[_SHARE, n]
            normaliser += blend[_SHARE, n]
    for n in range(sectors):
        blend[_SHARE, n] /= normaliser


@njit(inline="always")
def _forward_pixel(
    picture, b, y, x, major, minor, sharpness, positions, index, weight, total_weight, variance_scale, variance_eps,
    accumulated, accumulated_squares, sums, squares, blend, out, channels,
):  # fmt: skip
    """Pixel ``(b, y, x)``: its sector sums into ``sums`` and ``squares`` (the input's dtype) and its output."""
    height, width = picture.shape[0], picture.shape[1]
    half_width, half_height = 0.5 * (width - 1), 0.5 * (height - 1)
    major_x, major_y = major[b, y, x, 0] * half_width, major[b, y, x, 1] * half_height
    minor_x, minor_y = minor[b, y, x, 0] * half_width, minor[b, y, x, 1] * half_height
    _sample_sectors(
        picture, y, x, major_x, major_y, minor_x, minor_y, positions, index, weight, accumulated, accumulated_squares,
        channels,
    )  # fmt: skip
    sectors = sums.shape[0]
    for n in range(sectors):
        squares[n] = accumulated_squares[n]
        for c in range(channels):
            sums[n, c] = accumulated[n, c]
    _sector_shares(sums, squares, sharpness[b, 0, y, x], total_weight, variance_scale, variance_eps, blend, channels)
    for c in range(channels):
        blended = 0.0
        for n in range(sectors):
            blended += blend[_SHARE, n] * sums[n, c]
        out[b, c, y, x] = picture[y, x, c] + blended / total_weight


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _forward(
    image, lanes, major, minor, sharpness, positions, index, weight, total_weight, variance_scale, variance_eps, keep,
    kept_sums, kept_squares, out,
):  # fmt: skip
    batch, height, width = image.shape[:3]
    channels = len(lanes)  # known when compiling: the channel loops unroll
    sectors = kept_sums.shape[3]
    for row in prange(batch * height):
        b, y = row // height, row % height
        picture = image[b]
        accumulated = np.empty((sectors, channels))
        accumulated_squares = np.empty(sectors)
        blend = np.empty((_BLEND_ROWS, sectors))
        pixel_sums = np.empty((sectors, channels), dtype=image.dtype)
        pixel_squares = np.empty(sectors, dtype=image.dtype)
        for x in range(width):
            sums = kept_sums[b, y, x] if keep else pixel_sums
            squares = kept_squares[b, y, x] if keep else pixel_squares
            _forward_pixel(
                picture, b, y, x, major, minor, sharpness, positions, index, weight, total_weight, variance_scale,
                variance_eps, accumulated, accumulated_squares, sums, squares, blend, out, channels,
            )  # fmt: skip


@njit(inline="always")
def _backward_pixel(
    picture, g_picture, b, y, x, major, minor, sharpness, positions, index, weight, total_weight, variance_scale,
    variance_eps, sector_weights, sums, squares, grad, need_image, need_sharpness, blend, g_sums, g_squares, g_major,
    g_minor, g_sharpness, channels,
):  # fmt: skip
    """Gradients of pixel ``(b, y, x)``'s output: its ``q`` and axes, and scattered into ``g_picture``.
    ``sector_weights`` ``(sectors,)``: the taps' total weight in each sector."""
    height, width = picture.shape[0], picture.shape[1]
    half_width, half_height = 0.5 * (width - 1), 0.5 * (height - 1)
    sectors = sums.shape[0]
    q = sharpness[b, 0, y, x]
    _sector_shares(sums, squares, q, total_weight, variance_scale, variance_eps, blend, channels)

    # the blend's backward: gradients of S_n and Q_n, and of q
    mean_g_share = 0.0  # sum_n a_n dL/da_n, for the softmax
    for n in range(sectors):
        g_share = 0.0
        for c in range(channels):
            g_share += grad[b, c, y, x] * sums[n, c]
        g_squares[n] = g_share / total_weight  # dL/da_n until overwritten below
        mean_g_share += blend[_SHARE, n] * g_squares[n]
    g_q = 0.0
    for n in range(sectors):
        # l_n = -softplus(e_n), e_n = q / 2 log(K max(v_n, 0) + eps)
        share, deviation = blend[_SHARE, n], blend[_DEVIATION, n]
        g_exponent = -share * (g_squares[n] - mean_g_share) * blend[_SLOPE, n]
        if need_sharpness:
            g_q += g_exponent * 0.5 * math.log(deviation)
        g_variance = 0.0
        if blend[_VARIANCE, n] >= 0.0:  # clamp_min passes the gradient at 0
            g_variance = g_exponent * 0.5 * q * variance_scale / deviation
        g_squares[n] = g_variance / total_weight
        for c in range(channels):
            mean = sums[n, c] / total_weight
            g_sums[n, c] = (share * grad[b, c, y, x] - 2.0 * mean * g_variance) / total_weight
    g_sharpness[b, 0, y, x] = g_q

    # the taps' backward: d_t enters S_n linearly and Q_n through |d_t|^2
    major_x, major_y = major[b, y, x, 0] * half_width, major[b, y, x, 1] * half_height
    minor_x, minor_y = minor[b, y, x, 0] * half_width, minor[b, y, x, 1] * half_height
    g_major_x = g_major_y = g_minor_x = g_minor_y = 0.0
    for t in range(positions.shape[0]):
        along, across = positions[t, 0], positions[t, 1]
        first, second = index[t, 0], index[t, 1]
        first_weight, second_weight = weight[t, 0], weight[t, 1]
        x0, x1, fx, x_slope = locate(x + along * major_x + across * minor_x, width)
        y0, y1, fy, y_slope = locate(y + along * major_y + across * minor_y, height)
        g_square = 2.0 * (first_weight * g_squares[first] + second_weight * g_squares[second])
        g_x = g_y = 0.0
        for c in range(channels):
            top_left, top_right = picture[y0, x0, c], picture[y0, x1, c]
            bottom_left, bottom_right = picture[y1, x0, c], picture[y1, x1, c]
            top_slope, bottom_slope = top_right - top_left, bottom_right - bottom_left
            top, bottom = top_left + fx * top_slope, bottom_left + fx * bottom_slope
            difference = top + fy * (bottom - top) - picture[y, x, c]
            g_difference = g_square * difference + first_weight * g_sums[first, c] + second_weight * g_sums[second, c]
            g_x += g_difference * (top_slope + fy * (bottom_slope - top_slope))
            g_y += g_difference * (bottom - top)
            if need_image:
                g_top, g_bottom = g_difference * (1.0 - fy), g_difference * fy
                g_picture[y0, x0, c] += g_top * (1.0 - fx)
                g_picture[y0, x1, c] += g_top * fx
                g_picture[y1, x0, c] += g_bottom * (1.0 - fx)
                g_picture[y1, x1, c] += g_bottom * fx
        g_x *= x_slope
        g_y *= y_slope
        g_major_x += along * g_x
        g_major_y += along * g_y
        g_minor_x += across * g_x
        g_minor_y += across * g_y
    # back from pixels to grid units
    g_major[b, y, x, 0], g_major[b, y, x, 1] = g_major_x * half_width, g_major_y * half_height
    g_minor[b, y, x, 0], g_minor[b, y, x, 1] = g_minor_x * half_width, g_minor_y * half_height
    if need_image:
        # the centre enters every d_t: sum_t dL/dd_t = sum_n (W_n dL/dS_n + 2 S_n dL/dQ_n), W_n = sum_t w_tn
        for c in range(channels):
            g_centre = grad[b, c, y, x]
            for n in range(sectors):
                g_centre -= sector_weights[n] * g_sums[n, c] + 2.0 * sums[n, c] * g_squares[n]
            g_picture[y, x, c] += g_centre


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _backward(
    image, lanes, major, minor, sharpness, positions, index, weight, total_weight, variance_scale, variance_eps,
    kept_sums, kept_squares, grad, need_image, need_sharpness, g_image_parts, g_image, g_major, g_minor, g_sharpness,
):  # fmt: skip
    batch, height, width = image.shape[:3]
    channels = len(lanes)
    sectors = kept_sums.shape[3]
    parts = g_image_parts.shape[0]
    rows = batch * height
    for part in prange(parts):
        g_part = g_image_parts[part]
        if need_image:
            g_part[:] = 0.0
        blend = np.empty((_BLEND_ROWS, sectors))
        g_sums = np.empty((sectors, channels))
        g_squares = np.empty(sectors)
        sector_weights = np.zeros(sectors)
        for t in range(index.shape[0]):
            for slot in range(_SLOTS):
                sector_weights[index[t, slot]] += weight[t, slot]
        for row in range(part * rows // parts, (part + 1) * rows // parts):
            b, y = row // height, row % height
            picture = image[b]
            g_picture = g_part[b] if need_image else g_part[0]
            for x in range(width):
                sums, squares = kept_sums[b, y, x], kept_squares[b, y, x]
                _backward_pixel(
                    picture, g_picture, b, y, x, major, minor, sharpness, positions, index, weight, total_weight,
                    variance_scale, variance_eps, sector_weights, sums, squares, grad, need_image, need_sharpness,
                    blend, g_sums, g_squares, g_major, g_minor, g_sharpness, channels,
                )  # fmt: skip
    if need_image:  # the parts' sum, in a fixed order, back to (B, C, H, W)
        for row in prange(rows):
            b, y = row // height, row % height
            for x in range(width):
                for c in range(channels):
                    total = g_image_parts[0, b, y, x, c]
                    for part in range(1, parts):
                        total += g_image_parts[part, b, y, x, c]
                    g_image[b, c, y, x] = total


class AnisotropicKuwahara(torch.autograd.Function):
    """The fused ``_SectorSums`` and sector blend of :func:`wise.filters.kuwahara.anisotropic_kuwahara`.

    Inputs: the image ``(B, C, H, W)``, the sampling ellipse's major and minor axis vectors
    ``(B, H, W, 2)`` in grid units (``grid_sample``, ``align_corners=True``), the sharpness ``q``
    (broadcasting to ``(B, 1, H, W)``), the taps of ``_sample_layout``, the number of sectors, the
    weight ``T`` of a sector, the variance scale ``K``, ``eps`` and whether gradients are
    recorded (:func:`torch.is_grad_enabled` of the caller; forward cannot tell). Returns
    ``(B, C, H, W)``; gradients reach the image, both axes and ``q``.
    """

    @staticmethod
    def forward(  # type: ignore[override]
        ctx,
        image: torch.Tensor,
        major: torch.Tensor,
        minor: torch.Tensor,
        sharpness: torch.Tensor,
        taps: Sequence,
        sectors: int,
        total_weight: float,
        variance_scale: float,
        variance_eps: float,
        grad_enabled: bool,
    ) -> torch.Tensor:
        b, c, h, w = image.shape
        arguments = _arguments(image, major, minor, sharpness, taps, total_weight, variance_scale, variance_eps)
        dtype = arguments[0].dtype
        keep = grad_enabled and any(ctx.needs_input_grad)  # the sums for backward, else not kept
        kept_shape = (b, h, w) if keep else (1, 1, 1)
        kept_sums = np.empty((*kept_shape, sectors, c), dtype=dtype)
        kept_squares = np.empty((*kept_shape, sectors), dtype=dtype)
        out = np.empty((b, c, h, w), dtype=dtype)
        with kernel_threads():
            _forward(*arguments, keep, kept_sums, kept_squares, out)
        ctx.save_for_backward(image, major, minor, sharpness)  # checks that they are not changed in place
        ctx.arguments = (*arguments, kept_sums, kept_squares)
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, major, minor, sharpness = ctx.saved_tensors
        b, c, h, w = image.shape
        need_image = ctx.needs_input_grad[0]
        dtype = ctx.arguments[0].dtype
        g_image_parts = np.empty((chunks(), *((b, h, w, c) if need_image else (1, 1, 1, 1))), dtype=dtype)
        g_image = np.empty((b, c, h, w) if need_image else (1, 1, 1, 1), dtype=dtype)
        g_major = np.empty((b, h, w, 2), dtype=dtype)
        g_minor = np.empty_like(g_major)
        g_sharpness = np.empty((b, 1, h, w), dtype=dtype)
        with kernel_threads():
            _backward(
                *ctx.arguments,
                full(grad.to(image.dtype), (b, c, h, w)),
                need_image,
                ctx.needs_input_grad[3],
                g_image_parts,
                g_image,
                g_major,
                g_minor,
                g_sharpness,
            )
        return (
            torch.from_numpy(g_image) if need_image else None,
            reduce_to(torch.from_numpy(g_major), major.shape) if ctx.needs_input_grad[1] else None,
            reduce_to(torch.from_numpy(g_minor), minor.shape) if ctx.needs_input_grad[2] else None,
            reduce_to(torch.from_numpy(g_sharpness), sharpness.shape) if ctx.needs_input_grad[3] else None,
            None,
            None,
            None,
            None,
            None,
            None,
        )


def _arguments(image, major, minor, sharpness, taps, total_weight: float, variance_scale: float, variance_eps: float):
    """The kernels' leading arguments: the image channels-last ``(B, H, W, C)`` (a tap reads all
    channels of a corner at once), a tuple of ``C`` zeros, the axes and ``q`` full-shaped, the taps,
    all of the image's dtype."""
    b, c, h, w = image.shape
    pixels = image.detach().permute(0, 2, 3, 1).contiguous().numpy()
    positions, index, weight = tap_arrays(taps)
    return (
        pixels,
        (0,) * c,  # one lane per channel: the kernels compile for the number of channels
        full(major.to(image.dtype), (b, h, w, 2)),
        full(minor.to(image.dtype), (b, h, w, 2)),
        full(sharpness.to(image.dtype), (b, 1, h, w)),
        positions.astype(pixels.dtype),
        index,
        weight.astype(pixels.dtype),
        float(total_weight),
        float(variance_scale),
        float(variance_eps),
    )
