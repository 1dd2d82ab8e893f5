"""Separable Gaussian smoothing with a global or per-pixel sigma."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image, max_value, resolution_scale
from wise.filters.banded import correlate_axis, correlate_axis_adjoint
from wise.filters.resize import bilinear_resize
from wise.filters.sampling import tap_sum

MIN_SIGMA = 1e-3
"""Smallest sigma (pixels) used; smaller values act as no smoothing without dividing by zero."""
SUPPORT = 2.0
"""Gaussian kernels are cut off at ``SUPPORT`` sigma but always reach the nearest neighbours,
so that a sub-pixel sigma still smooths a little and keeps a gradient."""


PYRAMID_SIGMA = 3.0
"""A fixed sigma of at least twice this many pixels is applied to a reduced copy (same result
up to interpolation, a fraction of the cost), keeping at least this sigma at the reduced size."""
MAX_PYRAMID_REDUCTION = 8
"""Largest reduction factor (the tile alignment of :mod:`wise.render`)."""
_DEVIATION_EPS = 1e-8
"""Keeps the square root of a zero variance differentiable."""


def in_support(distance: torch.Tensor | float, sigma: torch.Tensor, nearest: bool) -> torch.Tensor:
    """Mask of the samples a Gaussian of ``sigma`` uses; ``nearest`` marks the nearest neighbours."""
    if nearest:
        return torch.ones_like(sigma)
    return (distance <= SUPPORT * sigma).to(sigma.dtype)


def _kernel_radius(sigma_max: float) -> int:
    return max(1, math.ceil(SUPPORT * sigma_max))


def _fixed_kernel(sigma: float, like: torch.Tensor) -> torch.Tensor:
    radius = _kernel_radius(sigma)
    offsets = torch.arange(-radius, radius + 1, dtype=like.dtype, device=like.device)
    kernel = torch.exp(-offsets * offsets / (2.0 * sigma * sigma)) * (offsets.abs() <= max(SUPPORT * sigma, 1.0))
    return kernel / kernel.sum()


def _correlate_axis(image: torch.Tensor, kernel: torch.Tensor, axis: int, padding_mode: str) -> torch.Tensor:
    """``kernel`` correlated with ``image`` along ``axis`` (3: x, 2: y); the border is padded by
    ``padding_mode`` ("replicate" keeps the size, "constant" grows it by the kernel's length - 1)."""
    radius = (kernel.numel() - 1) // 2
    channels = image.shape[1]
    if axis == 3:
        weight = kernel.view(1, 1, 1, -1).expand(channels, 1, 1, -1)
        pad = (radius, radius, 0, 0)
    else:
        weight = kernel.view(1, 1, -1, 1).expand(channels, 1, -1, 1)
        pad = (0, 0, radius, radius)
    if padding_mode == "constant":
        pad = tuple(2 * p for p in pad)
    return F.conv2d(F.pad(image, pad, mode=padding_mode), weight, groups=channels)


class _FixedBlurAxis(torch.autograd.Function):
    """One axis of a fixed Gaussian with replicated borders, with an analytic backward, both
    as banded matrix products (:mod:`wise.filters.banded`): on the CPU several times faster
    than the depthwise convolution (:func:`_correlate_axis`, the reference its tests compare
    with), whose generic backward is ten times slower still.

    The kernel is symmetric, so the adjoint of the correlation is the same correlation of the
    zero-padded gradient; the adjoint of the replicated border adds the gradient that fell on
    the padding to the outermost pixels.
    """

    @staticmethod
    def forward(ctx, image: torch.Tensor, kernel: torch.Tensor, axis: int) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(kernel)
        ctx.axis = axis
        return correlate_axis(image, kernel, axis)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        (kernel,) = ctx.saved_tensors
        axis = ctx.axis
        if not torch.is_grad_enabled():
            return correlate_axis_adjoint(grad, kernel, axis), None, None
        # a second derivative is asked for: differentiable operations only
        radius = (kernel.numel() - 1) // 2
        size = grad.shape[axis]
        on_padded = _correlate_axis(grad, kernel, axis, "constant")
        inner = on_padded.narrow(axis, radius, size).clone()
        inner.narrow(axis, 0, 1).add_(on_padded.narrow(axis, 0, radius).sum(axis, keepdim=True))
        inner.narrow(axis, size - 1, 1).add_(on_padded.narrow(axis, size + radius, radius).sum(axis, keepdim=True))
        return inner, None, None


def _blur_axis_fixed(image: torch.Tensor, sigma: float, axis: int) -> torch.Tensor:
    return _FixedBlurAxis.apply(image, _fixed_kernel(sigma, image), axis)


def _blur_by_pyramid(image: torch.Tensor, pixels: float) -> torch.Tensor:
    # A wide Gaussian of a smooth result: blur a box-reduced copy and interpolate it back.
    # Reductions are powers of two anchored at the top-left pixel, so tiles whose origins are
    # multiples of the reduction see the same grid as the whole picture.
    factor = min(MAX_PYRAMID_REDUCTION, 2 ** int(math.log2(pixels / PYRAMID_SIGMA)))
    height, width = image.shape[-2:]
    reduced = F.avg_pool2d(image, factor, ceil_mode=True)
    blurred = _blur_axis_fixed(_blur_axis_fixed(reduced, pixels / factor, 3), pixels / factor, 2)
    enlarged = bilinear_resize(blurred, (blurred.shape[-2] * factor, blurred.shape[-1] * factor))
    return enlarged[..., :height, :width]


def _blur_axis_varying(image: torch.Tensor, sigma: torch.Tensor, axis: int) -> torch.Tensor:
    radius = _kernel_radius(max_value(sigma))
    if fused.enabled(image, sigma):
        from wise.filters.fused.gaussian import VaryingBlurAxis

        return VaryingBlurAxis.apply(image, sigma, axis, radius, SUPPORT)
    size = image.shape[axis]
    pad = (radius, radius, 0, 0) if axis == 3 else (0, 0, radius, radius)
    padded = F.pad(image, pad, mode="replicate")

    neg_inv_two_sigma_sq = -0.5 / sigma.square()

    def tap(k: int, padded, sigma, neg_inv_two_sigma_sq):
        shifted = padded.narrow(axis, k, size)
        distance = float(k - radius)
        weight = torch.exp(distance * distance * neg_inv_two_sigma_sq) * in_support(
            abs(distance), sigma, abs(distance) <= 1
        )
        return weight * shifted, weight

    total, norm = tap_sum(tap, 2 * radius + 1, padded, sigma, neg_inv_two_sigma_sq)
    return total / norm


def gaussian_blur(image: torch.Tensor, sigma: ParamLike, scale: float | None = None) -> torch.Tensor:
    """Separable Gaussian smoothing, truncated at two sigma.

    Args:
        image: ``(B, C, H, W)``.
        sigma: standard deviation in pixels of a 512-pixel short side; a float, ``(B,)``
            or a per-pixel map ``(B, 1, H, W)``.
        scale: pixels per reference pixel; defaults to ``min(H, W) / 512`` so that the
            result looks the same at every resolution. Pass 1.0 for plain pixels.

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    s = resolution_scale(image) if scale is None else scale
    if isinstance(sigma, (int, float)):
        pixels = max(float(sigma) * s, MIN_SIGMA)
        if pixels >= 2 * PYRAMID_SIGMA:
            return _blur_by_pyramid(image, pixels)
        return _blur_axis_fixed(_blur_axis_fixed(image, pixels, 3), pixels, 2)
    pixels = (as_map(sigma, image, "sigma") * s).clamp_min(MIN_SIGMA)
    return _blur_axis_varying(_blur_axis_varying(image, pixels, 3), pixels, 2)


def local_deviation(image: torch.Tensor, sigma: float, scale: float | None = None) -> torch.Tensor:
    """The local standard deviation of each channel in a Gaussian window,
    ``sqrt(G * x^2 - (G * x)^2)``: how much an image varies around each pixel.

    Args:
        image: ``(B, C, H, W)``.
        sigma: window in pixels of a 512-pixel short side.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``, non-negative.
    """
    check_image(image)
    mean, mean_of_squares = gaussian_blur(torch.cat((image, image * image), dim=1), sigma, scale).chunk(2, dim=1)
    variance = (mean_of_squares - mean * mean).clamp_min(0.0)
    return torch.sqrt(variance + _DEVIATION_EPS) - math.sqrt(_DEVIATION_EPS)


def local_detail(image: torch.Tensor, sigma: float, window: float, scale: float | None = None) -> torch.Tensor:
    """The local amount of fine detail of each channel: the absolute difference of the image from
    its Gaussian blur of ``sigma``, averaged in a Gaussian window of ``window``. Unlike
    :func:`local_deviation` it is zero on smooth shading (a linear ramp equals its blur), so the
    shading of a cheek does not count as structure, while texture and edges do.

    Args:
        image: ``(B, C, H, W)``.
        sigma: scale of the detail, in pixels of a 512-pixel short side.
        window: the averaging window, in pixels of a 512-pixel short side.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``, non-negative.
    """
    check_image(image)
    difference = image - gaussian_blur(image, sigma, scale)
    magnitude = torch.sqrt(difference * difference + _DEVIATION_EPS) - math.sqrt(_DEVIATION_EPS)
    return gaussian_blur(magnitude, window, scale)
