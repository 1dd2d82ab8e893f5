"""Flow-based difference of Gaussians, line-integral smoothing and the XDoG threshold."""

from __future__ import annotations

import math

import torch

from wise.filters._checks import ParamLike, as_map, check_image, max_value, resolution_scale
from wise.filters.flow import check_direction, pixel_step, trace_streamlines
from wise.filters.gaussian import MIN_SIGMA, SUPPORT, in_support
from wise.filters.sampling import sample, sample_at_grid, tap_sum
from wise.filters.structure import gradient_direction

WIDE_TO_NARROW = 1.6
"""Ratio of the wide to the narrow Gaussian in the DoG (Winnemöller et al. 2012)."""


def flow_dog(
    image: torch.Tensor,
    tangent: torch.Tensor,
    sigma: ParamLike,
    sharpen: ParamLike,
    max_steps: int = 10,
    scale: float | None = None,
) -> torch.Tensor:
    """Difference of Gaussians across the flow, the first pass of the flow-based XDoG.

    ``(1 + p) * G(sigma) - p * G(1.6 sigma)`` computed by 1-D Gaussians along the
    gradient direction (perpendicular to ``tangent``), cut off at two sigma (nearest samples always count)
    (Kang et al. 2007; Winnemöller et al. 2012).

    Args:
        image: ``(B, C, H, W)``, usually luminance.
        tangent: ``(B, 2, H, W)`` edge tangent flow (unit vectors).
        sigma: narrow sigma in pixels of a 512-pixel short side.
        sharpen: p, the weight of the DoG edge response.
        max_steps: the most pixel steps sampled on each side.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    check_direction(tangent, image, "tangent")
    s = resolution_scale(image) if scale is None else scale
    narrow = (as_map(sigma, image, "sigma") * s).clamp_min(MIN_SIGMA)
    wide = narrow * WIDE_TO_NARROW
    steps = max(1, min(max_steps, math.floor(SUPPORT * max_value(wide))))
    direction = gradient_direction(tangent)
    step = pixel_step(direction)

    neg_inv_two_narrow_sq = -0.5 / narrow.square()
    neg_inv_two_wide_sq = -0.5 / wide.square()

    def tap(k: int, image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq):
        sign = 1.0 if k % 2 == 0 else -1.0
        distance = (k // 2 + 1) * step
        value = sample(image, direction * (sign * distance))
        distance_sq = distance * distance
        inside = in_support(distance, wide, nearest=k < 2)
        w_narrow = torch.exp(distance_sq * neg_inv_two_narrow_sq) * inside
        w_wide = torch.exp(distance_sq * neg_inv_two_wide_sq) * inside
        return w_narrow * value, w_narrow, w_wide * value, w_wide

    sum_narrow, norm_narrow, sum_wide, norm_wide = tap_sum(
        tap, 2 * steps, image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq
    )
    blur_narrow = (image + sum_narrow) / (1.0 + norm_narrow)
    blur_wide = (image + sum_wide) / (1.0 + norm_wide)
    p = as_map(sharpen, image, "sharpen")
    return (1.0 + p) * blur_narrow - p * blur_wide


def flow_smoothing(
    image: torch.Tensor,
    tangent: torch.Tensor,
    sigma: ParamLike,
    max_steps: int = 64,
    scale: float | None = None,
) -> torch.Tensor:
    """Gaussian line-integral smoothing along the streamlines of the flow.

    Line integral convolution (Cabral & Leedom 1993) with a Gaussian of ``sigma``,
    cut off at two sigma (nearest samples always count), as in the flow-based DoG and bilateral filters of Kyprianidis &
    Döllner 2008. Streamlines follow ``tangent`` in steps of one reference pixel (at least
    one pixel), so the cost does not grow with the resolution; gradients reach the image
    and ``sigma`` (the streamline geometry is treated as fixed).

    Args:
        image: ``(B, C, H, W)``.
        tangent: ``(B, 2, H, W)`` unit vectors.
        sigma: in pixels of a 512-pixel short side; float, ``(B,)`` or ``(B, 1, H, W)``.
        max_steps: the most steps taken on each side.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    check_direction(tangent, image, "tangent")
    s = resolution_scale(image) if scale is None else scale
    sigma_px = (as_map(sigma, image, "sigma") * s).clamp_min(MIN_SIGMA)
    step_length = max(1.0, s)
    steps = max(1, min(max_steps, math.floor(SUPPORT * max_value(sigma_px) / step_length)))
    grids = trace_streamlines(tangent.detach(), steps, step_length)

    neg_inv_two_sigma_sq = -0.5 / sigma_px.square()

    def tap(k: int, image, sigma_px, neg_inv_two_sigma_sq):
        distance = (k % steps + 1) * step_length
        weight = torch.exp(distance * distance * neg_inv_two_sigma_sq) * in_support(distance, sigma_px, k % steps == 0)
        return weight * sample_at_grid(image, grids[k]), weight

    total, norm = tap_sum(tap, 2 * steps, image, sigma_px, neg_inv_two_sigma_sq)
    return (image + total) / (1.0 + norm)


def xdog_threshold(image: torch.Tensor, epsilon: ParamLike, sharpness: ParamLike) -> torch.Tensor:
    """The XDoG soft threshold (Winnemöller et al. 2012): 1 above ``epsilon``,
    ``1 + tanh(sharpness * (u - epsilon))`` below it.

    Args:
        image: ``(B, C, H, W)`` DoG response.
        epsilon: threshold; float, ``(B,)`` or ``(B, 1, H, W)``.
        sharpness: phi, the steepness of the soft ramp.

    Returns:
        ``(B, C, H, W)`` in [0, 1].
    """
    check_image(image)
    eps = as_map(epsilon, image, "epsilon")
    ramp = 1.0 + torch.tanh(as_map(sharpness, image, "sharpness") * (image - eps))
    return torch.where(image >= eps, torch.ones_like(ramp), ramp)
