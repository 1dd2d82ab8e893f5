"""Fused kernel of :func:`wise.filters.gaussian._blur_axis_varying`: one axis of a Gaussian
with a per-pixel sigma and replicated borders, forward and adjoint, in Dr.Jit (the fixed blur
is faster as banded matrix products, :mod:`wise.filters.banded`).

- ``out_n = sum_k w_k v_clamp(n + k) / sum_k w_k`` with ``w_k = exp(-k^2 / (2 sigma_n^2))``
  for ``|k| <= 1`` or ``|k| <= support * sigma_n`` (and ``|k| <= radius``), the weights taken by
  the recurrence ``w_k = w_(k-1) * w_1 * (w_1^2)^(k-1)``; backward scatters the image's gradient
  along the line and gives ``g_sigma = sum_c g_c / (N sigma^3) * sum_k k^2 w_k (v_(n+k) - out)``.

One SIMD lane per pixel; a line is a row (axis 3) or a column (axis 2) read with its stride.
Arithmetic is in the image's dtype.
"""

from __future__ import annotations

import drjit as dr
import torch
from drjit.llvm import Int32, UInt32

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import flat, float_type, kernel_threads, to_torch
from wise.filters.fused._lanes import Grid, runtime


class _Line:
    """Where a lane lies on its line along ``axis`` (3: x, 2: y): its position, the line's
    length and stride, and the flat offset of the line's first pixel."""

    def __init__(self, grid: Grid, axis: int) -> None:
        row, column = grid.row, grid.column
        along = column if axis == 3 else row
        self.size = runtime(Int32, grid.width if axis == 3 else grid.height)
        self.stride = 1 if axis == 3 else grid.runtime_width
        self.position = Int32(along)
        self.start = grid.picture * grid.runtime_plane + grid.pixel - along * self.stride

    def index(self, position):
        """The flat offset of ``position`` (Int32, within the line) in a one-channel array."""
        return self.start + UInt32(position) * self.stride

    def clamped(self, offset):
        """The flat offset of the pixel ``offset`` away along the line, clamped to the line."""
        return self.index(dr.clip(self.position + offset, 0, self.size - 1))


class _Varying:
    """The inputs of the varying blur as lanes: the image, its channels' offsets, the line and
    the per-pixel sigma with the start of its weight recurrence."""

    def __init__(self, image: torch.Tensor, sigma: torch.Tensor, axis: int, radius: int, support: float) -> None:
        b, c, h, w = image.shape
        Float = float_type(image.dtype)
        self.grid = grid = Grid(b, h, w, Float)
        self.Float, self.channels = Float, c
        self.pixels = flat(image, Float)
        self.line = _Line(grid, axis)
        self.starts = [k * grid.runtime_plane for k in range(c)]
        self.own = [grid.channel_start(k, c) + grid.pixel for k in range(c)]
        self.sigma = grid.load_broadcast(sigma)
        self.support = support
        self.reach = support * self.sigma
        self.first = dr.exp(-0.5 / (self.sigma * self.sigma))  # w_1
        self.radius = dr.opaque(Int32, radius)  # a parameter: one kernel for every radius

    def going_on(self, k):
        """Whether tap ``k`` counts: within the radius, and the nearest or within the support."""
        return (k <= self.radius) & ((k <= 1) | (self.Float(k) <= self.reach))

    def neighbours(self, k):
        """Flat offsets of the pixels ``k`` before and after the lane's along its line, clamped,
        within one channel of a ``(B, C, H, W)`` array (add the channel's ``start``)."""
        before, after = self.line.clamped(-k), self.line.clamped(k)
        picture = self.grid.picture * ((self.channels - 1) * self.grid.runtime_plane)
        return before + picture, after + picture

    def pair(self, k, channel: int):
        before, after = self.neighbours(k)
        start = self.starts[channel]
        return dr.gather(self.Float, self.pixels, before + start) + dr.gather(self.Float, self.pixels, after + start)


def _varying_lines(inputs: _Varying):
    """The blurred channels of the lanes' pixels."""
    Float = inputs.Float
    step = inputs.first * inputs.first
    centre = [dr.gather(Float, inputs.pixels, own) for own in inputs.own]

    def body(k, weight, ratio, norm, *totals):
        weight = weight * ratio
        totals = tuple(dr.fma(weight, inputs.pair(k, c), total) for c, total in enumerate(totals))
        return (k + 1, weight, ratio * step, dr.fma(2.0, weight, norm), *totals)

    state = (Int32(1), Float(1.0), inputs.first, Float(1.0), *centre)
    _, _, _, norm, *totals = dr.while_loop(state, lambda k, *_: inputs.going_on(k), body)
    out = [total / norm for total in totals]
    dr.eval(*out)
    return out


def _varying_lines_adjoint(inputs: _Varying, grad, need_image: bool):
    """Sigma's gradient and, for the image's, each pixel's output gradient over its norm,
    ``g_total = g / N``, with the sums of the weights of its taps that fell beyond the first and
    the last pixel of its line (which the replicated border gives to those pixels)."""
    Float, channels, line = inputs.Float, inputs.channels, inputs.line
    step = inputs.first * inputs.first
    centre = [dr.gather(Float, inputs.pixels, own) for own in inputs.own]
    last = line.size - 1

    def sums(k, weight, ratio, norm, moment, beyond_first, beyond_last, *per_channel):
        # totals sum_k w_k v (with the centre) and spreads sum_k k^2 w_k v per channel
        weight = weight * ratio
        k_sq = Float(k * k)
        totals, spreads = list(per_channel[:channels]), list(per_channel[channels:])
        for c in range(channels):
            pair = inputs.pair(k, c)
            totals[c] = dr.fma(weight, pair, totals[c])
            spreads[c] = dr.fma(k_sq * weight, pair, spreads[c])
        norm = dr.fma(2.0, weight, norm)
        moment = dr.fma(2.0 * k_sq, weight, moment)
        beyond_first += dr.select(k > line.position, weight, 0.0)
        beyond_last += dr.select(k > last - line.position, weight, 0.0)
        return (k + 1, weight, ratio * step, norm, moment, beyond_first, beyond_last, *totals, *spreads)

    zeros = [Float(0.0) for _ in range(3 + channels)]  # moment, beyond the ends, spreads
    state = (Int32(1), Float(1.0), inputs.first, Float(1.0), *zeros[:3], *centre, *zeros[3:])
    _, _, _, norm, moment, beyond_first, beyond_last, *per_channel = dr.while_loop(
        state, lambda k, *_: inputs.going_on(k), sums
    )
    totals, spreads = per_channel[:channels], per_channel[channels:]
    g_totals = [dr.gather(Float, grad, own) / norm for own in inputs.own]
    g_deviation = Float(0.0)
    for total, spread, g_total in zip(totals, spreads, g_totals):
        g_deviation = dr.fma(g_total, spread - total / norm * moment, g_deviation)
    sigma = inputs.sigma
    g_sigma = g_deviation / (sigma * sigma * sigma)
    if not need_image:
        dr.eval(g_sigma)
        return g_sigma, None
    dr.eval(g_sigma, sigma, beyond_first, beyond_last, *g_totals)  # sigma per pixel, for the gathers
    return g_sigma, (g_totals, beyond_first, beyond_last)


def _varying_lines_gather(inputs: _Varying, g_totals: list):
    """The image's gradient within the lines: ``g_total`` of the pixel itself and of every pixel
    ``n = m -+ k`` whose tap ``k`` reads the lane's pixel ``m``, weighted by ``w_k(sigma_n)``, as
    gathers (the border's share is added by the caller). Every lane runs all ``radius`` taps."""
    Float, line = inputs.Float, inputs.line
    sigma_flat = inputs.sigma  # evaluated by the first pass
    own = line.index(line.position)
    totals = [dr.gather(Float, g_total, own) for g_total in g_totals]

    def body(k, *totals):
        totals = list(totals)
        distance = Float(k)
        for other in (line.position + k, line.position - k):
            inside = (other >= 0) & (other < line.size)
            index = line.index(dr.select(inside, other, 0))
            deviation = dr.gather(Float, sigma_flat, index, active=inside)
            counts = inside & ((k <= 1) | (distance <= inputs.support * deviation))
            weight = dr.select(counts, dr.exp(-0.5 * distance * distance / (deviation * deviation)), 0.0)
            for c, g_total in enumerate(g_totals):
                totals[c] = dr.fma(weight, dr.gather(Float, g_total, index, active=inside), totals[c])
        return (k + 1, *totals)

    _, *totals = dr.while_loop((Int32(1), *totals), lambda k, *_: k <= inputs.radius, body)
    dr.eval(*totals)
    return totals


class VaryingBlurAxis(torch.autograd.Function):
    """The fused :func:`wise.filters.gaussian._blur_axis_varying`: one axis (3: x, 2: y) of a Gaussian
    whose ``sigma`` (pixels, broadcasts to ``(B, 1, H, W)``) varies per pixel, cut off at ``support``
    sigma but always reaching the nearest neighbours, at most ``radius`` pixels; borders replicated."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx, image: torch.Tensor, sigma: torch.Tensor, axis: int, radius: int, support: float
    ) -> torch.Tensor:
        b, _, h, w = image.shape
        with kernel_threads():
            out = to_torch(_varying_lines(_Varying(image, sigma, axis, radius, support)), (b, h, w))
        ctx.save_for_backward(image, sigma)
        ctx.axis, ctx.radius, ctx.support = axis, radius, support
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, sigma = ctx.saved_tensors
        b, c, h, w = image.shape
        need = ctx.needs_input_grad
        with kernel_threads():
            inputs = _Varying(image, sigma, ctx.axis, ctx.radius, ctx.support)
            g_sigma, parts = _varying_lines_adjoint(
                inputs, flat(grad.to(image.dtype), inputs.Float, (b, c, h, w)), need[0]
            )
            g_sigma = to_torch([g_sigma], (b, h, w))
            g_image = None
            if need[0]:
                g_totals, beyond_first, beyond_last = parts
                g_image = to_torch(_varying_lines_gather(inputs, g_totals), (b, h, w))
                _add_border_share(g_image, g_totals, beyond_first, beyond_last, ctx.axis, ctx.radius)
        return (
            g_image,
            reduce_to(g_sigma, sigma.shape) if need[1] else None,
            None,
            None,
            None,
        )


def _add_border_share(g_image: torch.Tensor, g_totals: list, beyond_first, beyond_last, axis: int, radius: int) -> None:
    """Add to the first and the last pixel of each line the gradient of the taps that fell beyond
    them (the adjoint of the replicated border): ``sum_n g_total_n * beyond_n`` over the line's
    first or last ``radius`` pixels, the only ones whose taps reach past its ends."""
    b, _, h, w = g_image.shape
    dim, size = axis - 1, g_image.shape[axis]  # the line's dimension in a (B, H, W) channel
    count = min(radius, size)
    for end, start, beyond in ((0, 0, beyond_first), (size - 1, size - count, beyond_last)):
        weights = beyond.torch().view(b, h, w).narrow(dim, start, count)
        shares = [(g.torch().view(b, h, w).narrow(dim, start, count) * weights).sum(dim) for g in g_totals]
        g_image.narrow(axis, end, 1).add_(torch.stack(shares, dim=1).unsqueeze(axis))
