"""The orientation-aligned, separated bilateral filter."""

from __future__ import annotations

import math

import torch

from wise.filters._checks import ParamLike, as_map, check_image, max_value, resolution_scale
from wise.filters.flow import check_direction, pixel_step
from wise.filters.gaussian import MIN_SIGMA
from wise.filters.sampling import sample, tap_sum
from wise.filters.structure import gradient_direction


def _merged_samples_needed(sigma_max: float) -> int:
    # merged sample j covers the pixel steps 2j-1 and 2j; steps beyond 2 sigma are cut off
    return max(1, math.floor((2.0 * sigma_max + 1.0) / 2.0))


def bilateral_pass(
    image: torch.Tensor,
    direction: torch.Tensor,
    sigma_d: ParamLike,
    sigma_r: ParamLike,
    samples: int = 3,
    scale: float | None = None,
) -> torch.Tensor:
    """One pass of the separated bilateral filter along a direction field.

    Grid-sampling formulation of Lötzsch et al. 2022 (supplement, Eq. 3-5) of the filter
    of Kyprianidis & Döllner 2008: for every pixel, ``samples`` bilinear samples on each
    side along ``direction``, each merging two neighbouring pixel steps (linear
    sampling), weighted by a spatial Gaussian ``sigma_d`` cut off at two sigma and a
    range Gaussian ``sigma_r`` on the colour difference. Gradients reach the image, the
    direction and both sigmas; backward recomputes the samples instead of storing them.

    Args:
        image: ``(B, C, H, W)``, e.g. CIE Lab (the range distance is Euclidean over channels).
        direction: ``(B, 2, H, W)`` unit vectors.
        sigma_d: spatial sigma in pixels of a 512-pixel short side; float, ``(B,)`` or ``(B, 1, H, W)``.
        sigma_r: range sigma in the image's units; float, ``(B,)`` or ``(B, 1, H, W)``.
        samples: D, the maximum number of samples on each side (reach ``2 * D`` pixel steps).
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    check_direction(direction, image)
    s = resolution_scale(image) if scale is None else scale
    spatial = (as_map(sigma_d, image, "sigma_d") * s).clamp_min(MIN_SIGMA)
    two_range_sq = 2.0 * as_map(sigma_r, image, "sigma_r").clamp_min(MIN_SIGMA) ** 2
    n = min(samples, _merged_samples_needed(max_value(spatial)))
    step = pixel_step(direction)

    def tap(k: int, image, direction, step, spatial, two_range_sq):
        j, sign = k // 2 + 1, (1.0 if k % 2 == 0 else -1.0)
        near, far = (2 * j - 1) * step, 2 * j * step
        two_spatial_sq = 2.0 * spatial**2
        w_near = torch.exp(-(near**2) / two_spatial_sq)
        w_far = torch.exp(-(far**2) / two_spatial_sq)
        w_spatial = (w_near + w_far) * (near <= 2.0 * spatial)
        distance = (near * w_near + far * w_far) / (w_near + w_far).clamp_min(1e-12)
        value = sample(image, direction * (sign * distance))
        w = w_spatial * torch.exp(-((value - image) ** 2).sum(dim=1, keepdim=True) / two_range_sq)
        return w * value, w

    total, norm = tap_sum(tap, 2 * n, image, direction, step, spatial, two_range_sq)
    return (image + total) / (1.0 + norm)


def oriented_bilateral(
    image: torch.Tensor,
    tangent: torch.Tensor,
    sigma_d: ParamLike,
    sigma_r: ParamLike,
    samples: int = 3,
    scale: float | None = None,
) -> torch.Tensor:
    """Orientation-aligned bilateral filter (Kyprianidis & Döllner 2008): a pass across the
    edges (along the gradient) followed by a pass along them (the tangent).

    See :func:`bilateral_pass` for the arguments; ``tangent`` is the edge tangent flow.
    """
    across = bilateral_pass(image, gradient_direction(tangent), sigma_d, sigma_r, samples, scale)
    return bilateral_pass(across, tangent, sigma_d, sigma_r, samples, scale)
