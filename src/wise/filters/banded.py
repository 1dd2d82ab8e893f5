"""One axis of a correlation with a short symmetric kernel, as products with a banded matrix.

Correlating the lines of an image with a kernel of ``2r + 1`` taps multiplies them by a banded
Toeplitz matrix. Cut into blocks of ``m`` outputs, each block is a matrix product of the
``m + 2r`` input pixels it reads with one small ``(m + 2r, m)`` matrix: the work goes to the
BLAS, which streams contiguous rows with vector loads, where a convolution or a per-pixel
kernel gathers every tap. On the CPU this is 3-10x faster than either for the blurs of the
effects (``benchmarks/bench_blur.py``), and the sums are those of the convolution.

The blocks that read beyond the image are multiplied on small padded copies (replicated
borders forward, zeros for the adjoint); the others read the image in place.
"""

from __future__ import annotations

import torch

MIN_BLOCK = 32
"""Outputs per matrix product (at least; twice the kernel's radius for wider kernels)."""


def _block(radius: int) -> int:
    return max(MIN_BLOCK, 2 * radius)


def _toeplitz(kernel: torch.Tensor, outputs: int) -> torch.Tensor:
    """``T`` ``(outputs + 2r, outputs)`` with ``T[i, j] = kernel[i - j]`` on the band, else 0."""
    taps = kernel.numel()
    offset = torch.arange(outputs + taps - 1, device=kernel.device)[:, None] - torch.arange(
        outputs, device=kernel.device
    )
    inside = (offset >= 0) & (offset < taps)
    return torch.where(inside, kernel[offset.clamp(0, taps - 1)], torch.zeros((), dtype=kernel.dtype))


def _window(lines: torch.Tensor, dim: int, start: int, stop: int, replicate: bool) -> torch.Tensor:
    """``lines``' indices ``[start, stop)`` along ``dim``, beyond the ends replicated or zero."""
    size = lines.shape[dim]
    low, high = max(0, start), min(size, stop)
    if low == start and high == stop:
        return lines.narrow(dim, start, stop - start)

    def border(at: int, count: int) -> torch.Tensor:
        shape = list(lines.shape)
        shape[dim] = count
        if replicate:
            return lines.narrow(dim, at, 1).expand(shape)
        return lines.new_zeros(shape)

    parts = [border(0, low - start)] if low > start else []
    parts.append(lines.narrow(dim, low, high - low))
    if stop > high:
        parts.append(border(size - 1, stop - high))
    return torch.cat(parts, dim)


def _correlate(image: torch.Tensor, kernel: torch.Tensor, axis: int, replicate: bool) -> torch.Tensor:
    b, c, h, w = image.shape
    radius = (kernel.numel() - 1) // 2
    block = _block(radius)
    kernel = kernel.to(image.dtype)
    if axis == 3:
        lines = image.reshape(b * c * h, w)  # rows: out[:, j] = in[:, j - r : j + r + 1] @ T[:, j]
        size = w
        band = _toeplitz(kernel, min(block, w))
    else:
        lines = image.reshape(b * c, h, w)  # columns: out[:, i] = T[:, i]^T @ in[:, i - r : i + r + 1]
        size = h
        band = _toeplitz(kernel, min(block, h)).t().contiguous()
    lines = lines.contiguous()
    out = torch.empty_like(lines)
    for start in range(0, size, block):
        stop = min(size, start + block)
        count = stop - start
        read = _window(lines, 1, start - radius, stop + radius, replicate)
        if axis == 3:
            torch.mm(read, band[: count + 2 * radius, :count], out=out[:, start:stop])
        else:
            torch.matmul(band[:count, : count + 2 * radius], read, out=out[:, start:stop])
    return out.view(b, c, h, w)


def correlate_axis(image: torch.Tensor, kernel: torch.Tensor, axis: int) -> torch.Tensor:
    """``kernel`` (odd length, symmetric) correlated with ``image`` ``(B, C, H, W)`` along
    ``axis`` (3: x, 2: y), borders replicated: ``out_n = sum_k w_k v_clamp(n + k - r)``."""
    return _correlate(image, kernel, axis, replicate=True)


def correlate_axis_adjoint(grad: torch.Tensor, kernel: torch.Tensor, axis: int) -> torch.Tensor:
    """The transpose of :func:`correlate_axis` applied to ``grad`` ``(B, C, H, W)``: the same
    correlation with zeros beyond the line, except at its two ends, which take every gradient
    whose tap the border replicated: ``sum_n g_n c_n`` with ``c_n = sum_(k <= -n) w_k``."""
    size = grad.shape[axis]
    kernel = kernel.to(grad.dtype)
    if size == 1:
        return grad * kernel.sum()
    radius = (kernel.numel() - 1) // 2
    inner = _correlate(grad, kernel, axis, replicate=False)
    reach = min(radius, size - 1) + 1
    # c_n for n = 0 .. reach - 1: the taps at or beyond -n
    border = kernel.cumsum(0)[radius - torch.arange(reach, device=kernel.device)]
    shape = [1, 1, 1, 1]
    shape[axis] = reach
    border = border.view(shape)
    first = (grad.narrow(axis, 0, reach) * border).sum(axis, keepdim=True)
    last = (grad.narrow(axis, size - reach, reach) * border.flip(axis)).sum(axis, keepdim=True)
    inner.narrow(axis, 0, 1).copy_(first)
    inner.narrow(axis, size - 1, 1).copy_(last)
    return inner
