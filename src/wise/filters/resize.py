"""Bilinear resizing that gives the same values on any number of threads.

``F.interpolate(mode="bilinear")`` on the CPU computes a pixel with fused multiply-adds in its
vectorized loop and without them in the loop's remainder, and where the remainder falls
depends on how the rows are split between threads: a render then differed in the last bits
between one and two threads, enough to change bytes of an 8-bit result (a batch rendered by
Ray actors differed from the same batch rendered locally). Here each axis is two gathers, two
products and a sum, each exact per element, whatever the vector width and the threads.
"""

from __future__ import annotations

import torch


def _axis_weights(
    size: int, out: int, like: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Source indices and weights of the ``out`` output positions along an axis of ``size``
    pixels, pixel centres aligned (``align_corners=False``), as PyTorch's bilinear mode takes them."""
    ratio = size / out
    position = ((torch.arange(out, dtype=torch.float64, device=like.device) + 0.5) * ratio - 0.5).clamp_min(0.0)
    lower = position.floor().long().clamp_max(size - 1)
    upper = (lower + 1).clamp_max(size - 1)
    upper_weight = (position - lower.to(torch.float64)).to(like.dtype)
    return lower, upper, 1.0 - upper_weight, upper_weight


def _enlarge_axis(image: torch.Tensor, factor: int, dim: int) -> torch.Tensor:
    """Enlargement by a whole ``factor``: output pixel ``i * factor + r`` lies at the fixed offset
    ``c_r = (r + 0.5) / factor - 0.5`` from input pixel ``i``, so each phase ``r`` is a blend of two
    shifted copies of the input (borders replicated), and the phases are interleaved."""
    size = image.shape[dim]
    padded = torch.cat((image.narrow(dim, 0, 1), image, image.narrow(dim, size - 1, 1)), dim)
    phases = []
    for phase in range(factor):
        offset = (phase + 0.5) / factor - 0.5
        start, weight = (1, offset) if offset >= 0.0 else (0, 1.0 + offset)
        phases.append(padded.narrow(dim, start, size) * (1.0 - weight) + padded.narrow(dim, start + 1, size) * weight)
    stacked = torch.stack(phases, dim + 1)
    shape = list(image.shape)
    shape[dim] = size * factor
    return stacked.reshape(shape)


def _resize_axis(image: torch.Tensor, out: int, dim: int) -> torch.Tensor:
    size = image.shape[dim]
    if size == out:
        return image
    if out % size == 0 and size > 1:
        return _enlarge_axis(image, out // size, dim)
    lower, upper, lower_weight, upper_weight = _axis_weights(size, out, image)
    shape = [1] * image.dim()
    shape[dim] = out
    return image.index_select(dim, lower) * lower_weight.view(shape) + image.index_select(
        dim, upper
    ) * upper_weight.view(shape)


def bilinear_resize(image: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """``image`` ``(B, C, H, W)`` resized to ``size`` (rows, columns) by bilinear interpolation
    with pixel centres aligned, as ``F.interpolate(mode="bilinear", align_corners=False)``
    (without antialiasing: for enlarging and for reductions by less than two), the same values
    on any number of threads. Differentiable."""
    return _resize_axis(_resize_axis(image, size[1], 3), size[0], 2)
