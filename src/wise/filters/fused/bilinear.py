"""Bilinear sampling with clamped borders inside the fused kernels, and its derivatives.

The same sampling as ``grid_sample(mode="bilinear", padding_mode="border", align_corners=True)``
at a pixel position: the position is clamped to the image, and a clamped coordinate passes no
gradient. A kernel locates a position once per axis with :func:`locate` and then reads, scatters
or differentiates every channel with the corners it returned.
"""

from __future__ import annotations

from numba import njit


@njit(inline="always")
def locate(position: float, size: int) -> tuple[int, int, float, float]:
    """The lower and upper neighbour along one axis, the fraction towards the upper one, and the
    derivative of the clamped position with respect to ``position`` (0 where it is clamped)."""
    if position <= 0.0:
        return 0, 0, 0.0, 0.0
    if position >= size - 1:
        return size - 1, size - 1, 0.0, 0.0
    lower = int(position)
    return lower, lower + 1, position - lower, 1.0


@njit(inline="always")
def interpolate(image, b: int, c: int, y0: int, y1: int, x0: int, x1: int, fy: float, fx: float) -> float:
    """The bilinear value of channel ``c`` of picture ``b`` of a ``(B, C, H, W)`` image between the four corners."""
    top = image[b, c, y0, x0] + fx * (image[b, c, y0, x1] - image[b, c, y0, x0])
    bottom = image[b, c, y1, x0] + fx * (image[b, c, y1, x1] - image[b, c, y1, x0])
    return top + fy * (bottom - top)


@njit(inline="always")
def slopes(image, b: int, c: int, y0: int, y1: int, x0: int, x1: int, fy: float, fx: float) -> tuple[float, float]:
    """The derivatives of :func:`interpolate` with respect to the x and the y position (unclamped)."""
    top_slope = image[b, c, y0, x1] - image[b, c, y0, x0]
    bottom_slope = image[b, c, y1, x1] - image[b, c, y1, x0]
    top = image[b, c, y0, x0] + fx * top_slope
    bottom = image[b, c, y1, x0] + fx * bottom_slope
    return top_slope + fy * (bottom_slope - top_slope), bottom - top


@njit(inline="always")
def scatter(image, b: int, c: int, y0: int, y1: int, x0: int, x1: int, fy: float, fx: float, value: float) -> None:
    """Add ``value`` to the four corners with the bilinear weights: the adjoint of :func:`interpolate`."""
    top = value * (1.0 - fy)
    bottom = value * fy
    image[b, c, y0, x0] += top * (1.0 - fx)
    image[b, c, y0, x1] += top * fx
    image[b, c, y1, x0] += bottom * (1.0 - fx)
    image[b, c, y1, x1] += bottom * fx


@njit(inline="always")
def interpolate_with_slopes(
    image, b: int, c: int, y0: int, y1: int, x0: int, x1: int, fy: float, fx: float
) -> tuple[float, float, float]:
    """:func:`interpolate` and :func:`slopes` together, reading the four corners once."""
    top_left, top_right = image[b, c, y0, x0], image[b, c, y0, x1]
    bottom_left, bottom_right = image[b, c, y1, x0], image[b, c, y1, x1]
    top_slope = top_right - top_left
    bottom_slope = bottom_right - bottom_left
    top = top_left + fx * top_slope
    bottom = bottom_left + fx * bottom_slope
    return top + fy * (bottom - top), top_slope + fy * (bottom_slope - top_slope), bottom - top
