"""Flow-based Laplacian of Gaussian: the second derivative across the edges of a flow field."""

from __future__ import annotations

import torch

from wise.filters import fused
from wise.filters._checks import ParamLike, max_value
from wise.filters.flow import flow_filter_inputs, pixel_step, spaced_samples
from wise.filters.sampling import sample, tap_sum
from wise.filters.structure import gradient_direction

EXTENT = 3.0
"""The kernel reaches three sigma (the nearest samples always count); the second derivative of
a Gaussian still carries weight at two sigma, where the other filters stop."""
MIN_SIGMA = 0.3
"""Smallest sigma (pixels): below it the neighbours' weights vanish and the kernel degenerates."""
_MIN_CURVATURE = 1e-12


def _log_tap(k: int, image, direction, step, inv_sigma):
    """Samples ``k + 1`` pixel steps to both sides and their Gaussian / second-derivative weights.

    Returns ``g'' * v``, ``g * v``, ``g''``, ``g``, ``g'' * u^2`` and ``g * u^2`` for the
    pair of samples, with ``u`` the distance in sigmas, ``g = exp(-u^2 / 2)`` and
    ``g'' = (u^2 - 1) g`` (the Gaussian's second derivative up to a factor).
    """
    distance = (k + 1) * step
    u = distance * inv_sigma
    u_sq = u * u
    gauss = torch.exp(-0.5 * u_sq)
    if k > 0:
        gauss = gauss * (u <= EXTENT).to(u.dtype)
    second = (u_sq - 1.0) * gauss
    offset = direction * distance
    both_sides = sample(image, offset) + sample(image, -offset)
    return (
        second * both_sides,
        gauss * both_sides,
        2.0 * second,
        2.0 * gauss,
        2.0 * second * u_sq,
        2.0 * gauss * u_sq,
    )


def flow_log(
    image: torch.Tensor,
    tangent: torch.Tensor,
    sigma: ParamLike,
    scale: float | None = None,
    max_steps: int = 16,
) -> torch.Tensor:
    """Laplacian of Gaussian across the flow (Kyprianidis 2011), the edge enhancement of the oil
    paint filter of Semmo et al. 2016.

    The 1-D second derivative of a Gaussian along the gradient direction (perpendicular to
    ``tangent``), sampled every pixel step (:func:`~wise.filters.flow.pixel_step`) out to
    three sigma. The sampled kernel ``g''(u) - c g(u)`` is made zero-sum per pixel (so
    constants and linear ramps give 0) and normalized so that a quadratic gives its exact
    second derivative; the response is scale-normalized, ``sigma^2 * d^2/dt^2`` of the
    smoothed image, hence dimensionless and the same at every resolution. It is negative
    on the bright side of an edge and at the centre of a bright line (a step of height
    ``h`` peaks at about ``-0.24 h`` and ``+0.24 h``). Gradients reach the image, the tangent
    and ``sigma``.

    Args:
        image: ``(B, C, H, W)``, usually luminance.
        tangent: ``(B, 2, H, W)`` edge tangent flow (unit vectors).
        sigma: in pixels of a 512-pixel short side; float, ``(B,)`` or ``(B, 1, H, W)``.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).
        max_steps: the most samples on each side; a wider kernel is sampled every few pixels.

    Returns:
        ``(B, C, H, W)``.
    """
    _, sigma_px = flow_filter_inputs(image, tangent, sigma, scale)
    spacing, steps = spaced_samples(EXTENT * max_value(sigma_px), max_steps)
    direction = gradient_direction(tangent).expand(image.shape[0], -1, -1, -1)
    step = pixel_step(direction) * spacing

    if fused.enabled(image, direction, step, sigma_px):
        from wise.filters.fused.log import LogTaps

        sums = LogTaps.apply(image, direction, step, 1.0 / sigma_px, steps, EXTENT)
    else:
        sums = tap_sum(_log_tap, steps, image, direction, step, 1.0 / sigma_px)
    second_v, gauss_v, second, gauss, second_u2, gauss_u2 = sums
    # the centre sample: u = 0, g = 1, g'' = -1
    second_v = second_v - image
    gauss_v = gauss_v + image
    zero_sum = (second - 1.0) / (gauss + 1.0)
    curvature = (second_u2 - zero_sum * gauss_u2).clamp_min(_MIN_CURVATURE)
    return 2.0 * (second_v - zero_sum * gauss_v) / curvature
