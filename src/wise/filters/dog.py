"""Flow-based difference of Gaussians, line-integral smoothing and the XDoG threshold."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image, max_value
from wise.filters.flow import flow_filter_inputs, pixel_step, spaced_samples, trace_streamlines
from wise.filters.gaussian import SUPPORT, in_support
from wise.filters.sampling import offset_grid, sample, sample_at_grid, sample_backward, sum_to, tap_sum
from wise.filters.smoothing import gradient_softness, step_temperature
from wise.filters.structure import gradient_direction

WIDE_TO_NARROW = 1.6
"""Ratio of the wide to the narrow Gaussian in the DoG (Winnemöller et al. 2012)."""
SOFTENING_DECADES = 2.5
"""The threshold's ramp is ``10 ** (SOFTENING_DECADES * t)`` times wider at step temperature ``t``."""
CORNER_WIDTH = 0.5
"""Width of the smooth minimum that rounds the threshold's corner at step temperature 1."""


class _DogTaps(torch.autograd.Function):
    """Sums over the samples across the flow for the narrow and the wide Gaussian.

    Returns ``sum w_n v``, ``sum w_n``, ``sum w_w v`` and ``sum w_w``. Backward recomputes
    the samples with analytic derivatives; only the inputs are kept.
    """

    @staticmethod
    def _weights(i: int, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq):
        distance = i * step
        distance_sq = distance * distance
        inside = in_support(distance, wide, nearest=i == 1)
        w_narrow = torch.exp(distance_sq * neg_inv_two_narrow_sq) * inside
        w_wide = torch.exp(distance_sq * neg_inv_two_wide_sq) * inside
        return distance, distance_sq, w_narrow, w_wide

    @staticmethod
    def forward(ctx, image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq, steps: int):  # type: ignore[override]
        sum_narrow, sum_wide = torch.zeros_like(image), torch.zeros_like(image)
        norm_narrow, norm_wide = torch.zeros_like(step), torch.zeros_like(step)
        for i in range(1, steps + 1):
            distance, _, w_narrow, w_wide = _DogTaps._weights(i, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq)
            both_sides = sample(image, direction * distance) + sample(image, direction * -distance)
            sum_narrow.addcmul_(w_narrow, both_sides)
            sum_wide.addcmul_(w_wide, both_sides)
            norm_narrow.add_(w_narrow, alpha=2.0)
            norm_wide.add_(w_wide, alpha=2.0)
        ctx.save_for_backward(image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq)
        ctx.steps = steps
        return sum_narrow, norm_narrow, sum_wide, norm_wide

    @staticmethod
    def backward(ctx, g_sum_narrow, g_norm_narrow, g_sum_wide, g_norm_wide):  # type: ignore[override]
        image, direction, step, wide, neg_narrow, neg_wide = ctx.saved_tensors
        need_image = ctx.needs_input_grad[0]
        full = torch.broadcast_shapes(step.shape, neg_narrow.shape, neg_wide.shape)
        g_image = torch.zeros_like(image)
        g_direction = torch.zeros_like(direction)
        g_step = torch.zeros(full, dtype=step.dtype, device=step.device)
        g_neg_narrow, g_neg_wide = torch.zeros_like(g_step), torch.zeros_like(g_step)
        for i in range(1, ctx.steps + 1):
            distance, distance_sq, w_narrow, w_wide = _DogTaps._weights(i, step, wide, neg_narrow, neg_wide)
            g_value = g_sum_narrow * w_narrow + g_sum_wide * w_wide
            g_offset_signed = torch.zeros_like(direction)
            both_sides = torch.zeros_like(image)
            for sign in (1.0, -1.0):
                grid = offset_grid(direction * (sign * distance))
                both_sides.add_(sample_at_grid(image, grid))
                g_sampled_image, g_offset = sample_backward(g_value, image, grid, need_image)
                if g_sampled_image is not None:
                    g_image.add_(g_sampled_image)
                g_offset_signed.add_(g_offset, alpha=sign)
            g_w_narrow = (g_sum_narrow * both_sides).sum(dim=1, keepdim=True) + 2.0 * g_norm_narrow
            g_w_wide = (g_sum_wide * both_sides).sum(dim=1, keepdim=True) + 2.0 * g_norm_wide
            g_log_narrow, g_log_wide = g_w_narrow * w_narrow, g_w_wide * w_wide
            g_neg_narrow.addcmul_(g_log_narrow, distance_sq)
            g_neg_wide.addcmul_(g_log_wide, distance_sq)
            g_direction.addcmul_(g_offset_signed, distance)
            g_distance = (
                g_offset_signed[:, 0:1] * direction[:, 0:1]
                + g_offset_signed[:, 1:2] * direction[:, 1:2]
                + 2.0 * distance * (g_log_narrow * neg_narrow + g_log_wide * neg_wide)
            )
            g_step.add_(g_distance, alpha=float(i))
        wanted = ctx.needs_input_grad
        return (
            g_image if need_image else None,
            g_direction if wanted[1] else None,
            sum_to(g_step, step.shape) if wanted[2] else None,
            None,
            sum_to(g_neg_narrow, neg_narrow.shape) if wanted[4] else None,
            sum_to(g_neg_wide, neg_wide.shape) if wanted[5] else None,
            None,
        )


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
        max_steps: the most samples on each side; a wider kernel is sampled every few
            pixels instead of every pixel, so the cost does not grow with the resolution.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``.
    """
    s, narrow = flow_filter_inputs(image, tangent, sigma, scale)
    wide = narrow * WIDE_TO_NARROW
    spacing, steps = spaced_samples(SUPPORT * max_value(wide), max_steps)
    direction = gradient_direction(tangent).expand(image.shape[0], -1, -1, -1)  # one flow may serve a batch
    step = pixel_step(direction) * spacing

    neg_inv_two_narrow_sq = -0.5 / narrow.square()
    neg_inv_two_wide_sq = -0.5 / wide.square()

    if fused.enabled(image, direction, step, wide):
        from wise.filters.fused.dog import DogTaps

        taps = DogTaps.apply(image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq, steps, SUPPORT)
    else:
        taps = _DogTaps.apply(image, direction, step, wide, neg_inv_two_narrow_sq, neg_inv_two_wide_sq, steps)
    sum_narrow, norm_narrow, sum_wide, norm_wide = taps
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
    one pixel, longer when ``max_steps`` would not reach two sigma), so the cost does not
    grow with the resolution; gradients reach the image and ``sigma`` (the streamline
    geometry is treated as fixed).

    Args:
        image: ``(B, C, H, W)``.
        tangent: ``(B, 2, H, W)`` unit vectors.
        sigma: in pixels of a 512-pixel short side; float, ``(B,)`` or ``(B, 1, H, W)``.
        max_steps: the most steps taken on each side.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``.
    """
    s, sigma_px = flow_filter_inputs(image, tangent, sigma, scale)
    step_length, steps = spaced_samples(SUPPORT * max_value(sigma_px), max_steps, max(1.0, s))
    neg_inv_two_sigma_sq = -0.5 / sigma_px.square()

    if fused.enabled(image, tangent, sigma_px):
        from wise.filters.fused.dog import FlowSmoothingTaps

        total, norm = FlowSmoothingTaps.apply(
            image, tangent.detach(), sigma_px, neg_inv_two_sigma_sq, steps, step_length, SUPPORT
        )
        return (image + total) / (1.0 + norm)

    grids = trace_streamlines(tangent.detach(), steps, step_length)

    def tap(k: int, image, sigma_px, neg_inv_two_sigma_sq):
        distance = (k % steps + 1) * step_length
        weight = torch.exp(distance * distance * neg_inv_two_sigma_sq) * in_support(distance, sigma_px, k % steps == 0)
        return weight * sample_at_grid(image, grids[k]), weight

    total, norm = tap_sum(tap, 2 * steps, image, sigma_px, neg_inv_two_sigma_sq)
    return (image + total) / (1.0 + norm)


def xdog_threshold(image: torch.Tensor, epsilon: ParamLike, sharpness: ParamLike) -> torch.Tensor:
    """The XDoG soft threshold (Winnemöller et al. 2012): 1 above ``epsilon``,
    ``1 + tanh(sharpness * (u - epsilon))`` below it.

    Under a step temperature ``t > 0`` (:func:`wise.filters.smoothing.smoothed_steps`) the
    ramp is ``10 ** (SOFTENING_DECADES * t)`` times wider and the corner at ``epsilon`` is rounded
    by a smooth minimum of width ``CORNER_WIDTH * t``, so that pixels far from the threshold
    still pass gradients to ``epsilon``; at 0 it is the threshold above, exactly. Under a
    gradient softness ``s > 0`` (:func:`wise.filters.smoothing.softened_gradients`) it renders
    as at ``s = 0`` and backward differentiates ``tanh`` of a ramp ``10 ** (SOFTENING_DECADES * s)``
    times wider through ``epsilon`` instead.

    Args:
        image: ``(B, C, H, W)`` DoG response.
        epsilon: threshold; float, ``(B,)`` or ``(B, 1, H, W)``.
        sharpness: phi, the steepness of the soft ramp.

    Returns:
        ``(B, C, H, W)`` in [0, 1].
    """
    check_image(image)
    eps = as_map(epsilon, image, "epsilon")
    phi = as_map(sharpness, image, "sharpness")
    softness = gradient_softness()
    if softness <= 0.0:
        return _threshold(image, eps, phi, step_temperature())
    with torch.no_grad():
        rendered = _threshold(image, eps, phi, step_temperature())
    # straight through: the value rendered, the gradient of a ramp through the threshold
    # that reaches both sides of it (the white side of the exact step is flat)
    surrogate = torch.tanh(phi * 10.0 ** (-SOFTENING_DECADES * softness) * (image - eps))
    return surrogate + (rendered - surrogate).detach()


def _threshold(image: torch.Tensor, eps: torch.Tensor, phi: torch.Tensor, temperature: float) -> torch.Tensor:
    if temperature > 0.0:
        phi = phi * 10.0 ** (-SOFTENING_DECADES * temperature)
        width = CORNER_WIDTH * temperature
        # smooth minimum of 1 + tanh(z) and 1, 1 - w softplus(-tanh(z) / w), shifted by
        # w softplus(-1 / w) so that it spans [0, 1] like the threshold
        shift = width * math.log1p(math.exp(-1.0 / width))
        return (1.0 + shift) - width * F.softplus(-torch.tanh(phi * (image - eps)) / width)
    ramp = 1.0 + torch.tanh(phi * (image - eps))
    return torch.where(image >= eps, torch.ones_like(ramp), ramp)
