"""Fused kernels of :mod:`wise.filters.dog`: the line-integral smoothing along the flow and the
difference of Gaussians across it, forward and analytic backward, in Dr.Jit.

:class:`DogTaps` sums the samples across the flow for the narrow and the wide Gaussian of
:func:`wise.filters.dog.flow_dog` (Winnemöller et al. 2012) in one pass over the pixels, with
the analytic backward of :class:`wise.filters.dog._DogTaps`. Per pixel ``p`` (unit direction
``u``, sample spacing ``s``) and sample ``i = 1..n`` at the distance ``d_i = i s``: the bilinear
samples ``v_i = I(p + d_i u) + I(p - d_i u)`` of both sides, weighted by
``w_i = exp(d_i^2 a)`` with ``a = -1 / (2 sigma^2)`` of either Gaussian; samples beyond
``support`` wide sigmas are left out, except the nearest (``i = 1``).

:func:`wise.filters.dog.flow_smoothing` sums Gaussian-weighted bilinear samples along each
pixel's streamline (line integral convolution, Cabral & Leedom 1993): Euler steps of
``step_length`` pixels along the tangent, each step's tangent sampled where the last one
landed, flipped to agree with the last heading and normalized. The PyTorch path traces every
streamline as ``2 * steps`` full-image grids and sums one full-image tensor per sample; here
each pixel (one SIMD lane) traces both its streamlines in one loop that stops at the last
sample within ``support`` sigmas, and keeps its sums in registers. Backward traces again and
gives the gradients of the image and of the Gaussian's coefficient ``-1 / (2 sigma^2)`` (the
streamline geometry is fixed, as on the PyTorch path).

Arithmetic is in the image's dtype. The image's gradient is scattered through the bilinear
samples into one copy per thread, summed at the end.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import torch
from drjit.llvm import UInt32

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import as_tensor, flat, float_type, kernel_threads
from wise.filters.fused._lanes import Grid, PackedGradient, empty_output, maximum, runtime

_MIN_TANGENT_LENGTH = 1e-6


def _grid(image: torch.Tensor) -> Grid:
    b, _, h, w = image.shape
    return Grid(b, h, w, float_type(image.dtype))


def _full(grid: Grid, tensor: torch.Tensor, channels: int):
    """A ``(B, channels, H, W)`` tensor (perhaps broadcast) as a flat array of that shape."""
    return flat(tensor, grid.Float, (grid.batch, channels, grid.height, grid.width))


def _lanes(grid: Grid, tensor: torch.Tensor, channels: int) -> list:
    """Each channel of a ``(B, channels, H, W)`` tensor (perhaps broadcast) at the lane's pixel."""
    array = _full(grid, tensor, channels)
    return [grid.load(array, k, channels) for k in range(channels)]


# --- line-integral smoothing along the flow ---


@dataclass
class _Streamlines:
    """The inputs of the smoothing as lanes and flat arrays."""

    grid: Grid
    image: object
    image_starts: list
    tangent: object
    tangent_starts: list
    heading_x: object
    heading_y: object
    reach: object
    coefficient: object
    steps: object
    step_length: object

    @classmethod
    def of(cls, image, tangent, sigma, coefficient, steps: int, step_length: float, support: float) -> "_Streamlines":
        grid = _grid(image)
        c = image.shape[1]
        tangents = _full(grid, tangent.to(image.dtype), 2)
        return cls(
            grid,
            flat(image, grid.Float),
            [grid.channel_start(k, c) for k in range(c)],
            tangents,
            [grid.channel_start(k, 2) for k in range(2)],
            grid.load(tangents, 0, 2),
            grid.load(tangents, 1, 2),
            support * grid.load_broadcast(sigma),
            grid.load_broadcast(coefficient),
            # run-time values: one kernel serves every count and length of steps
            runtime(UInt32, steps),
            runtime(grid.Float, step_length),
        )

    def start(self):
        """The state of both streamlines before the first step: offsets and headings, forward then backward."""
        zero = dr.zeros(self.grid.Float, self.grid.lanes)
        return (zero, zero, self.heading_x, self.heading_y, zero, zero, -self.heading_x, -self.heading_y)

    def distance(self, k):
        """The distance of step ``k`` (counted from 0) from the pixel."""
        return self.grid.Float(k + 1) * self.step_length

    def goes_on(self, k):
        """Whether a lane takes step ``k``: within the steps and the support (the first step always)."""
        return (k < self.steps) & ((k == 0) | (self.distance(k) <= self.reach))

    def step(self, offset_x, offset_y, heading_x, heading_y):
        """One Euler step: the new offset, its bilinear corners and the heading sampled there."""
        grid = self.grid
        offset_x = dr.fma(heading_x, self.step_length, offset_x)
        offset_y = dr.fma(heading_y, self.step_length, offset_y)
        corners = grid.locate(grid.x + offset_x, grid.y + offset_y)
        sampled_x = grid.sample(self.tangent, corners, self.tangent_starts[0])
        sampled_y = grid.sample(self.tangent, corners, self.tangent_starts[1])
        agree = dr.fma(sampled_x, heading_x, sampled_y * heading_y)
        flip = dr.select(agree < 0.0, grid.Float(-1.0), 1.0)
        scale = flip / maximum(dr.sqrt(dr.fma(sampled_x, sampled_x, sampled_y * sampled_y)), _MIN_TANGENT_LENGTH)
        return (offset_x, offset_y, sampled_x * scale, sampled_y * scale), corners


def _smoothing_forward(lines: _Streamlines, total_output, norm_output) -> None:
    grid = lines.grid
    channels = len(lines.image_starts)

    def body(k, *state):
        ahead, corners_ahead = lines.step(*state[0:4])
        behind, corners_behind = lines.step(*state[4:8])
        distance = lines.distance(k)
        weight = dr.exp(distance * distance * lines.coefficient)
        norm = dr.fma(2.0, weight, state[8])
        totals = [
            dr.fma(
                weight,
                grid.sample(lines.image, corners_ahead, start) + grid.sample(lines.image, corners_behind, start),
                total,
            )
            for start, total in zip(lines.image_starts, state[9:])
        ]
        return (k + 1, *ahead, *behind, norm, *totals)

    zero = dr.zeros(grid.Float, grid.lanes)
    start = (dr.zeros(UInt32, grid.lanes), *lines.start(), *([zero] * (1 + channels)))
    state = dr.while_loop(state=start, cond=lambda k, *_: lines.goes_on(k), body=body)
    for k, total in enumerate(state[10:]):
        grid.store(total_output, total, k, channels)
    grid.store(norm_output, state[9])
    dr.eval(total_output, norm_output)


def _smoothing_backward(lines: _Streamlines, grad_total: list, grad_norm, g_image, g_coefficient_output) -> None:
    """The coefficient's gradient into ``g_coefficient_output``, the image's scattered into
    ``g_image`` (a :class:`PackedGradient`, ``None`` when not needed)."""
    grid = lines.grid

    def body(k, *state):
        ahead, corners_ahead = lines.step(*state[0:4])
        behind, corners_behind = lines.step(*state[4:8])
        distance = lines.distance(k)
        weight = dr.exp(distance * distance * lines.coefficient)
        g_weight = 2.0 * grad_norm
        for start, g in zip(lines.image_starts, grad_total):
            both = grid.sample(lines.image, corners_ahead, start) + grid.sample(lines.image, corners_behind, start)
            g_weight = dr.fma(g, both, g_weight)
        if g_image is not None:
            g_values = [g * weight for g in grad_total]
            g_image.scatter(g_values, corners_ahead)
            g_image.scatter(g_values, corners_behind)
        g_coefficient = dr.fma(g_weight * weight, distance * distance, state[8])
        return (k + 1, *ahead, *behind, g_coefficient)

    zero = dr.zeros(grid.Float, grid.lanes)
    start = (dr.zeros(UInt32, grid.lanes), *lines.start(), zero)
    grid.store(g_coefficient_output, dr.while_loop(state=start, cond=lambda k, *_: lines.goes_on(k), body=body)[9])
    dr.eval(g_coefficient_output, *([g_image.array] if g_image is not None else []))


class FlowSmoothingTaps(torch.autograd.Function):
    """``sum_k w_k v_k`` and ``sum_k w_k`` over the samples of :func:`wise.filters.dog.flow_smoothing`
    on both streamlines of every pixel, ``w_k = exp(d_k^2 a)`` cut off beyond ``support * sigma``
    (the nearest samples always count). Gradients reach the image and ``a``."""

    @staticmethod
    def forward(ctx, image, tangent, sigma, coefficient, steps: int, step_length: float, support: float):  # type: ignore[override]
        b, c, h, w = image.shape
        with kernel_threads():
            lines = _Streamlines.of(image, tangent, sigma, coefficient, steps, step_length, support)
            total_array, norm_array = empty_output(lines.grid, c), empty_output(lines.grid, 1)
            _smoothing_forward(lines, total_array, norm_array)
            total, norm = as_tensor(total_array, (b, c, h, w)), as_tensor(norm_array, (b, 1, h, w))
        ctx.save_for_backward(image, tangent, sigma, coefficient)
        ctx.settings = (steps, step_length, support)
        return total, norm

    @staticmethod
    def backward(ctx, grad_total, grad_norm):  # type: ignore[override]
        image, tangent, sigma, coefficient = ctx.saved_tensors
        b, c, h, w = image.shape
        need_image = ctx.needs_input_grad[0]
        with kernel_threads():
            lines = _Streamlines.of(image, tangent, sigma, coefficient, *ctx.settings)
            grid = lines.grid
            g_image = PackedGradient(grid, c) if need_image else None
            g_coefficient_array = empty_output(grid, 1)
            _smoothing_backward(
                lines, _lanes(grid, grad_total, c), _lanes(grid, grad_norm, 1)[0], g_image, g_coefficient_array
            )
            g_image = g_image.torch((b, c, h, w)) if need_image else None
            g_coefficient = as_tensor(g_coefficient_array, (b, 1, h, w))
        return (
            g_image,
            None,
            None,
            reduce_to(g_coefficient, coefficient.shape) if ctx.needs_input_grad[3] else None,
            None,
            None,
            None,
        )


# --- difference of Gaussians across the flow ---


@dataclass
class _Across:
    """The inputs of the DoG's samples as lanes and flat arrays."""

    grid: Grid
    image: object
    image_starts: list
    ux: object
    uy: object
    spacing: object
    reach: object
    narrow: object
    wide: object
    count: object

    @classmethod
    def of(
        cls, image, direction, step, wide, narrow_coefficient, wide_coefficient, steps: int, support: float
    ) -> "_Across":
        grid = _grid(image)
        c = image.shape[1]
        ux, uy = _lanes(grid, direction.to(image.dtype), 2)
        return cls(
            grid,
            flat(image, grid.Float),
            [grid.channel_start(k, c) for k in range(c)],
            ux,
            uy,
            _lanes(grid, step.to(image.dtype), 1)[0],
            support * grid.load_broadcast(wide),
            grid.load_broadcast(narrow_coefficient),
            grid.load_broadcast(wide_coefficient),
            runtime(UInt32, steps),  # one kernel serves every count of samples
        )

    def goes_on(self, i):
        """Whether a lane takes sample ``i`` (from 1): within the samples and the support (the first always)."""
        return (i <= self.count) & ((i == 1) | (self.grid.Float(i) * self.spacing <= self.reach))

    def sample(self, i):
        """Sample ``i``: its distance, its square, both weights and both sides' corners."""
        grid = self.grid
        distance = grid.Float(i) * self.spacing
        distance_sq = distance * distance
        w_narrow = dr.exp(distance_sq * self.narrow)
        w_wide = dr.exp(distance_sq * self.wide)
        ahead = grid.locate(grid.x + distance * self.ux, grid.y + distance * self.uy)
        behind = grid.locate(grid.x - distance * self.ux, grid.y - distance * self.uy)
        return distance, distance_sq, w_narrow, w_wide, ahead, behind

    def over_samples(self, state: tuple, body) -> tuple:
        """``state = body(i, *state)`` for the samples ``i = 1, 2, ...`` that each lane takes."""
        first = dr.full(UInt32, 1, self.grid.lanes)
        return dr.while_loop(
            state=(first, *state), cond=lambda i, *_: self.goes_on(i), body=lambda i, *rest: (i + 1, *body(i, *rest))
        )[1:]


def _dog_forward(across: _Across, sum_outputs: tuple, norm_outputs: tuple) -> None:
    grid = across.grid
    channels = len(across.image_starts)

    def body(i, norm_narrow, norm_wide, *sums):
        _, _, w_narrow, w_wide, ahead, behind = across.sample(i)
        both = [
            grid.sample(across.image, ahead, start) + grid.sample(across.image, behind, start)
            for start in across.image_starts
        ]
        narrow = [dr.fma(w_narrow, value, total) for value, total in zip(both, sums[:channels])]
        wide = [dr.fma(w_wide, value, total) for value, total in zip(both, sums[channels:])]
        return (dr.fma(2.0, w_narrow, norm_narrow), dr.fma(2.0, w_wide, norm_wide), *narrow, *wide)

    zero = dr.zeros(grid.Float, grid.lanes)
    state = across.over_samples((zero,) * (2 + 2 * channels), body)
    for gaussian, (sum_output, norm_output) in enumerate(zip(sum_outputs, norm_outputs)):
        for k in range(channels):
            grid.store(sum_output, state[2 + gaussian * channels + k], k, channels)
        grid.store(norm_output, state[gaussian])
    dr.eval(*sum_outputs, *norm_outputs)


def _dog_backward(across: _Across, grad_narrow: list, grad_wide: list, g_norms: tuple, g_image, g_maps) -> None:
    """The gradients of the direction, the spacing and both coefficients into ``g_maps``
    (``(B, 5, H, W)``), the image's scattered into ``g_image`` (``None`` when not needed)."""
    grid = across.grid
    g_norm_narrow, g_norm_wide = g_norms

    def body(i, g_ux, g_uy, g_step, g_a_narrow, g_a_wide):
        distance, distance_sq, w_narrow, w_wide, ahead, behind = across.sample(i)
        g_w_narrow, g_w_wide = 2.0 * g_norm_narrow, 2.0 * g_norm_wide
        g_offset_x, g_offset_y = grid.Float(0.0), grid.Float(0.0)
        g_values = [dr.fma(g_narrow, w_narrow, g_wide * w_wide) for g_narrow, g_wide in zip(grad_narrow, grad_wide)]
        for corners, sign in ((ahead, 1.0), (behind, -1.0)):
            moves_x = dr.select(corners.moves_x, grid.Float(sign), 0.0)
            moves_y = dr.select(corners.moves_y, grid.Float(sign), 0.0)
            for start, g_narrow, g_wide, g_value in zip(across.image_starts, grad_narrow, grad_wide, g_values):
                value, slope_x, slope_y = grid.sample_with_slopes(across.image, corners, start)
                g_w_narrow = dr.fma(g_narrow, value, g_w_narrow)
                g_w_wide = dr.fma(g_wide, value, g_w_wide)
                g_offset_x = dr.fma(g_value * moves_x, slope_x, g_offset_x)
                g_offset_y = dr.fma(g_value * moves_y, slope_y, g_offset_y)
            if g_image is not None:
                g_image.scatter(g_values, corners)
        g_log_narrow, g_log_wide = g_w_narrow * w_narrow, g_w_wide * w_wide
        g_distance = dr.fma(
            g_offset_x,
            across.ux,
            dr.fma(
                g_offset_y, across.uy, 2.0 * distance * dr.fma(g_log_narrow, across.narrow, g_log_wide * across.wide)
            ),
        )
        return (
            dr.fma(g_offset_x, distance, g_ux),
            dr.fma(g_offset_y, distance, g_uy),
            dr.fma(g_distance, grid.Float(i), g_step),
            dr.fma(g_log_narrow, distance_sq, g_a_narrow),
            dr.fma(g_log_wide, distance_sq, g_a_wide),
        )

    zero = dr.zeros(grid.Float, grid.lanes)
    for k, output in enumerate(across.over_samples((zero,) * 5, body)):
        grid.store(g_maps, output, k, 5)
    dr.eval(g_maps, *([g_image.array] if g_image is not None else []))


class DogTaps(torch.autograd.Function):
    """The fused :class:`wise.filters.dog._DogTaps`: ``sum w_n v``, ``sum w_n``, ``sum w_w v`` and
    ``sum w_w`` over the samples across the flow, for the narrow and the wide Gaussian."""

    @staticmethod
    def forward(
        ctx, image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq, steps: int, support: float
    ):  # type: ignore[override]
        inputs = (image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq)
        b, c, h, w = image.shape
        with kernel_threads():
            across = _Across.of(*inputs, steps, support)
            sums = (empty_output(across.grid, c), empty_output(across.grid, c))
            norms = (empty_output(across.grid, 1), empty_output(across.grid, 1))
            _dog_forward(across, sums, norms)
            sum_narrow, sum_wide = (as_tensor(array, (b, c, h, w)) for array in sums)
            norm_narrow, norm_wide = (as_tensor(array, (b, 1, h, w)) for array in norms)
        ctx.save_for_backward(*inputs)
        ctx.steps, ctx.support = steps, support
        return sum_narrow, norm_narrow, sum_wide, norm_wide

    @staticmethod
    def backward(ctx, g_sum_narrow, g_norm_narrow, g_sum_wide, g_norm_wide):  # type: ignore[override]
        inputs = ctx.saved_tensors
        image, direction, step, _, neg_narrow, neg_wide = inputs
        b, c, h, w = image.shape
        need = ctx.needs_input_grad
        with kernel_threads():
            across = _Across.of(*inputs, ctx.steps, ctx.support)
            grid = across.grid
            g_image = PackedGradient(grid, c) if need[0] else None
            g_maps_array = empty_output(grid, 5)
            _dog_backward(
                across,
                _lanes(grid, g_sum_narrow, c),
                _lanes(grid, g_sum_wide, c),
                (_lanes(grid, g_norm_narrow, 1)[0], _lanes(grid, g_norm_wide, 1)[0]),
                g_image,
                g_maps_array,
            )
            g_image = g_image.torch((b, c, h, w)) if need[0] else None
            g_maps = as_tensor(g_maps_array, (b, 5, h, w))
        return (
            g_image,
            reduce_to(g_maps[:, 0:2], direction.shape) if need[1] else None,
            reduce_to(g_maps[:, 2:3], step.shape) if need[2] else None,
            None,
            reduce_to(g_maps[:, 3:4], neg_narrow.shape) if need[4] else None,
            reduce_to(g_maps[:, 4:5], neg_wide.shape) if need[5] else None,
            None,
            None,
        )
