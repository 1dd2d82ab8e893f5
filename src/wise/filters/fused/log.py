"""Fused kernel of the sample sums of :func:`wise.filters.log.flow_log`, the Laplacian of
Gaussian across the flow (Kyprianidis 2011), in Dr.Jit.

For sample ``k`` of a pixel, ``k + 1`` pixel steps to both sides along the direction, with
``u`` the distance in sigmas, ``g = exp(-u^2 / 2)`` (0 beyond ``extent`` but for the nearest
samples) and ``g'' = (u^2 - 1) g``, the sums of ``g'' v``, ``g v`` (``v`` the two samples
added), ``2 g''``, ``2 g``, ``2 g'' u^2`` and ``2 g u^2``, as ``_log_tap`` of the PyTorch path.
Backward gives the gradients of the image (scattered into per-thread copies), the direction, the
pixel step and ``1 / sigma``.

One SIMD lane per pixel; the samples are a symbolic loop that each lane leaves at its own
extent, so one compiled kernel serves every number of steps. Arithmetic is in the image's dtype.
"""

from __future__ import annotations

import drjit as dr
import torch
from drjit.llvm import Int32

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import flat, float_type, kernel_threads, to_torch
from wise.filters.fused._lanes import Grid, PackedGradient

_MOMENTS = 4
"""``2 g''``, ``2 g``, ``2 g'' u^2`` and ``2 g u^2`` summed over the samples."""


class _Inputs:
    """The kernel's inputs as lanes: the image, the direction, the pixel step, ``1 / sigma``, the
    number of steps and the start of the recurrence of the Gaussian weights."""

    def __init__(self, image, direction, step, inv_sigma, steps: int, extent: float) -> None:
        b, c, h, w = image.shape
        Float = float_type(image.dtype)
        self.grid = grid = Grid(b, h, w, Float)
        self.Float, self.channels = Float, c
        self.pixels = flat(image, Float)
        direction = direction.to(image.dtype)
        self.ux = grid.load_broadcast(direction[:, 0:1])
        self.uy = grid.load_broadcast(direction[:, 1:2])
        self.step = grid.load_broadcast(step)
        self.inverse = grid.load_broadcast(inv_sigma)
        self.steps = dr.opaque(Int32, steps)  # a parameter: one kernel for every count
        self.extent = extent
        self.starts = [grid.channel_start(k, c) for k in range(c)]
        # g_k = exp(-(k step / sigma)^2 / 2): g_1, g_2 / g_1 and the constant ratio of successive ratios
        unit = -0.5 * dr.square(self.step * self.inverse)
        self.gauss, self.growth, self.ratio = dr.exp(unit), dr.exp(3.0 * unit), dr.exp(2.0 * unit)

    def going_on(self, k):
        """Whether sample ``k`` counts: within the steps, and the nearest or within the extent."""
        u = self.Float(k + 1) * self.step * self.inverse
        return (k < self.steps) & ((k == 0) | (u <= self.extent))

    def sides(self, distance):
        """The corners of the samples ``distance`` ahead and behind along the direction."""
        grid = self.grid
        ahead = grid.locate(grid.x + distance * self.ux, grid.y + distance * self.uy)
        behind = grid.locate(grid.x - distance * self.ux, grid.y - distance * self.uy)
        return ahead, behind


def _log_forward(inputs: _Inputs):
    Float, channels = inputs.Float, inputs.channels
    grid = inputs.grid

    def body(k, gauss, growth, *sums):
        second_v, gauss_v, moments = sums[:channels], sums[channels : 2 * channels], sums[2 * channels :]
        distance = Float(k + 1) * inputs.step
        u = distance * inputs.inverse
        u_sq = u * u
        second = (u_sq - 1.0) * gauss
        ahead, behind = inputs.sides(distance)
        both = [grid.sample(inputs.pixels, ahead, s) + grid.sample(inputs.pixels, behind, s) for s in inputs.starts]
        second_v = [dr.fma(second, v, total) for v, total in zip(both, second_v)]
        gauss_v = [dr.fma(gauss, v, total) for v, total in zip(both, gauss_v)]
        terms = (2.0 * second, 2.0 * gauss, 2.0 * second * u_sq, 2.0 * gauss * u_sq)
        moments = [total + term for total, term in zip(moments, terms)]
        return (k + 1, gauss * growth, growth * inputs.ratio, *second_v, *gauss_v, *moments)

    zeros = (Float(0.0) for _ in range(2 * channels + _MOMENTS))
    state = (Int32(0), inputs.gauss, inputs.growth, *zeros)
    _, _, _, *sums = dr.while_loop(state, lambda k, *_: inputs.going_on(k), body)
    dr.eval(*sums)
    return sums[:channels], sums[channels : 2 * channels], sums[2 * channels :]


def _log_backward(inputs: _Inputs, grad_second_v, grad_gauss_v, grad_moments, need_image: bool):
    grid, Float, channels = inputs.grid, inputs.Float, inputs.channels
    g_second_v = [grid.load(grad_second_v, c, channels) for c in range(channels)]
    g_gauss_v = [grid.load(grad_gauss_v, c, channels) for c in range(channels)]
    g_second_sum, g_gauss_sum, g_second_u2, g_gauss_u2 = (grid.load(grad_moments, m, _MOMENTS) for m in range(4))
    g_image = PackedGradient(grid, channels) if need_image else None
    ux, uy, inverse = inputs.ux, inputs.uy, inputs.inverse

    def body(k, gauss, growth, g_ux, g_uy, g_step, g_inverse):
        distance = Float(k + 1) * inputs.step
        u = distance * inverse
        u_sq = u * u
        second = (u_sq - 1.0) * gauss
        ahead, behind = inputs.sides(distance)
        g_second = 2.0 * g_second_sum + 2.0 * g_second_u2 * u_sq
        g_gauss = 2.0 * g_gauss_sum + 2.0 * g_gauss_u2 * u_sq
        g_offset_x, g_offset_y = Float(0.0), Float(0.0)
        g_values = []
        for start, g_s, g_g in zip(inputs.starts, g_second_v, g_gauss_v):
            value_a, slope_xa, slope_ya = grid.sample_with_slopes(inputs.pixels, ahead, start)
            value_b, slope_xb, slope_yb = grid.sample_with_slopes(inputs.pixels, behind, start)
            g_second = dr.fma(g_s, value_a + value_b, g_second)
            g_gauss = dr.fma(g_g, value_a + value_b, g_gauss)
            g_both = g_s * second + g_g * gauss
            g_values.append(g_both)
            along_x = dr.select(ahead.moves_x, slope_xa, 0.0) - dr.select(behind.moves_x, slope_xb, 0.0)
            along_y = dr.select(ahead.moves_y, slope_ya, 0.0) - dr.select(behind.moves_y, slope_yb, 0.0)
            g_offset_x = dr.fma(g_both, along_x, g_offset_x)
            g_offset_y = dr.fma(g_both, along_y, g_offset_y)
        if need_image:
            g_image.scatter(g_values, ahead)
            g_image.scatter(g_values, behind)
        # g'' = (u^2 - 1) g and g = exp(-u^2 / 2): back to u^2, then to u
        g_gauss_total = g_gauss + g_second * (u_sq - 1.0)
        g_u_sq = 2.0 * g_second_u2 * second + 2.0 * g_gauss_u2 * gauss + g_second * gauss - 0.5 * g_gauss_total * gauss
        g_u = 2.0 * u * g_u_sq
        g_distance = g_u * inverse + g_offset_x * ux + g_offset_y * uy
        return (
            k + 1,
            gauss * growth,
            growth * inputs.ratio,
            dr.fma(g_offset_x, distance, g_ux),
            dr.fma(g_offset_y, distance, g_uy),
            dr.fma(g_distance, Float(k + 1), g_step),
            dr.fma(g_u, distance, g_inverse),
        )

    state = (Int32(0), inputs.gauss, inputs.growth, *(Float(0.0) for _ in range(4)))
    _, _, _, *g_maps = dr.while_loop(state, lambda k, *_: inputs.going_on(k), body)
    dr.eval(*g_maps, *([g_image.array] if need_image else []))
    return g_image, g_maps


class LogTaps(torch.autograd.Function):
    """The six sums of ``_log_tap`` over ``steps`` samples; see the module docstring."""

    @staticmethod
    def forward(ctx, image, direction, step, inv_sigma, steps: int, extent: float):  # type: ignore[override]
        b, c, h, w = image.shape
        with kernel_threads():
            second_v, gauss_v, moments = _log_forward(_Inputs(image, direction, step, inv_sigma, steps, extent))
            second_v, gauss_v = to_torch(second_v, (b, h, w)), to_torch(gauss_v, (b, h, w))
            moments = [to_torch([m], (b, h, w)) for m in moments]
        ctx.save_for_backward(image, direction, step, inv_sigma)
        ctx.steps, ctx.extent = steps, extent
        return (second_v, gauss_v, *moments)

    @staticmethod
    def backward(ctx, grad_second_v, grad_gauss_v, *grad_moments):  # type: ignore[override]
        image, direction, step, inv_sigma = ctx.saved_tensors
        b, c, h, w = image.shape
        wanted = ctx.needs_input_grad
        need_image = wanted[0]
        moments = torch.cat([g.to(image.dtype).expand(b, 1, h, w) for g in grad_moments], dim=1)
        with kernel_threads():
            inputs = _Inputs(image, direction, step, inv_sigma, ctx.steps, ctx.extent)
            Float = inputs.Float
            g_image, g_maps = _log_backward(
                inputs,
                flat(grad_second_v.to(image.dtype), Float, (b, c, h, w)),
                flat(grad_gauss_v.to(image.dtype), Float, (b, c, h, w)),
                flat(moments, Float),
                need_image,
            )
            g_direction = to_torch(g_maps[:2], (b, h, w))
            g_step, g_inverse = (to_torch([g], (b, h, w)) for g in g_maps[2:])
            g_image = g_image.torch((b, c, h, w)) if need_image else None
        return (
            g_image,
            reduce_to(g_direction, direction.shape) if wanted[1] else None,
            reduce_to(g_step, step.shape) if wanted[2] else None,
            reduce_to(g_inverse, inv_sigma.shape) if wanted[3] else None,
            None,
            None,
        )
