"""Fused kernels of :mod:`wise.filters.watercolor`: the wet-in-wet bleeding and the gaps and
overlaps at edges, each forward and analytic backward, in Dr.Jit.

Both sample the image bilinearly (border clamped, as ``grid_sample``) at offsets along a
per-pixel direction. The PyTorch path builds a full-image sampling grid and a full-image sample
per offset, and its backward goes through ``grid_sample``'s backward once per sample; here every
lane (pixel) reads its samples and keeps its sums in registers, and backward scatters the image's
gradient through the samples into one private copy per thread (summed at the end) and returns the
centre pixel's own terms directly. The scattered gradient is kept with the channels of a pixel side
by side, four at a time, so that a corner takes one four-wide addition instead of one per channel.

Wet-in-wet, for the image ``C``, the step ``s`` between samples (``(B, 2, H, W)``, pixels), the
blend ``e`` and the weights ``w_0 .. w_n``: ``out = C + e (bled - C)`` with
``bled = (w_0 C + sum_j w_j (C(p + j s) + C(p - j s))) / W`` and ``W = w_0 + 2 sum_j w_j``.

Gaps and overlaps, for the unit direction ``u``, the band ``b``, the gap and overlap strengths
``g`` and ``o``: ``out = C + b (g (paper - C) + o (C C_other - C))`` with
``C_other = C + (A |A|^2 + B |B|^2) / (|A|^2 + |B|^2 + eps)``, ``A`` and ``B`` the samples at
``p +- distance u`` minus ``C``.
"""

from __future__ import annotations

from typing import Sequence

import drjit as dr
import torch

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import flat, float_type, kernel_threads, to_torch
from wise.filters.fused._lanes import Grid, PackedGradient, runtime

_UNROLLED_SAMPLES = 16
"""Wet-in-wet samples per side up to which the forward kernel unrolls its loop over them; more run
in a symbolic loop, so that the kernel stays small. The backward kernel, four times the code per
sample, always loops symbolically: unrolled, its six default samples take over a second to compile
and run no faster."""


class _Map:
    """A ``(B or 1, K, H or 1, W or 1)`` tensor stored flat without its broadcast dimensions, read per lane."""

    def __init__(self, tensor: torch.Tensor, grid: Grid, dtype: torch.dtype) -> None:
        value = tensor.detach().to(dtype)
        for dim in (0, 2, 3):
            if value.shape[dim] > 1 and value.stride(dim) == 0:  # expanded: one copy suffices
                value = value.narrow(dim, 0, 1)
        self.grid = grid
        self.batch, self.channels, self.height, self.width = value.shape
        self.array = flat(value, grid.Float)

    def load(self, channel: int = 0):
        grid = self.grid
        plane = runtime(type(grid.pixel), self.height * self.width)
        index = dr.zeros(type(grid.pixel), grid.lanes) + channel * plane
        if self.batch > 1:
            index += grid.picture * (self.channels * plane)
        if self.height > 1 and self.width > 1:
            index += grid.pixel
        elif self.height > 1:
            index += grid.row
        elif self.width > 1:
            index += grid.column
        return dr.gather(grid.Float, self.array, index)


def _along(moves, value):
    """``value`` where the sample's coordinate moves with its position, 0 where it is clamped."""
    return dr.select(moves, value, 0.0)


# --- wet-in-wet ---------------------------------------------------------------------------------


def _over_samples(grid: Grid, weights: Sequence[float], state: tuple, body, unrolled: int):
    """``state = body(j, w_j, *state)`` for ``j = 1 .. n``: unrolled up to ``unrolled`` samples, else
    a symbolic loop."""
    samples = len(weights) - 1
    if samples <= unrolled:
        for j in range(1, samples + 1):
            state = body(grid.Float(j), weights[j], *state)
        return state
    table = grid.Float(weights)
    UInt = type(grid.pixel)

    def step(j, *state):
        return (j + 1, *body(grid.Float(j), dr.gather(grid.Float, table, j), *state))

    j0 = dr.zeros(UInt, grid.lanes) + 1
    return dr.while_loop(state=(j0, *state), cond=lambda j, *_: j <= samples, body=step)[1:]


def _wet_forward(image, step: _Map, edges: _Map, weights: Sequence[float], grid: Grid, channels: int):
    """The output's channels: ``C + e (bled - C)``."""
    starts = [grid.channel_start(c, channels) for c in range(channels)]
    sx, sy = step.load(0), step.load(1)

    def sample_pair(j, weight, *sums):
        ahead = grid.locate(dr.fma(j, sx, grid.x), dr.fma(j, sy, grid.y))
        behind = grid.locate(grid.x - j * sx, grid.y - j * sy)
        return tuple(
            dr.fma(weight, grid.sample(image, ahead, start) + grid.sample(image, behind, start), total)
            for start, total in zip(starts, sums)
        )

    zeros = tuple(grid.Float(0.0) for _ in range(channels))
    sums = _over_samples(grid, weights, zeros, sample_pair, _UNROLLED_SAMPLES)
    blend = edges.load()
    inverse_total = 1.0 / (weights[0] + 2.0 * sum(weights[1:]))
    outputs = []
    for c, total in enumerate(sums):
        value = grid.load(image, c, channels)
        bled = dr.fma(value, weights[0], total) * inverse_total
        outputs.append(dr.fma(blend, bled - value, value))
    dr.eval(*outputs)
    return outputs


def _wet_backward(
    image, step: _Map, edges: _Map, weights: Sequence[float], grid: Grid, channels: int, grad, need_image
):
    """Gradients of :func:`_wet_forward`: the image's samples scattered into a
    :class:`PackedGradient` (if ``need_image``) and its centre term per lane, the step's
    ``sum_j j w_j sum_c g_c e / W (dC/dx(p + j s) - dC/dx(p - j s))`` (zero along a clamped
    coordinate) and the edges' ``sum_c g_c (bled_c - C_c)``."""
    Float = grid.Float
    starts = [grid.channel_start(c, channels) for c in range(channels)]
    sx, sy = step.load(0), step.load(1)
    blend = edges.load()
    inverse_total = 1.0 / (weights[0] + 2.0 * sum(weights[1:]))
    g_out = [grid.load(grad, c, channels) for c in range(channels)]
    g_sums = [g * blend * inverse_total for g in g_out]
    g_image = PackedGradient(grid, channels) if need_image else None

    def sample_pair(j, weight, g_sx, g_sy, *sums):
        ahead = grid.locate(dr.fma(j, sx, grid.x), dr.fma(j, sy, grid.y))
        behind = grid.locate(grid.x - j * sx, grid.y - j * sy)
        ahead_x, ahead_y, behind_x, behind_y = (Float(0.0) for _ in range(4))
        new_sums, g_samples = [], [g_sum * weight for g_sum in g_sums]
        if need_image:
            g_image.scatter(g_samples, ahead)
            g_image.scatter(g_samples, behind)
        for start, g_sample, total in zip(starts, g_samples, sums):
            ahead_value, slope_xa, slope_ya = grid.sample_with_slopes(image, ahead, start)
            behind_value, slope_xb, slope_yb = grid.sample_with_slopes(image, behind, start)
            new_sums.append(dr.fma(weight, ahead_value + behind_value, total))
            ahead_x = dr.fma(g_sample, slope_xa, ahead_x)
            ahead_y = dr.fma(g_sample, slope_ya, ahead_y)
            behind_x = dr.fma(g_sample, slope_xb, behind_x)
            behind_y = dr.fma(g_sample, slope_yb, behind_y)
        g_sx = dr.fma(j, _along(ahead.moves_x, ahead_x) - _along(behind.moves_x, behind_x), g_sx)
        g_sy = dr.fma(j, _along(ahead.moves_y, ahead_y) - _along(behind.moves_y, behind_y), g_sy)
        return (g_sx, g_sy, *new_sums)

    zero = Float(0.0)
    zeros = (zero, zero, *(zero for _ in range(channels)))
    g_sx, g_sy, *sums = _over_samples(grid, weights, zeros, sample_pair, unrolled=0)
    g_blend = Float(0.0)
    g_centre = []
    for c, (total, g, g_sum) in enumerate(zip(sums, g_out, g_sums)):
        value = grid.load(image, c, channels)
        bled = dr.fma(value, weights[0], total) * inverse_total
        g_blend = dr.fma(g, bled - value, g_blend)
        g_centre.append(dr.fma(g, 1.0 - blend, g_sum * weights[0]))
    outputs = [*g_centre, g_sx, g_sy, g_blend]
    dr.eval(*outputs, *([g_image.array] if need_image else []))
    return g_image, outputs


class WetInWet(torch.autograd.Function):
    """:func:`wise.filters.watercolor.wet_in_wet` once the step ``(B, 2, H, W)`` between samples
    (direction times spacing, pixels) and the blend map ``edges`` (broadcasting to ``(B, 1, H, W)``)
    are known; ``weights`` are the Gaussian weights ``w_0 .. w_n`` of the samples. Gradients reach
    the image, the step and the edges."""

    @staticmethod
    def forward(ctx, image: torch.Tensor, step: torch.Tensor, edges: torch.Tensor, weights: Sequence[float]):  # type: ignore[override]
        b, c, h, w = image.shape
        weights = [float(weight) for weight in weights]
        with kernel_threads():
            grid = Grid(b, h, w, float_type(image.dtype))
            pixels = flat(image, grid.Float)
            outputs = _wet_forward(
                pixels, _Map(step, grid, image.dtype), _Map(edges, grid, image.dtype), weights, grid, c
            )
            out = to_torch(outputs, (b, h, w))
        ctx.save_for_backward(image, step, edges)
        ctx.weights = weights
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, step, edges = ctx.saved_tensors
        b, c, h, w = image.shape
        need = ctx.needs_input_grad
        with kernel_threads():
            grid = Grid(b, h, w, float_type(image.dtype))
            g_image, outputs = _wet_backward(
                flat(image, grid.Float),
                _Map(step, grid, image.dtype),
                _Map(edges, grid, image.dtype),
                ctx.weights,
                grid,
                c,
                flat(grad.to(image.dtype), grid.Float, image.shape),
                need[0],
            )
            g_centre = to_torch(outputs[:c], (b, h, w))
            g_step = to_torch(outputs[c : c + 2], (b, h, w))
            g_edges = to_torch(outputs[c + 2 :], (b, h, w))
            g_image = g_image.torch(image.shape) + g_centre if need[0] else None
        return (
            g_image,
            reduce_to(g_step, step.shape) if need[1] else None,
            reduce_to(g_edges, edges.shape) if need[2] else None,
            None,
        )


# --- gaps and overlaps --------------------------------------------------------------------------


class _Sides:
    """The samples at ``p +- offset``: their corners, their differences ``A`` and ``B`` to the
    centre (per channel) and the squared lengths ``|A|^2`` and ``|B|^2``."""

    def __init__(self, image, grid: Grid, channels: int, centre: list, offset_x, offset_y) -> None:
        self.starts = [grid.channel_start(c, channels) for c in range(channels)]
        self.ahead_corners = grid.locate(grid.x + offset_x, grid.y + offset_y)
        self.behind_corners = grid.locate(grid.x - offset_x, grid.y - offset_y)
        self.ahead = [grid.sample(image, self.ahead_corners, s) - v for s, v in zip(self.starts, centre)]
        self.behind = [grid.sample(image, self.behind_corners, s) - v for s, v in zip(self.starts, centre)]
        self.ahead_sq, self.behind_sq = grid.Float(0.0), grid.Float(0.0)
        for a, b in zip(self.ahead, self.behind):
            self.ahead_sq = dr.fma(a, a, self.ahead_sq)
            self.behind_sq = dr.fma(b, b, self.behind_sq)


def _gaps_forward(image, direction: _Map, maps: list, distance, paper: float, eps: float, grid: Grid, channels: int):
    """The output's channels: ``C + b (g (paper - C) + o (C C_other - C))``."""
    centre = [grid.load(image, c, channels) for c in range(channels)]
    sides = _Sides(image, grid, channels, centre, distance * direction.load(0), distance * direction.load(1))
    norm = sides.ahead_sq + sides.behind_sq + eps
    strength, gap, overlap = (m.load() for m in maps)
    outputs = []
    for value, a, b in zip(centre, sides.ahead, sides.behind):
        other = value + dr.fma(a, sides.ahead_sq, b * sides.behind_sq) / norm
        change = dr.fma(gap, paper - value, overlap * (value * other - value))
        outputs.append(dr.fma(strength, change, value))
    dr.eval(*outputs)
    return outputs


def _gaps_backward(
    image, direction: _Map, maps: list, distance, paper: float, eps: float, grid: Grid, channels: int, grad, need_image
):
    """Gradients of :func:`_gaps_forward`. With ``q = dL/dC_other / n`` (``n`` the norm):
    ``dL/dA = q |A|^2 + 2 A (q.A - (q.A |A|^2 + q.B |B|^2) / n)`` (``B`` alike); ``A`` and ``B``
    pass their gradient to the samples (scattered into a :class:`PackedGradient` if ``need_image``, and along
    ``u`` to the direction) and minus it to the centre, which is returned per lane."""
    Float = grid.Float
    centre = [grid.load(image, c, channels) for c in range(channels)]
    sides = _Sides(image, grid, channels, centre, distance * direction.load(0), distance * direction.load(1))
    norm = sides.ahead_sq + sides.behind_sq + eps
    strength, gap, overlap = (m.load() for m in maps)
    g_band, g_gap, g_overlap = Float(0.0), Float(0.0), Float(0.0)
    q_ahead, q_behind = Float(0.0), Float(0.0)
    q, g_centre = [], []
    for c, (value, a, b) in enumerate(zip(centre, sides.ahead, sides.behind)):
        other = value + dr.fma(a, sides.ahead_sq, b * sides.behind_sq) / norm
        g = grid.load(grad, c, channels)
        g_change = g * strength
        to_paper = paper - value
        mixed = value * other - value
        g_band = dr.fma(g, dr.fma(gap, to_paper, overlap * mixed), g_band)
        g_gap = dr.fma(g_change, to_paper, g_gap)
        g_overlap = dr.fma(g_change, mixed, g_overlap)
        g_other = g_change * overlap * value
        q.append(g_other / norm)
        q_ahead = dr.fma(q[c], a, q_ahead)
        q_behind = dr.fma(q[c], b, q_behind)
        # the centre's own terms: out's, change's and C_other's
        own = 1.0 + strength * (overlap * (other - 1.0) - gap)
        g_centre.append(dr.fma(g, own, g_other))
    q_mean = dr.fma(q_ahead, sides.ahead_sq, q_behind * sides.behind_sq) / norm
    ahead_x, ahead_y, behind_x, behind_y = (Float(0.0) for _ in range(4))
    g_aheads, g_behinds = [], []
    for c, (start, a, b) in enumerate(zip(sides.starts, sides.ahead, sides.behind)):
        g_ahead = dr.fma(q[c], sides.ahead_sq, 2.0 * a * (q_ahead - q_mean))
        g_behind = dr.fma(q[c], sides.behind_sq, 2.0 * b * (q_behind - q_mean))
        g_aheads.append(g_ahead)
        g_behinds.append(g_behind)
        g_centre[c] -= g_ahead + g_behind
        _, slope_x, slope_y = grid.sample_with_slopes(image, sides.ahead_corners, start)
        ahead_x = dr.fma(g_ahead, slope_x, ahead_x)
        ahead_y = dr.fma(g_ahead, slope_y, ahead_y)
        _, slope_x, slope_y = grid.sample_with_slopes(image, sides.behind_corners, start)
        behind_x = dr.fma(g_behind, slope_x, behind_x)
        behind_y = dr.fma(g_behind, slope_y, behind_y)
    g_image = PackedGradient(grid, channels) if need_image else None
    if need_image:
        g_image.scatter(g_aheads, sides.ahead_corners)
        g_image.scatter(g_behinds, sides.behind_corners)
    corners_a, corners_b = sides.ahead_corners, sides.behind_corners
    g_ux = distance * (_along(corners_a.moves_x, ahead_x) - _along(corners_b.moves_x, behind_x))
    g_uy = distance * (_along(corners_a.moves_y, ahead_y) - _along(corners_b.moves_y, behind_y))
    outputs = [*g_centre, g_ux, g_uy, g_band, g_gap, g_overlap]
    dr.eval(*outputs, *([g_image.array] if need_image else []))
    return g_image, outputs


class GapsOverlaps(torch.autograd.Function):
    """:func:`wise.filters.watercolor.gaps_overlaps` once its maps are known: ``image``
    ``(B, C, H, W)``, ``direction`` ``(B, 2, H, W)``, ``band``, ``gap`` and ``overlap`` broadcasting
    to ``(B, 1, H, W)``, the other side ``distance`` pixels away, the ``paper`` colour and the
    selection's ``eps``. Gradients reach the image, the direction and the three maps."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx,
        image: torch.Tensor,
        direction: torch.Tensor,
        band: torch.Tensor,
        gap: torch.Tensor,
        overlap: torch.Tensor,
        distance: float,
        paper: float,
        eps: float,
    ) -> torch.Tensor:
        b, c, h, w = image.shape
        with kernel_threads():
            grid = Grid(b, h, w, float_type(image.dtype))
            outputs = _gaps_forward(
                flat(image, grid.Float),
                _Map(direction, grid, image.dtype),
                [_Map(m, grid, image.dtype) for m in (band, gap, overlap)],
                dr.opaque(grid.Float, distance),  # a kernel parameter: every distance runs the same kernel
                float(paper),
                float(eps),
                grid,
                c,
            )
            out = to_torch(outputs, (b, h, w))
        ctx.save_for_backward(image, direction, band, gap, overlap)
        ctx.settings = (distance, paper, eps)
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, direction, band, gap, overlap = ctx.saved_tensors
        b, c, h, w = image.shape
        distance, paper, eps = ctx.settings
        need = ctx.needs_input_grad
        with kernel_threads():
            grid = Grid(b, h, w, float_type(image.dtype))
            g_image, outputs = _gaps_backward(
                flat(image, grid.Float),
                _Map(direction, grid, image.dtype),
                [_Map(m, grid, image.dtype) for m in (band, gap, overlap)],
                dr.opaque(grid.Float, distance),
                float(paper),
                float(eps),
                grid,
                c,
                flat(grad.to(image.dtype), grid.Float, image.shape),
                need[0],
            )
            g_centre = to_torch(outputs[:c], (b, h, w))
            g_direction = to_torch(outputs[c : c + 2], (b, h, w))
            g_maps = [to_torch([o], (b, h, w)) for o in outputs[c + 2 :]]
            g_image = g_image.torch(image.shape) + g_centre if need[0] else None
        map_grads = [
            reduce_to(g, m.shape) if wanted else None for g, m, wanted in zip(g_maps, (band, gap, overlap), need[2:5])
        ]
        return (
            g_image,
            reduce_to(g_direction, direction.shape) if need[1] else None,
            *map_grads,
            None,
            None,
            None,
        )
