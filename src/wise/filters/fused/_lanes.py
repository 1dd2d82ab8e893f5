"""Pixels as SIMD lanes for the Dr.Jit kernels: indices, per-pixel loads and bilinear samples.

A kernel works on flat arrays with one lane per pixel of a ``(B, H, W)`` grid. :class:`Grid`
holds the lanes' coordinates; its methods gather a pixel's values from ``(B, C, H, W)`` images
and ``(B, 1, H, W)`` maps stored flat, and sample an image bilinearly with clamped borders,
the sampling of ``grid_sample(mode="bilinear", padding_mode="border", align_corners=True)``.

Minima and maxima of floats are written as selections: LLVM 15 and older cannot compile the
``llvm.minimum`` intrinsic that Dr.Jit emits for them on x86.

Sizes enter a kernel as opaque values (read at run time), not as constants of its code: Dr.Jit
caches compiled kernels by their code, and a size written into it would compile every kernel
again for each new picture size. :func:`runtime` does the same for any value that changes
between calls.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import torch
from drjit.llvm import Float64, Int32, UInt32


def runtime(array_type, value):
    """``value`` as an opaque array of ``array_type``: the kernel reads it, so a new value does not
    compile a new kernel."""
    return dr.opaque(array_type, value)


def empty_output(grid: "Grid", channels: int):
    """A flat ``(B, channels, H, W)`` array for :meth:`Grid.store` to fill."""
    return dr.empty(grid.Float, grid.batch * channels * grid.plane)


def divide(index, divisor: int):
    """Quotient and remainder of lane indices by a run-time ``divisor``: a float64 reciprocal,
    corrected by one where it rounded across a multiple (x86 has no vector integer division)."""
    signed = Int32(index)
    d = runtime(Int32, divisor)
    quotient = Int32(Float64(signed) * runtime(Float64, 1.0 / divisor))
    remainder = signed - quotient * d
    quotient = dr.select(remainder < 0, quotient - 1, dr.select(remainder >= d, quotient + 1, quotient))
    return UInt32(quotient), UInt32(signed - quotient * d)


def maximum(a, b):
    return dr.select(a > b, a, b)


def minimum(a, b):
    return dr.select(a < b, a, b)


def clamp(value, low=None, high=None):
    """``torch.clamp``: the gradient passes where ``low <= value <= high``, the bounds included."""
    if low is not None:
        value = dr.select(value < low, low, value)
    if high is not None:
        value = dr.select(value > high, high, value)
    return value


@dataclass
class Corners:
    """A position's four bilinear neighbours (flat offsets within a channel), the fractions
    towards the upper ones, and whether each axis moves with the position (not clamped)."""

    top_left: object
    top_right: object
    bottom_left: object
    bottom_right: object
    fx: object
    fy: object
    moves_x: object
    moves_y: object


class Grid:
    """One lane per pixel of ``batch`` pictures of ``height x width``, with ``Float`` arithmetic."""

    def __init__(self, batch: int, height: int, width: int, float_type) -> None:
        self.batch, self.height, self.width = batch, height, width
        self.Float = float_type
        self.dtype = torch.float64 if float_type is Float64 else torch.float32
        self.plane = height * width
        self.lanes = batch * self.plane
        # the sizes as the kernel reads them, for index arithmetic (the ints above size arrays)
        self.runtime_width = runtime(UInt32, width)
        self.runtime_height = runtime(UInt32, height)
        self.runtime_plane = runtime(UInt32, self.plane)
        self._last = (runtime(float_type, float(width - 1)), runtime(float_type, float(height - 1)))
        self.lane = dr.arange(UInt32, self.lanes)
        self.picture, self.pixel = divide(self.lane, self.plane) if batch > 1 else (UInt32(0), self.lane)
        self.row, self.column = divide(self.pixel, width)
        self.x = float_type(self.column)
        self.y = float_type(self.row)

    def channel_start(self, channel: int, channels: int):
        """Flat offset of the lane's picture's ``channel`` in a ``(B, channels, H, W)`` array."""
        return (self.picture * channels + channel) * self.runtime_plane

    def load(self, array, channel: int = 0, channels: int = 1):
        """The lane's own pixel of ``channel`` of a flat ``(B, channels, H, W)`` array."""
        return dr.gather(self.Float, array, self.channel_start(channel, channels) + self.pixel)

    def load_broadcast(self, tensor: torch.Tensor):
        """The lane's value of a map broadcasting to ``(B, 1, H, W)``: one value per picture
        ``(B, 1, 1, 1)``, a map shared by the batch ``(1, 1, H, W)``, a single value, ... read from
        the map's own values, never from a copy expanded to the picture's size (a dimension
        expanded with stride 0 counts as 1)."""
        value = tensor.detach()
        for dim in range(value.dim()):
            if value.stride(dim) == 0 and value.shape[dim] > 1:
                value = value.narrow(dim, 0, 1)
        batch, _, height, width = value.shape
        array = self.Float(value.to(self.dtype).contiguous().view(-1))
        if batch == height == width == 1:
            return array  # a single value: Dr.Jit broadcasts it over the lanes
        index = self.picture if batch > 1 else UInt32(0)
        if height > 1:
            index = index * self.runtime_height + self.row
        if width > 1:
            index = index * self.runtime_width + self.column
        return dr.gather(self.Float, array, index)

    def store(self, target, value, channel: int = 0, channels: int = 1) -> None:
        """Write ``value`` to the lane's own pixel of ``channel`` of a flat output: each element
        once, so the writes of all channels share one kernel (see :func:`empty_output`)."""
        index = self.channel_start(channel, channels) + self.pixel
        dr.scatter(target, value, index, mode=dr.ReduceMode.Permute)

    def locate(self, x, y) -> Corners:
        """The bilinear neighbours of the position ``(x, y)`` in pixels, clamped to the picture."""
        fx, x0, x1, moves_x = self._axis(x, self._last[0])
        fy, y0, y1, moves_y = self._axis(y, self._last[1])
        top, bottom = y0 * self.runtime_width, y1 * self.runtime_width
        return Corners(top + x0, top + x1, bottom + x0, bottom + x1, fx, fy, moves_x, moves_y)

    def _axis(self, position, last):
        moves = (position > 0) & (position < last)
        clamped = minimum(maximum(position, 0.0), last)
        lower = UInt32(clamped)  # truncation is the floor of a non-negative position
        upper = dr.select(moves, lower + 1, lower)
        return clamped - self.Float(lower), lower, upper, moves

    def corner_values(self, array, corners: Corners, start):
        """The four corner values of the channel starting at ``start`` of a flat image."""
        return (
            dr.gather(self.Float, array, start + corners.top_left),
            dr.gather(self.Float, array, start + corners.top_right),
            dr.gather(self.Float, array, start + corners.bottom_left),
            dr.gather(self.Float, array, start + corners.bottom_right),
        )

    def sample(self, array, corners: Corners, start):
        """The bilinear value of the channel starting at ``start``."""
        top_left, top_right, bottom_left, bottom_right = self.corner_values(array, corners, start)
        top = dr.fma(corners.fx, top_right - top_left, top_left)
        bottom = dr.fma(corners.fx, bottom_right - bottom_left, bottom_left)
        return dr.fma(corners.fy, bottom - top, top)

    def sample_with_slopes(self, array, corners: Corners, start):
        """The bilinear value and its derivatives along x and y (unclamped)."""
        top_left, top_right, bottom_left, bottom_right = self.corner_values(array, corners, start)
        top_slope = top_right - top_left
        bottom_slope = bottom_right - bottom_left
        top = dr.fma(corners.fx, top_slope, top_left)
        bottom = dr.fma(corners.fx, bottom_slope, bottom_left)
        value = dr.fma(corners.fy, bottom - top, top)
        return value, dr.fma(corners.fy, bottom_slope - top_slope, top_slope), bottom - top

    def scatter(self, target, value, corners: Corners, start) -> None:
        """Add ``value`` to the four corners with the bilinear weights (the adjoint of :meth:`sample`),
        into per-thread copies of ``target`` summed at the end (no atomics contend)."""
        top = value * (1.0 - corners.fy)
        bottom = value * corners.fy
        mode = dr.ReduceMode.Expand
        dr.scatter_add(target, top * (1.0 - corners.fx), start + corners.top_left, mode=mode)
        dr.scatter_add(target, top * corners.fx, start + corners.top_right, mode=mode)
        dr.scatter_add(target, bottom * (1.0 - corners.fx), start + corners.bottom_left, mode=mode)
        dr.scatter_add(target, bottom * corners.fx, start + corners.bottom_right, mode=mode)


PACKET = 4
"""Channels added by one scatter of :class:`PackedGradient`."""


class PackedGradient:
    """An image's gradient kept as ``(B, H, W, G * 4)``: a pixel's channels side by side in ``G``
    groups of four (the last padded with zeros), added to with one four-wide scatter per group.
    One scatter per channel costs many times more: each is a reduction of its own over the lanes."""

    def __init__(self, grid: Grid, channels: int) -> None:
        import drjit.llvm as backend

        self.grid, self.channels = grid, channels
        self.groups = -(-channels // PACKET)
        self.Packet = backend.Array4f64 if grid.Float is backend.Float64 else backend.Array4f
        self.array = dr.zeros(grid.Float, grid.batch * grid.plane * self.groups * PACKET)

    def add(self, values: list, pixel) -> None:
        """Add the channels' ``values`` at ``pixel`` (an offset within the lane's picture), into
        per-thread copies summed at the end (no atomics contend)."""
        padded = list(values) + [0.0] * (self.groups * PACKET - self.channels)
        start = (self.grid.picture * self.grid.runtime_plane + pixel) * self.groups
        for group in range(self.groups):
            packet = self.Packet(*padded[group * PACKET : (group + 1) * PACKET])
            dr.scatter_add(self.array, packet, start + group, mode=dr.ReduceMode.Expand)

    def scatter(self, values: list, corners: Corners) -> None:
        """Add the channels' ``values`` to the four corners with the bilinear weights: the adjoint
        of :meth:`Grid.sample`."""
        top, bottom = 1.0 - corners.fy, corners.fy
        for weight, pixel in (
            (top * (1.0 - corners.fx), corners.top_left),
            (top * corners.fx, corners.top_right),
            (bottom * (1.0 - corners.fx), corners.bottom_left),
            (bottom * corners.fx, corners.bottom_right),
        ):
            self.add([v * weight for v in values], pixel)

    def torch(self, shape: tuple[int, int, int, int]) -> torch.Tensor:
        """The evaluated gradient as a ``(B, C, H, W)`` tensor."""
        b, c, h, w = shape
        dr.sync_thread()
        return self.array.torch().view(b, h, w, -1)[..., :c].permute(0, 3, 1, 2)
