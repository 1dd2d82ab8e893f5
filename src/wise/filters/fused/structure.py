"""Fused kernel of :func:`wise.filters.structure.structure_tensor`, in Dr.Jit.

For every pixel the eight neighbours of a 3x3 Sobel stencil ``d`` pixels away (bilinear samples,
borders clamped) give the derivatives of each channel, ``f_x = sum_k w_x,k v_k / d`` and
``f_y = sum_k w_y,k v_k / d``, and Di Zenzo's tensor sums their products over the channels:
``(sum_c f_x^2, sum_c f_x f_y, sum_c f_y^2)`` (Brox et al. 2006). Backward gives the gradients
of the image (scattered into per-thread copies) and of the per-pixel distance ``d``.
One SIMD lane per pixel; arithmetic is in the image's dtype.
"""

from __future__ import annotations

import drjit as dr
import torch
from drjit.llvm import UInt32

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import flat, float_type, kernel_threads, to_torch
from wise.filters.fused._lanes import Corners, Grid, maximum, minimum, runtime

_SIDE = 3
"""The stencil is a 3x3 grid of samples ``d`` apart..."""
_CENTRE = 1
"""...around the pixel itself, which it does not read."""


def _locate(position, size: int, Float):
    """One axis of a bilinear sample, clamped: lower and upper neighbour, the fraction towards the
    upper one, and whether the position moves the sample (not clamped)."""
    last = runtime(Float, float(size - 1))
    moves = (position > 0) & (position < last)
    clamped = minimum(maximum(position, 0.0), last)
    lower = UInt32(clamped)  # truncation is the floor of a non-negative position
    return lower, dr.select(moves, lower + 1, lower), clamped - Float(lower), moves


class _Stencil:
    """The lanes' image, distance and the 3x3 stencil's columns and rows, each located once."""

    def __init__(self, image: torch.Tensor, distance: torch.Tensor, weights: torch.Tensor) -> None:
        b, c, h, w = image.shape
        Float = float_type(image.dtype)
        self.grid = grid = Grid(b, h, w, Float)
        self.Float, self.channels = Float, c
        self.pixels = flat(image, Float)
        self.reach = grid.load_broadcast(distance)
        self.weights = weights.tolist()  # the Sobel constants, literals of the kernel
        column, row = grid.column, grid.row
        left, right = _locate(grid.x - self.reach, w, Float), _locate(grid.x + self.reach, w, Float)
        top, bottom = _locate(grid.y - self.reach, h, Float), _locate(grid.y + self.reach, h, Float)
        no = dr.zeros(dr.mask_t(Float), dr.width(column))
        self.columns = (left, (column, column, Float(0.0), no), right)
        self.rows = (top, (row, row, Float(0.0), no), bottom)
        self.starts = [grid.channel_start(k, c) for k in range(c)]

    def taps(self):
        """``(i, j, corners)`` of the eight samples, ``(i - 1, j - 1) d`` from the pixel."""
        for j in range(_SIDE):
            y0, y1, fy, moves_y = self.rows[j]
            for i in range(_SIDE):
                if i == _CENTRE and j == _CENTRE:
                    continue
                x0, x1, fx, moves_x = self.columns[i]
                top, bottom = y0 * self.grid.runtime_width, y1 * self.grid.runtime_width
                yield i, j, Corners(top + x0, top + x1, bottom + x0, bottom + x1, fx, fy, moves_x, moves_y)

    def derivatives(self, start):
        """The stencil sums ``sum_k w_x,k v_k`` and ``sum_k w_y,k v_k`` of the channel at ``start``."""
        sum_x, sum_y = self.Float(0.0), self.Float(0.0)
        for i, j, corners in self.taps():
            value = self.grid.sample(self.pixels, corners, start)
            weight_x, weight_y = self.weights[0][j][i], self.weights[1][j][i]
            if weight_x:
                sum_x = dr.fma(weight_x, value, sum_x)
            if weight_y:
                sum_y = dr.fma(weight_y, value, sum_y)
        return sum_x, sum_y


def _tensor_forward(stencil: _Stencil):
    Float = stencil.Float
    xx, xy, yy = Float(0.0), Float(0.0), Float(0.0)
    for start in stencil.starts:
        sum_x, sum_y = stencil.derivatives(start)
        fx, fy = sum_x / stencil.reach, sum_y / stencil.reach
        xx = dr.fma(fx, fx, xx)
        xy = dr.fma(fx, fy, xy)
        yy = dr.fma(fy, fy, yy)
    dr.eval(xx, xy, yy)
    return xx, xy, yy


def _tensor_backward(stencil: _Stencil, grad, need_image: bool, need_distance: bool):
    grid, Float, reach = stencil.grid, stencil.Float, stencil.reach
    g_xx, g_xy, g_yy = (grid.load(grad, k, 3) for k in range(3))
    g_image = dr.zeros(Float, dr.width(stencil.pixels)) if need_image else None
    first = grid.channel_start(0, stencil.channels)

    def channel(c, g_reach):
        # a symbolic loop over the channels keeps the kernel small (it compiles in a fraction of the time)
        start = first + c * grid.runtime_plane
        sum_x, sum_y = stencil.derivatives(start)
        fx, fy = sum_x / reach, sum_y / reach
        g_fx = 2.0 * g_xx * fx + g_xy * fy
        g_fy = g_xy * fx + 2.0 * g_yy * fy
        g_reach -= (g_fx * fx + g_fy * fy) / reach  # through the division by d
        g_sum_x, g_sum_y = g_fx / reach, g_fy / reach
        for i, j, corners in stencil.taps():
            g_value = stencil.weights[0][j][i] * g_sum_x + stencil.weights[1][j][i] * g_sum_y
            if need_image:
                grid.scatter(g_image, g_value, corners, start)
            if need_distance:  # through the positions of the samples, (i - 1, j - 1) * d
                _, slope_x, slope_y = grid.sample_with_slopes(stencil.pixels, corners, start)
                through = Float(0.0)
                if i != _CENTRE:
                    through = dr.select(corners.moves_x, (i - _CENTRE) * slope_x, 0.0)
                if j != _CENTRE:
                    through += dr.select(corners.moves_y, (j - _CENTRE) * slope_y, 0.0)
                g_reach = dr.fma(g_value, through, g_reach)
        return c + 1, g_reach

    channels = dr.opaque(UInt32, stencil.channels)
    _, g_reach = dr.while_loop((UInt32(0), Float(0.0)), lambda c, _: c < channels, channel)
    outputs = ([g_image] if need_image else []) + ([g_reach] if need_distance else [])
    dr.eval(*outputs)
    return g_image, g_reach


class StructureTensor(torch.autograd.Function):
    """The structure tensor ``(B, 3, H, W)`` of ``image`` ``(B, C, H, W)`` from the Sobel neighbours
    at ``distance`` (broadcasts to ``(B, 1, H, W)``, pixels); ``weights`` ``(2, 3, 3)`` are the
    stencil's weights of d/dx and d/dy, indexed by ``(dy + 1, dx + 1)``."""

    @staticmethod
    def forward(ctx, image: torch.Tensor, distance: torch.Tensor, weights: torch.Tensor):  # type: ignore[override]
        b, _, h, w = image.shape
        with kernel_threads():
            tensor = to_torch(_tensor_forward(_Stencil(image, distance, weights)), (b, h, w))
        ctx.save_for_backward(image, distance, weights)
        return tensor

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, distance, weights = ctx.saved_tensors
        b, c, h, w = image.shape
        need_image, need_distance = ctx.needs_input_grad[0], ctx.needs_input_grad[1]
        if not (need_image or need_distance):
            return None, None, None
        with kernel_threads():
            stencil = _Stencil(image, distance, weights)
            g_image, g_reach = _tensor_backward(
                stencil, flat(grad.to(image.dtype), stencil.Float, (b, 3, h, w)), need_image, need_distance
            )
            g_image = g_image.torch().view(b, c, h, w) if need_image else None
            g_distance = to_torch([g_reach], (b, h, w)) if need_distance else None
        return (
            g_image,
            reduce_to(g_distance, distance.shape) if need_distance else None,
            None,
        )


def edge_tangent_flow(tensor: torch.Tensor, epsilon: float) -> torch.Tensor:
    """The fused :func:`wise.filters.structure.edge_tangent_flow`: the minor eigenvector of the
    structure tensor ``(B, 3, H, W)`` as ``(B, 2, H, W)``, one pass per pixel (autodiff by Dr.Jit)."""
    from wise.filters.fused import _pointwise

    def planes(components):
        xx, xy, yy = components
        # (cos, sin) of half the angle of (x, y) = (yy - xx, epsilon - 2 xy), without atan2 (whose
        # Dr.Jit code selects no instruction on LLVM 15): (r + x, y) and sign(y) (y, r - x) both
        # point along it; each is taken where its length is at least r / sqrt(2)
        x, y = yy - xx, epsilon - 2.0 * xy
        r = dr.sqrt(x * x + y * y)
        right = x >= 0.0
        u = dr.select(right, r + x, dr.select(y >= 0.0, y, -y))
        v = dr.select(right, y, dr.select(y >= 0.0, r - x, x - r))
        length = dr.sqrt(u * u + v * v)
        return u / length, v / length

    return _pointwise.apply(planes, tensor)
