"""The orientation-aligned, separated bilateral filter."""

from __future__ import annotations

import math

import torch

from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image, max_value, resolution_scale
from wise.filters.flow import check_direction, pixel_step
from wise.filters.gaussian import MIN_SIGMA, SUPPORT, in_support
from wise.filters.sampling import offset_grid, sample, sample_at_grid, sample_backward, sum_to
from wise.filters.structure import gradient_direction


def _merged_samples_needed(sigma_max: float) -> int:
    # merged sample j covers the pixel steps 2j-1 and 2j; steps beyond 2 sigma are cut off
    return max(1, math.floor((SUPPORT * sigma_max + 1.0) / 2.0))


class _MergedSample:
    """Geometry of merged sample ``j`` (pixel steps ``2j - 1`` and ``2j``) of a bilateral pass."""

    def __init__(self, j: int, step: torch.Tensor, spatial: torch.Tensor, neg_inv_two_spatial_sq: torch.Tensor):
        self.n_near, self.n_far = 2 * j - 1, 2 * j
        self.near = self.n_near * step
        self.far = self.n_far * step
        self.w_near = torch.exp(self.near * self.near * neg_inv_two_spatial_sq)
        self.w_far = torch.exp(self.far * self.far * neg_inv_two_spatial_sq)
        self.w_pair = (self.w_near + self.w_far).clamp_min(1e-30)
        self.distance = (self.near * self.w_near + self.far * self.w_far) / self.w_pair
        self.inside = in_support(self.near, spatial, nearest=j == 1)


class _BilateralTaps(torch.autograd.Function):
    """Sums ``sum_k w_k v_k`` and ``sum_k w_k`` over the samples of one bilateral pass.

    Backward recomputes each sample and applies the analytic derivatives; only the
    inputs are kept between forward and backward.
    """

    @staticmethod
    def forward(ctx, image, direction, step, spatial, neg_inv_two_spatial_sq, neg_inv_two_range_sq, n: int):  # type: ignore[override]
        total = torch.zeros_like(image)
        norm = torch.zeros_like(step)
        for j in range(1, n + 1):
            geometry = _MergedSample(j, step, spatial, neg_inv_two_spatial_sq)
            for sign in (1.0, -1.0):
                value = sample(image, direction * (sign * geometry.distance))
                difference = value - image
                range_sq = (difference * difference).sum(dim=1, keepdim=True)
                weight = geometry.w_pair * geometry.inside * torch.exp(range_sq * neg_inv_two_range_sq)
                total.addcmul_(weight, value)
                norm.add_(weight)
        ctx.save_for_backward(image, direction, step, spatial, neg_inv_two_spatial_sq, neg_inv_two_range_sq)
        ctx.n = n
        return total, norm

    @staticmethod
    def backward(ctx, grad_total, grad_norm):  # type: ignore[override]
        image, direction, step, spatial, neg_a, neg_r = ctx.saved_tensors
        full = torch.broadcast_shapes(step.shape, neg_a.shape, neg_r.shape)
        g_image = torch.zeros_like(image)
        g_direction = torch.zeros_like(direction)
        g_step = torch.zeros(full, dtype=step.dtype, device=step.device)
        g_neg_a = torch.zeros_like(g_step)
        g_neg_r = torch.zeros_like(g_step)
        need_image = ctx.needs_input_grad[0]
        for j in range(1, ctx.n + 1):
            geo = _MergedSample(j, step, spatial, neg_a)
            g_w_pair = torch.zeros_like(geo.w_pair)
            g_offset_signed = torch.zeros_like(direction)
            for sign in (1.0, -1.0):
                grid = offset_grid(direction * (sign * geo.distance))
                value = sample_at_grid(image, grid)
                difference = value - image
                range_sq = (difference * difference).sum(dim=1, keepdim=True)
                range_weight = torch.exp(range_sq * neg_r)
                weight = geo.w_pair * geo.inside * range_weight
                g_weight = (grad_total * value).sum(dim=1, keepdim=True) + grad_norm
                g_log_range = g_weight * weight
                through_range = (2.0 * g_log_range * neg_r) * difference
                g_value = grad_total * weight + through_range
                g_image.sub_(through_range)
                g_neg_r.add_(g_log_range * range_sq)
                g_w_pair.add_(g_weight * geo.inside * range_weight)
                g_sampled_image, g_offset = sample_backward(g_value, image, grid, need_image)
                if g_sampled_image is not None:
                    g_image.add_(g_sampled_image)
                g_offset_signed.add_(g_offset, alpha=sign)
            # chain rule through the sample geometry, shared by both sides
            g_direction.addcmul_(g_offset_signed, geo.distance)
            g_distance = g_offset_signed[:, 0:1] * direction[:, 0:1] + g_offset_signed[:, 1:2] * direction[:, 1:2]
            g_distance_per_pair = g_distance / geo.w_pair
            g_w_near = g_w_pair + g_distance_per_pair * (geo.near - geo.distance)
            g_w_far = g_w_pair + g_distance_per_pair * (geo.far - geo.distance)
            g_near = g_w_near * geo.w_near * (2.0 * geo.near) * neg_a + g_distance_per_pair * geo.w_near
            g_far = g_w_far * geo.w_far * (2.0 * geo.far) * neg_a + g_distance_per_pair * geo.w_far
            g_neg_a.add_(g_w_near * geo.w_near * geo.near * geo.near + g_w_far * geo.w_far * geo.far * geo.far)
            g_step.add_(g_near * geo.n_near + g_far * geo.n_far)
        return (
            g_image if need_image else None,
            g_direction if ctx.needs_input_grad[1] else None,
            sum_to(g_step, step.shape) if ctx.needs_input_grad[2] else None,
            None,
            sum_to(g_neg_a, neg_a.shape) if ctx.needs_input_grad[4] else None,
            sum_to(g_neg_r, neg_r.shape) if ctx.needs_input_grad[5] else None,
            None,
        )


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
    sampling), weighted by a spatial Gaussian ``sigma_d`` cut off at two sigma (the nearest samples always count) and a
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
    neg_inv_two_range_sq = -0.5 / as_map(sigma_r, image, "sigma_r").clamp_min(MIN_SIGMA).square()
    n = min(samples, _merged_samples_needed(max_value(spatial)))
    direction = direction.expand(image.shape[0], -1, -1, -1)
    if fused.enabled(image, direction, spatial, neg_inv_two_range_sq):
        from wise.filters.fused.bilateral import BilateralPass

        return BilateralPass.apply(image, direction, spatial, neg_inv_two_range_sq, n, SUPPORT)

    step = pixel_step(direction)
    neg_inv_two_spatial_sq = -0.5 / spatial.square()
    total, norm = _BilateralTaps.apply(image, direction, step, spatial, neg_inv_two_spatial_sq, neg_inv_two_range_sq, n)
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


def bilateral(
    image: torch.Tensor,
    sigma_d: ParamLike,
    sigma_r: ParamLike,
    samples: int = 3,
    scale: float | None = None,
) -> torch.Tensor:
    """Bilateral filter (Tomasi & Manduchi 1998) over a fixed, axis-aligned neighbourhood,
    separated into a horizontal and a vertical pass (Pham & van Vliet 2005).

    See :func:`bilateral_pass` for the arguments.
    """
    check_image(image)
    b, _, h, w = image.shape
    horizontal = image.new_tensor([1.0, 0.0]).view(1, 2, 1, 1).expand(b, 2, h, w)
    vertical = image.new_tensor([0.0, 1.0]).view(1, 2, 1, 1).expand(b, 2, h, w)
    rows = bilateral_pass(image, horizontal, sigma_d, sigma_r, samples, scale)
    return bilateral_pass(rows, vertical, sigma_d, sigma_r, samples, scale)
