"""Helpers for filters that sample along a direction field."""

from __future__ import annotations

import math

import torch

from wise.filters._checks import ParamLike, as_map, check_image, resolution_scale
from wise.filters.gaussian import MIN_SIGMA
from wise.filters.sampling import offset_grid, sample_at_grid


def check_direction(direction: torch.Tensor, image: torch.Tensor, name: str = "direction") -> None:
    check_image(direction, name=name, channels=2)
    if direction.shape[0] not in (1, image.shape[0]) or direction.shape[-2:] != image.shape[-2:]:
        raise ValueError(f"{name} {tuple(direction.shape)} does not match the image {tuple(image.shape)}")


def pixel_step(direction: torch.Tensor) -> torch.Tensor:
    """Distance travelled along the unit ``direction`` (B, 2, H, W) per pixel of its major axis.

    Stepping ``k * pixel_step`` along the direction moves exactly ``k`` pixels along the
    axis the direction is closer to, so every sample lands on a pixel row or column.
    Returns ``(B, 1, H, W)`` values in [1, sqrt(2)].
    """
    return _PixelStep.apply(direction)


class _PixelStep(torch.autograd.Function):
    """``1 / max(|x|, |y|)`` keeping only its input for backward."""

    @staticmethod
    def forward(ctx, direction: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(direction)
        return 1.0 / torch.maximum(direction[:, 0:1].abs(), direction[:, 1:2].abs()).clamp_min(1e-6)

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        (direction,) = ctx.saved_tensors
        x, y = direction[:, 0:1], direction[:, 1:2]
        x_major = x.abs() >= y.abs()
        major = torch.where(x_major, x, y)
        g_major = -grad / major.abs().clamp_min(1e-6).square() * torch.sign(major)
        zero = torch.zeros_like(g_major)
        return torch.cat((torch.where(x_major, g_major, zero), torch.where(x_major, zero, g_major)), dim=1)


def flow_filter_inputs(
    image: torch.Tensor, tangent: torch.Tensor, sigma: ParamLike, scale: float | None
) -> tuple[float, torch.Tensor]:
    """Checks of a filter along a flow field; returns the scale and ``sigma`` in pixels."""
    check_image(image)
    check_direction(tangent, image, "tangent")
    s = resolution_scale(image) if scale is None else scale
    return s, (as_map(sigma, image, "sigma") * s).clamp_min(MIN_SIGMA)


def spaced_samples(reach: float, max_samples: int, min_spacing: float = 1.0) -> tuple[float, int]:
    """Spacing (pixels) and count of the samples on one side that cover ``reach`` pixels with
    at most ``max_samples``: every ``min_spacing`` pixels while that suffices, sparser beyond,
    so the cost of a kernel does not grow with its size."""
    spacing = max(min_spacing, reach / max_samples)
    return spacing, max(1, min(max_samples, math.floor(reach / spacing)))


@torch.no_grad()
def trace_streamlines(tangent: torch.Tensor, steps: int, step_length: float = 1.0) -> list[torch.Tensor]:
    """Sampling grids along the streamlines of ``tangent`` through every pixel, both ways.

    Euler integration in unit steps; the orientation of each newly sampled tangent is
    flipped to agree with the previous one, since a tangent field has no sign.

    Args:
        tangent: ``(B, 2, H, W)`` unit vectors.
        steps: number of steps in each direction.

    Returns:
        ``2 * steps`` grids ``(B, H, W, 2)`` for :func:`sample_at_grid`: the forward
        streamline first, then the backward one.
    """
    grids: list[torch.Tensor] = []
    for sign in (1.0, -1.0):
        heading = tangent * sign
        offset = torch.zeros_like(tangent)
        for _ in range(steps):
            offset = offset + heading * step_length
            grid = offset_grid(offset)
            grids.append(grid)
            sampled = sample_at_grid(tangent, grid)
            agree = sampled[:, 0:1] * heading[:, 0:1] + sampled[:, 1:2] * heading[:, 1:2]
            flip = 1.0 - 2.0 * (agree < 0).to(sampled.dtype)
            heading = sampled * (flip / torch.hypot(sampled[:, 0:1], sampled[:, 1:2]).clamp_min(1e-6))
    return grids
