"""Fused kernel of the candidate scores of :func:`wise.filters.quantize.quantize`'s numeric
gradient for the number of bins (Lötzsch et al. 2022, supplement, "Color Quantization"), in Dr.Jit.

For every candidate bin count ``r = max(b + o, 1)`` (one per offset ``o``) and image, the score
``f(r) = sum_i sign(y_i - q_r(x_i)) sign(g_i)``: one lane per pixel evaluates every candidate in a
loop and adds its count (over the channels) to the candidate's score of its image, where the
PyTorch path sets off a dozen full-image tensors per candidate. The scores are integers, so the
order in which the lanes add them does not matter. The scores have no gradient: they run inside
the backward pass of :class:`wise.filters.quantize._NumericBinsGradient`.

The quantizer is evaluated with the same operations in the same order and precision as the
PyTorch path, without reassociation or fused multiply-add (a different rounding could flip the
sign of ``y - q_r(x)`` where the two nearly meet and so change a score). The one exception is
``tanh``, taken from one exponential by a short series (``2 ** n`` built from its exponent bits,
``2 ** f`` by its Taylor series): it may differ from PyTorch's in the last bit, so a score can
differ where ``y`` and ``q_r(x)`` agree to the last bit (the tests find none in float32 or float64).
"""

from __future__ import annotations

import math

import drjit as dr
import torch

from wise.filters.fused._drjit import flat, float_type, kernel_threads
from wise.filters.fused._lanes import Grid

MIN_EXPONENT = -60
"""``2 ** -60`` is below half a unit in the last place of 1 in float64: beyond it ``tanh`` is 1."""
_TAYLOR_TERMS = 14
"""Terms of the series of ``2 ** f = e ** (f ln 2)`` for ``|f| <= 1/2``: the next one is below 1e-17."""
_SERIES = tuple(math.log(2.0) ** k / math.factorial(k) for k in range(_TAYLOR_TERMS))
_LOG2_E = 1.0 / math.log(2.0)


def _types(Float):
    """The signed and unsigned integer types as wide as ``Float``, and its exponent bias and mantissa bits."""
    import drjit.llvm as backend

    if Float is backend.Float64:
        return backend.Int64, backend.UInt64, 1023, 52
    return backend.Int32, backend.UInt32, 127, 23


def _exp2(t, Float):
    """``2 ** t`` for ``t <= 0``: ``2 ** n`` from its exponent bits, ``2 ** f`` (``|f| <= 1/2``) by its
    Taylor series (Horner, no fused multiply-add)."""
    Int, UInt, bias, mantissa = _types(Float)
    t = dr.select(MIN_EXPONENT > t, Float(MIN_EXPONENT), t)
    whole = dr.round(t)  # to the nearest, ties to even
    f = t - whole
    p = Float(_SERIES[-1])
    for coefficient in reversed(_SERIES[:-1]):
        p = p * f + coefficient
    power = dr.reinterpret_array(Float, UInt(Int(whole) + bias) << mantissa)
    return p * power


def _tanh(z, Float):
    """``tanh(z) = sign(z) (1 - e^-2|z|) / (1 + e^-2|z|)``, within a few units in the last place."""
    magnitude = dr.abs(z)
    decay = _exp2(-(magnitude + magnitude) * _LOG2_E, Float)
    ratio = (1.0 - decay) / (1.0 + decay)
    return dr.select(z >= 0, ratio, -ratio)


def _sign(value, Int):
    return dr.select(value > 0, Int(1), Int(0)) - dr.select(value < 0, Int(1), Int(0))


def _candidate_scores(grid: Grid, x, y, grad, channels: int, base, ramp_width, offsets, min_bins: float):
    """The scores ``(K * B)`` (candidate-major) of the ``K`` candidates ``max(base + offsets[k], min_bins)``
    for the flat images ``x``, ``y`` and ``grad`` and the lanes' bins ``base`` and ramp widths
    ``ramp_width`` (None: hard steps); a symbolic loop over the candidates."""
    Float = grid.Float
    Int = dr.int32_array_t(Float)
    UInt = type(grid.pixel)
    candidates = dr.width(offsets)
    values = [grid.load(x, c, channels) for c in range(channels)]
    targets = [grid.load(y, c, channels) for c in range(channels)]
    directions = [_sign(grid.load(grad, c, channels), Int) for c in range(channels)]
    soft = ramp_width is not None
    ramp_norm = 0.5 / _tanh(0.5 / ramp_width, Float) if soft else None  # 1 / tanh(1 / 2 softness) / 2
    scores = dr.zeros(Int, candidates * grid.batch)

    def body(k):
        offset = dr.gather(Float, offsets, k)
        candidate = base + offset
        candidate = dr.select(min_bins > candidate, Float(min_bins), candidate)
        last = dr.ceil(candidate) - 1.0
        total = Int(0)
        for value, target, direction in zip(values, targets, directions):
            scaled = value * candidate
            if soft:  # wise.filters.quantize._soft_levels, operation by operation
                boundary = dr.round(scaled)
                boundary = dr.select(1.0 > boundary, Float(1.0), boundary)
                top = dr.select(1.0 > last, Float(1.0), last)
                boundary = dr.select(top < boundary, top, boundary)
                ramp = _tanh((scaled - boundary) / ramp_width, Float)
                level = (boundary + ramp * ramp_norm) / candidate
            else:  # _hard_levels
                index = dr.floor(scaled)
                index = dr.select(0.0 > index, Float(0.0), index)
                index = dr.select(last < index, last, index)
                level = (index + 0.5) / candidate
            total += _sign(target - level, Int) * direction
        dr.scatter_add(scores, total, k * grid.batch + grid.picture, mode=dr.ReduceMode.Expand)
        return (k + 1,)

    dr.while_loop(state=(dr.zeros(UInt, grid.lanes),), cond=lambda k: k < candidates, body=body)
    dr.eval(scores)
    return scores


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
    dtype = x.dtype
    Float = float_type(dtype)
    with kernel_threads():
        grid = Grid(b, h, w, Float)
        scores = _candidate_scores(
            grid,
            flat(x, Float),
            flat(y.to(dtype), Float),
            flat(grad.to(dtype), Float),
            c,
            grid.load_broadcast(bins),
            None if softness is None else grid.load_broadcast(softness),
            Float(offsets),
            min_bins,
        )
        result = scores.torch().view(len(offsets), b).to(dtype)
    return result
