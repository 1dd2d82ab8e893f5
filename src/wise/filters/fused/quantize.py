"""Fused CPU kernel of the candidate scores of :func:`wise.filters.quantize.quantize`'s numeric
gradient for the number of bins (Lötzsch et al. 2022, supplement, "Color Quantization").

For every candidate bin count ``r = max(b + o, 1)`` (one per offset ``o``) and image, the score
``f(r) = sum_i sign(y_i - q_r(x_i)) sign(g_i)``: one pass over the pixels evaluates every candidate,
where the PyTorch path sets off a dozen full-image tensors per candidate.

The quantizer is evaluated with the same operations in the same order and precision as the
PyTorch path, without reassociation or fused multiply-add (a different rounding could flip the
sign of ``y - q_r(x)`` where the two nearly meet and so change a score). The one exception is
``tanh``, taken from one exponential by a short series (the C library's ``tanh`` costs more than
the rest of the loop): it may differ from PyTorch's in the last bit, so a score can differ where
``y`` and ``q_r(x)`` agree to the last bit (the tests find none in float32 or float64).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import full, kernel_threads

_HALF, _ONE, _MIN_BINS, _LOG2_E, _MIN_EXPONENT = range(5)
"""Positions in the array of constants, which carries them in the image's dtype (a Python
float literal would promote float32 arithmetic to float64 and round differently)."""
MIN_EXPONENT = -60
"""``2 ** -60`` is below half a unit in the last place of 1 in float64: beyond it ``tanh`` is 1."""
_TAYLOR_TERMS = 14
"""Terms of the series of ``2 ** f = e ** (f ln 2)`` for ``|f| <= 1/2``: the next one is below 1e-17."""


@njit(inline="always")
def _exp2(t, constants, powers, series):
    """``2 ** t`` for ``t <= 0``: ``2 ** n`` from a table, ``2 ** f`` (``|f| <= 1/2``) by its Taylor series."""
    t = max(t, constants[_MIN_EXPONENT])
    whole = np.rint(t)
    f = t - whole
    p = series[13]
    p = p * f + series[12]
    p = p * f + series[11]
    p = p * f + series[10]
    p = p * f + series[9]
    p = p * f + series[8]
    p = p * f + series[7]
    p = p * f + series[6]
    p = p * f + series[5]
    p = p * f + series[4]
    p = p * f + series[3]
    p = p * f + series[2]
    p = p * f + series[1]
    p = p * f + series[0]
    return p * powers[-int(whole)]


@njit(inline="always")
def _tanh(z, constants, powers, series):
    """``tanh(z) = sign(z) (1 - e^-2|z|) / (1 + e^-2|z|)``, within a few units in the last place."""
    one = constants[_ONE]
    decay = _exp2(-(abs(z) + abs(z)) * constants[_LOG2_E], constants, powers, series)
    magnitude = (one - decay) / (one + decay)
    return magnitude if z >= 0 else -magnitude


@njit(parallel=True, cache=True)
def _candidate_scores(x, y, grad, bins, softness, offsets, constants, powers, series, soft, partial):
    """``partial[task, k]``: the score of candidate ``k`` over the pixels of one row of one image
    (``task = b * H + row``), so that no two tasks add to the same count."""
    batch, channels, height, width = x.shape
    half, one, min_bins = constants[_HALF], constants[_ONE], constants[_MIN_BINS]
    for task in prange(batch * height):
        b, row = task // height, task % height
        base = bins[b, 0, row]
        ramp_width = softness[b, 0, row]
        ramp_norm = np.empty_like(ramp_width)  # 1 / tanh(1 / 2 softness) / 2, once per pixel
        for column in range(width):
            ramp_norm[column] = half / _tanh(half / ramp_width[column], constants, powers, series) if soft else half
        for k in range(offsets.shape[0]):
            total = 0
            for c in range(channels):
                values, targets, directions = x[b, c, row], y[b, c, row], grad[b, c, row]
                for column in range(width):
                    candidate = max(base[column] + offsets[k], min_bins)
                    scaled = values[column] * candidate
                    last = np.ceil(candidate) - one
                    if soft:  # wise.filters.quantize._soft_levels, operation by operation
                        boundary = min(max(np.rint(scaled), one), max(last, one))
                        ramp = _tanh((scaled - boundary) / ramp_width[column], constants, powers, series)
                        level = (boundary + ramp * ramp_norm[column]) / candidate
                    else:  # _hard_levels
                        level = (min(max(np.floor(scaled), half - half), last) + half) / candidate
                    move = targets[column] - level
                    direction = directions[column]
                    total += ((move > 0) - (move < 0)) * ((direction > 0) - (direction < 0))
            partial[task, k] = total


def candidate_scores(
    x: torch.Tensor,
    y: torch.Tensor,
    grad: torch.Tensor,
    bins: torch.Tensor,
    softness: torch.Tensor | None,
    offsets: list[float],
    min_bins: float,
) -> torch.Tensor:
    """The scores ``(len(offsets), B)`` of the candidates ``max(bins + offset, min_bins)``.

    Args:
        x, y, grad: ``(B, C, H, W)`` quantizer input, its output and the output's gradient.
        bins, softness: ``(B or 1, 1, H or 1, W or 1)`` bin counts and ramp widths (``softness`` None:
            hard steps).
        offsets: the candidates' offsets from ``bins``.
        min_bins: the smallest bin count.
    """
    b, c, h, w = x.shape
    dtype = x.detach().numpy().dtype
    soft = softness is not None
    powers = 2.0 ** -np.arange(-MIN_EXPONENT + 1, dtype=dtype)
    series = np.array([np.log(2.0) ** k / math.factorial(k) for k in range(_TAYLOR_TERMS)], dtype=dtype)
    partial = np.empty((b * h, len(offsets)), dtype=np.int64)
    with kernel_threads():
        _candidate_scores(
            full(x, x.shape),
            full(y, x.shape),
            full(grad, x.shape),
            full(bins, (b, 1, h, w)),
            full(softness if soft else bins, (b, 1, h, w)),  # not read on hard steps
            np.asarray(offsets, dtype=dtype),
            np.asarray((0.5, 1.0, min_bins, 1.0 / np.log(2.0), MIN_EXPONENT), dtype=dtype),
            powers,
            series,
            soft,
            partial,
        )
    return torch.from_numpy(partial.reshape(b, h, len(offsets)).sum(axis=1).T.astype(dtype))
