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

The pass is ``(I(p) + sum w v) / (1 + sum w)`` with ``w = w_pair * exp(|v - I(p)|^2 r)``; the pixel
step ``s = 1 / max(|u_x|, |u_y|)`` and ``a`` are computed in the kernel from the direction and
``sigma_d``, and maps of one value per picture are read as such, so a pass is one kernel over the
pixels. Arithmetic is in the image's dtype. Backward recomputes every sample; it gathers the
gradients of the direction, ``sigma_d`` and ``r`` per pixel and scatters the image's gradient
through the bilinear samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import torch

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import as_tensor, flat, float_type, kernel_threads
from wise.filters.fused._lanes import Grid, PackedGradient, empty_output, maximum

_MIN_PAIR_WEIGHT = 1e-30
"""Floor of ``w_near + w_far`` as on the PyTorch path: both may underflow far out in a narrow Gaussian."""

_SIDES = (1.0, -1.0)


_MIN_DIRECTION = 1e-6
"""Floor of the direction's major component in the pixel step, as in :func:`wise.filters.flow.pixel_step`."""


@dataclass
class _Inputs:
    """The kernel's inputs: the flat image and the lanes' own values of everything per pixel."""

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
    def of(cls, image, direction, spatial, neg_r) -> "_Inputs":
        b, c, h, w = image.shape
        Float = float_type(image.dtype)
        grid = Grid(b, h, w, Float)
        pixels = flat(image, Float)
        directions = flat(direction, Float, (b, 2, h, w))
        ux, uy = grid.load(directions, 0, 2), grid.load(directions, 1, 2)
        sigma = grid.load_broadcast(spatial)
        return cls(
            grid,
            pixels,
            c,
            [grid.load(pixels, k, c) for k in range(c)],
            ux,
            uy,
            1.0 / maximum(maximum(dr.abs(ux), dr.abs(uy)), _MIN_DIRECTION),
            sigma,
            -0.5 / (sigma * sigma),
            grid.load_broadcast(neg_r),
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


def _forward(inputs: _Inputs, samples: int, support: float, output, norm_output) -> None:
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
    scale = 1.0 / (1.0 + norm)
    for k, (centre, total) in enumerate(zip(inputs.centre, totals)):
        grid.store(output, (centre + total) * scale, k, channels)
    grid.store(norm_output, norm)
    dr.eval(output, norm_output)


def _backward(inputs: _Inputs, samples: int, support: float, g_output, output, norm, g_image, g_maps):
    """The gradients: the image's scattered into ``g_image`` (``None`` when not needed), and per
    pixel the direction's two components, ``sigma_d``'s and ``r``'s into the four channels of ``g_maps``."""
    grid, channels = inputs.grid, inputs.channels
    Float = grid.Float
    starts = [grid.channel_start(k, channels) for k in range(channels)]
    # through the normalization (I + T) / (1 + N): the sums' gradients and the centre's own
    scale = 1.0 / (1.0 + grid.load(norm))
    g_passed = [grid.load(g_output, k, channels) * scale for k in range(channels)]
    g_total = g_passed
    g_norm = Float(0.0)
    for k, g in enumerate(g_passed):
        g_norm -= g * grid.load(output, k, channels)
    g_centre = list(g_passed)
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
            g_values = []
            for k, ((_, slope_x, slope_y), difference, g) in enumerate(zip(sampled, differences, g_total)):
                through_range = g_per_difference * difference
                g_value = dr.fma(g, weight, through_range)
                g_values.append(g_value)
                g_centre[k] = g_centre[k] - through_range  # not in place: the list shares g_total's arrays
                g_offset_x = dr.fma(moves_x * g_value, slope_x, g_offset_x)
                g_offset_y = dr.fma(moves_y * g_value, slope_y, g_offset_y)
            if g_image is not None:
                g_image.scatter(g_values, corners)
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
    # the pixel step 1 / max(|u_x|, |u_y|) passes its gradient to the major component
    x_major = dr.abs(inputs.ux) >= dr.abs(inputs.uy)
    major = dr.select(x_major, inputs.ux, inputs.uy)
    g_major = -g_s * inputs.step * inputs.step * dr.sign(major)
    g_major = dr.select(dr.abs(major) > _MIN_DIRECTION, g_major, 0.0)
    grid.store(g_maps, g_ux + dr.select(x_major, g_major, 0.0), 0, 4)
    grid.store(g_maps, g_uy + dr.select(x_major, 0.0, g_major), 1, 4)
    grid.store(g_maps, g_a / (inputs.spatial * inputs.spatial * inputs.spatial), 2, 4)  # a = -1 / (2 sigma^2)
    grid.store(g_maps, g_r, 3, 4)
    if g_image is not None:
        g_image.add(g_centre, grid.pixel)
        dr.eval(g_maps, g_image.array)
    else:
        dr.eval(g_maps)


class BilateralPass(torch.autograd.Function):
    """The fused :func:`wise.filters.bilateral.bilateral_pass` from its prepared inputs: the image,
    the direction ``(B, 2, H, W)``, ``sigma_d`` in pixels and ``r = -1 / (2 sigma_r^2)`` (maps of
    ``(B, 1, H, W)`` or ``(B, 1, 1, 1)``); ``support`` is the cut-off in sigmas
    (:data:`wise.filters.gaussian.SUPPORT`), passed in to keep this module free of the PyTorch filters."""

    @staticmethod
    def forward(ctx, image, direction, spatial, neg_inv_two_range_sq, n: int, support: float):  # type: ignore[override]
        b, c, h, w = image.shape
        with kernel_threads():
            inputs = _Inputs.of(image, direction, spatial, neg_inv_two_range_sq)
            output_array, norm_array = empty_output(inputs.grid, c), empty_output(inputs.grid, 1)
            _forward(inputs, n, support, output_array, norm_array)
            output, norm = as_tensor(output_array, (b, c, h, w)), as_tensor(norm_array, (b, 1, h, w))
        ctx.save_for_backward(image, direction, spatial, neg_inv_two_range_sq, output, norm)
        ctx.n, ctx.support = n, support
        return output

    @staticmethod
    def backward(ctx, grad_output):  # type: ignore[override]
        image, direction, spatial, neg_r, output, norm = ctx.saved_tensors
        b, c, h, w = image.shape
        need = ctx.needs_input_grad
        with kernel_threads():
            inputs = _Inputs.of(image, direction, spatial, neg_r)
            Float = inputs.grid.Float
            g_image_packed = PackedGradient(inputs.grid, c) if need[0] else None
            g_maps_array = empty_output(inputs.grid, 4)
            _backward(
                inputs,
                ctx.n,
                ctx.support,
                flat(grad_output, Float, (b, c, h, w)),
                flat(output, Float),
                flat(norm, Float),
                g_image_packed,
                g_maps_array,
            )
            g_image = g_image_packed.torch((b, c, h, w)) if need[0] else None
            g_maps = as_tensor(g_maps_array, (b, 4, h, w))
        return (
            g_image,
            reduce_to(g_maps[:, 0:2], direction.shape) if need[1] else None,
            reduce_to(g_maps[:, 2:3], spatial.shape) if need[2] else None,
            reduce_to(g_maps[:, 3:4], neg_r.shape) if need[3] else None,
            None,
            None,
        )
