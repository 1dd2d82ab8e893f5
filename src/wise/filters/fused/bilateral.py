"""Fused kernel of :class:`wise.filters.bilateral._BilateralTaps`: the samples of one pass of
the orientation-aligned bilateral filter (Kyprianidis & Döllner 2008, in the grid-sampling form
of Lötzsch et al. 2022, supplement Eq. 3-5), forward and analytic backward, in Dr.Jit.

Per pixel ``p`` (colour ``I(p)``, unit direction ``u``, pixel step ``s``) and merged sample
``j = 1..n`` covering the pixel steps ``2j - 1`` and ``2j`` at the distances ``near = (2j - 1) s``
and ``far = 2j s``:

- spatial weights ``w_near = exp(near^2 a)``, ``w_far = exp(far^2 a)`` with ``a = -1 / (2 sigma_d^2)``,
  the pair's weight ``w_pair = w_near + w_far`` and its weighted mean distance
  ``d_j = (near w_near + far w_far) / w_pair`` (linear sampling: one bilinear read for two steps);
- on each side ``+-``: the bilinear sample ``v = I(p +- d_j u)`` and its range weight
  ``exp(|v - I(p)|^2 r)`` with ``r = -1 / (2 sigma_r^2)`` (Euclidean distance over channels);
- samples with ``near > support * sigma_d`` are left out, except the nearest pair (``j = 1``).

Returns ``sum w v`` (``(B, C, H, W)``) and ``sum w`` (``(B, 1, H, W)``) with
``w = w_pair * exp(|v - I(p)|^2 r)``. Arithmetic is in the image's dtype. Backward recomputes
every sample; it gathers the gradients of the direction, the pixel step and both coefficients per
pixel and scatters the image's gradient through the bilinear samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import torch

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import flat, float_type, kernel_threads, to_torch
from wise.filters.fused._lanes import Grid, maximum

_MIN_PAIR_WEIGHT = 1e-30
"""Floor of ``w_near + w_far`` as on the PyTorch path: both may underflow far out in a narrow Gaussian."""

_SIDES = (1.0, -1.0)


@dataclass
class _Inputs:
    """The kernel's inputs as flat arrays, per-pixel maps loaded into the lanes."""

    grid: Grid
    image: object
    channels: int
    centre: list
    ux: object
    uy: object
    step: object
    spatial: object
    a: object
    r: object

    @classmethod
    def of(cls, image, direction, step, spatial, neg_a, neg_r) -> "_Inputs":
        b, c, h, w = image.shape
        Float = float_type(image.dtype)
        grid = Grid(b, h, w, Float)
        pixels = flat(image, Float)

        def per_pixel(map_: torch.Tensor):
            return grid.load(flat(map_.to(image.dtype), Float, (b, 1, h, w)))

        directions = flat(direction.to(image.dtype), Float, (b, 2, h, w))
        return cls(
            grid,
            pixels,
            c,
            [grid.load(pixels, k, c) for k in range(c)],
            grid.load(directions, 0, 2),
            grid.load(directions, 1, 2),
            per_pixel(step),
            per_pixel(spatial),
            per_pixel(neg_a),
            per_pixel(neg_r),
        )


@dataclass
class _Pair:
    """Merged sample ``j``: its distances, spatial weights and whether it is inside the support."""

    near: object
    far: object
    w_near: object
    w_far: object
    w_pair: object
    distance: object
    inside: object

    @classmethod
    def of(cls, j: int, inputs: _Inputs, support: float) -> "_Pair":
        near, far = (2 * j - 1) * inputs.step, 2 * j * inputs.step
        w_near, w_far = dr.exp(near * near * inputs.a), dr.exp(far * far * inputs.a)
        w_pair = maximum(w_near + w_far, _MIN_PAIR_WEIGHT)
        distance = (near * w_near + far * w_far) / w_pair
        inside = True if j == 1 else near <= support * inputs.spatial
        return cls(near, far, w_near, w_far, w_pair, distance, inside)


def _forward(inputs: _Inputs, samples: int, support: float):
    grid, channels = inputs.grid, inputs.channels
    starts = [grid.channel_start(k, channels) for k in range(channels)]
    totals = [grid.Float(0.0) for _ in range(channels)]
    norm = grid.Float(0.0)
    for j in range(1, samples + 1):
        pair = _Pair.of(j, inputs, support)
        w_pair = dr.select(pair.inside, pair.w_pair, 0.0)
        for sign in _SIDES:
            corners = grid.locate(grid.x + sign * pair.distance * inputs.ux, grid.y + sign * pair.distance * inputs.uy)
            values = [grid.sample(inputs.image, corners, start) for start in starts]
            range_sq = grid.Float(0.0)
            for value, centre in zip(values, inputs.centre):
                range_sq = dr.fma(value - centre, value - centre, range_sq)
            weight = w_pair * dr.exp(range_sq * inputs.r)
            norm += weight
            totals = [dr.fma(weight, value, total) for value, total in zip(values, totals)]
    dr.eval(*totals, norm)
    return totals, norm


def _backward(inputs: _Inputs, samples: int, support: float, grad_total, grad_norm, need_image: bool):
    grid, channels = inputs.grid, inputs.channels
    Float = grid.Float
    starts = [grid.channel_start(k, channels) for k in range(channels)]
    g_total = [grid.load(grad_total, k, channels) for k in range(channels)]
    g_norm = grid.load(grad_norm)
    g_image = dr.zeros(Float, grid.batch * channels * grid.plane) if need_image else None
    g_centre = [Float(0.0) for _ in range(channels)]
    g_ux, g_uy, g_s, g_a, g_r = (Float(0.0) for _ in range(5))
    for j in range(1, samples + 1):
        pair = _Pair.of(j, inputs, support)
        inside = dr.select(pair.inside, Float(1.0), 0.0)
        g_w_pair, g_offset_x, g_offset_y = Float(0.0), Float(0.0), Float(0.0)
        for sign in _SIDES:
            corners = grid.locate(grid.x + sign * pair.distance * inputs.ux, grid.y + sign * pair.distance * inputs.uy)
            sampled = [grid.sample_with_slopes(inputs.image, corners, start) for start in starts]
            differences = [value - centre for (value, _, _), centre in zip(sampled, inputs.centre)]
            range_sq, g_weight = Float(0.0), g_norm
            for (value, _, _), difference, g in zip(sampled, differences, g_total):
                range_sq = dr.fma(difference, difference, range_sq)
                g_weight = dr.fma(g, value, g_weight)
            range_weight = inside * dr.exp(range_sq * inputs.r)
            weight = pair.w_pair * range_weight
            g_log_range = g_weight * weight
            g_r = dr.fma(g_log_range, range_sq, g_r)
            g_w_pair = dr.fma(g_weight, range_weight, g_w_pair)
            g_per_difference = 2.0 * g_log_range * inputs.r
            moves_x = dr.select(corners.moves_x, Float(sign), 0.0)
            moves_y = dr.select(corners.moves_y, Float(sign), 0.0)
            for k, ((_, slope_x, slope_y), difference, g) in enumerate(zip(sampled, differences, g_total)):
                through_range = g_per_difference * difference
                g_value = dr.fma(g, weight, through_range)
                g_centre[k] -= through_range
                g_offset_x = dr.fma(moves_x * g_value, slope_x, g_offset_x)
                g_offset_y = dr.fma(moves_y * g_value, slope_y, g_offset_y)
                if need_image:
                    grid.scatter(g_image, g_value, corners, starts[k])
        # the chain rule through the geometry both sides share: d_j(near, far), near and far of s and a
        g_ux = dr.fma(g_offset_x, pair.distance, g_ux)
        g_uy = dr.fma(g_offset_y, pair.distance, g_uy)
        g_distance_per_pair = (g_offset_x * inputs.ux + g_offset_y * inputs.uy) / pair.w_pair
        g_w_near = g_w_pair + g_distance_per_pair * (pair.near - pair.distance)
        g_w_far = g_w_pair + g_distance_per_pair * (pair.far - pair.distance)
        g_near = g_w_near * pair.w_near * 2.0 * pair.near * inputs.a + g_distance_per_pair * pair.w_near
        g_far = g_w_far * pair.w_far * 2.0 * pair.far * inputs.a + g_distance_per_pair * pair.w_far
        g_a += g_w_near * pair.w_near * pair.near * pair.near + g_w_far * pair.w_far * pair.far * pair.far
        g_s += g_near * (2 * j - 1) + g_far * (2 * j)
    outputs = [*g_centre, g_ux, g_uy, g_s, g_a, g_r]
    dr.eval(*outputs, *([g_image] if need_image else []))
    return g_image, outputs


class BilateralTaps(torch.autograd.Function):
    """The fused :class:`wise.filters.bilateral._BilateralTaps`; ``support`` is the cut-off in sigmas
    (:data:`wise.filters.gaussian.SUPPORT`), passed in to keep this module free of the PyTorch filters."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx, image, direction, step, spatial, neg_inv_two_spatial_sq, neg_inv_two_range_sq, n: int, support: float
    ):
        inputs = (image, direction, step, spatial, neg_inv_two_spatial_sq, neg_inv_two_range_sq)
        b, c, h, w = image.shape
        with kernel_threads():
            totals, norm = _forward(_Inputs.of(*inputs), n, support)
            total, norm = to_torch(totals, (b, h, w)), to_torch([norm], (b, h, w))
        ctx.save_for_backward(*inputs)
        ctx.n, ctx.support = n, support
        return total, norm

    @staticmethod
    def backward(ctx, grad_total, grad_norm):  # type: ignore[override]
        inputs = ctx.saved_tensors
        image, direction, step, _, neg_a, neg_r = inputs
        b, c, h, w = image.shape
        need = ctx.needs_input_grad
        with kernel_threads():
            kernel_inputs = _Inputs.of(*inputs)
            Float = kernel_inputs.grid.Float
            g_image, outputs = _backward(
                kernel_inputs,
                ctx.n,
                ctx.support,
                flat(grad_total.to(image.dtype), Float, (b, c, h, w)),
                flat(grad_norm.to(image.dtype), Float, (b, 1, h, w)),
                need[0],
            )
            g_centre = to_torch(outputs[:c], (b, h, w))
            g_direction = to_torch(outputs[c : c + 2], (b, h, w))
            g_step, g_a, g_r = (to_torch([o], (b, h, w)) for o in outputs[c + 2 :])
            g_image = g_image.torch().view(b, c, h, w) + g_centre if need[0] else None
        return (
            g_image,
            reduce_to(g_direction, direction.shape) if need[1] else None,
            reduce_to(g_step, step.shape) if need[2] else None,
            None,
            reduce_to(g_a, neg_a.shape) if need[4] else None,
            reduce_to(g_r, neg_r.shape) if need[5] else None,
            None,
            None,
        )
