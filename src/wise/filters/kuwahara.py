"""The anisotropic Kuwahara filter with a fixed number of bilinear samples."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import torch
import torch.nn.functional as F

from wise.errors import WiseError
from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image, resolution_scale
from wise.filters.sampling import offset_grid, sample_at_grid
from wise.filters.structure import edge_tangent_flow, gradient_direction

RADIAL_SIGMA = 0.5
"""Sigma of the radial Gaussian in units of the kernel radius (Kyprianidis et al. 2009: r / 2)."""
CENTRE_WEIGHT = 1.0
"""Weight of the centre pixel in every sector; an off-centre sample has weight 1 in all sectors together."""
VARIANCE_SCALE = 255.0
"""Variances of [0, 1] images are measured in these units, as in the reference shaders of
Kyprianidis et al.: a_i = 1 / (1 + (255 s_i^2)^(q / 2)). Without it, q = 8 would hardly
tell sectors apart on [0, 1] images."""
MIN_ANISOTROPY_STRENGTH = 1e-3
_GOLDEN_RATIO_FRACTION = (math.sqrt(5.0) - 1.0) / 2.0
_DISCRIMINANT_EPS = 1e-12  # keeps sqrt differentiable where the tensor is isotropic
_TRACE_EPS = 1e-8  # anisotropy 0 where the tensor vanishes (flat regions)
_VARIANCE_EPS = 1e-12  # keeps log finite for a sector of constant colour
_BILINEAR, _BORDER = 0, 1  # grid_sampler_2d's interpolation and padding modes


@dataclass(frozen=True)
class _Tap:
    """One off-centre sample: its unit-disc position and its weight in the sectors it touches."""

    along: float  # along the edge tangent (the ellipse's major axis)
    across: float  # along the gradient (the minor axis)
    sector_weights: tuple[tuple[int, float], ...]


def _ring_radius(quantile: float) -> float:
    """Radius in the unit disc below which ``quantile`` of a Gaussian of :data:`RADIAL_SIGMA` cut at 1 lies."""
    two_sigma_sq = 2.0 * RADIAL_SIGMA * RADIAL_SIGMA
    inside_disc = 1.0 - math.exp(-1.0 / two_sigma_sq)
    return math.sqrt(-two_sigma_sq * math.log1p(-quantile * inside_disc))


@lru_cache(maxsize=16)
def _sample_layout(sectors: int, samples_per_sector: int) -> tuple[_Tap, ...]:
    """The off-centre samples: ring ``j`` carries one sample per sector (see :func:`anisotropic_kuwahara`)."""
    spacing = 2.0 * math.pi / sectors
    taps = []
    for j in range(samples_per_sector):
        radius = _ring_radius((j + 0.5) / samples_per_sector)
        shift = spacing * ((j * _GOLDEN_RATIO_FRACTION + 0.5) % 1.0 - 0.5)
        own_weight = math.cos(0.5 * math.pi * shift / spacing) ** 2
        leaning_towards = 1 if shift > 0 else -1
        for i in range(sectors):
            angle = i * spacing + shift
            weights = [(i, own_weight)]
            if own_weight < 1.0:
                weights.append(((i + leaning_towards) % sectors, 1.0 - own_weight))
            taps.append(_Tap(radius * math.cos(angle), radius * math.sin(angle), tuple(weights)))
    return tuple(taps)


class _SectorSums(torch.autograd.Function):
    """Weighted sums per sector of ``d`` and of ``|d|^2`` (over channels), ``d`` = sample - centre pixel.

    Inputs are the image and the sampling grid's major and minor axis vectors
    (``(B, H, W, 2)``, grid units); the sample at unit-disc position ``(u, v)`` lies at
    ``centre + u * major + v * minor``. Returns ``(N, B, C, H, W)`` and ``(N, B, 1, H, W)``.
    Backward recomputes each sample, so no per-sample tensor is kept.
    """

    @staticmethod
    def forward(ctx, image, centre, major, minor, taps: tuple[_Tap, ...], sectors: int):  # type: ignore[override]
        b, _, h, w = image.shape
        sums = image.new_zeros((sectors, *image.shape))
        square_sums = image.new_zeros((sectors, b, 1, h, w))
        for tap in taps:
            difference = sample_at_grid(image, _tap_grid(tap, centre, major, minor)).sub_(image)
            square = (difference * difference).sum(dim=1, keepdim=True)
            for sector, weight in tap.sector_weights:
                sums[sector].add_(difference, alpha=weight)
                square_sums[sector].add_(square, alpha=weight)
        ctx.save_for_backward(image, centre, major, minor)
        ctx.taps = taps
        return sums, square_sums

    @staticmethod
    def backward(ctx, grad_sums, grad_square_sums):  # type: ignore[override]
        image, centre, major, minor = ctx.saved_tensors
        need_image = ctx.needs_input_grad[0]
        g_image = torch.zeros_like(image)
        g_major = torch.zeros_like(major)
        g_minor = torch.zeros_like(minor)
        for tap in ctx.taps:
            grid = _tap_grid(tap, centre, major, minor)
            difference = sample_at_grid(image, grid).sub_(image)
            (first, first_weight), *others = tap.sector_weights
            g_linear = grad_sums[first] * first_weight
            g_square = grad_square_sums[first] * (2.0 * first_weight)
            for sector, weight in others:
                g_linear.add_(grad_sums[sector], alpha=weight)
                g_square.add_(grad_square_sums[sector], alpha=2.0 * weight)
            g_difference = g_linear.addcmul_(g_square, difference)
            g_sampled, g_grid = torch.ops.aten.grid_sampler_2d_backward(
                g_difference, image, grid, _BILINEAR, _BORDER, True, [need_image, True]
            )
            if need_image:
                g_image.add_(g_sampled).sub_(g_difference)
            g_major.add_(g_grid, alpha=tap.along)
            g_minor.add_(g_grid, alpha=tap.across)
        return (
            g_image if need_image else None,
            None,
            g_major if ctx.needs_input_grad[2] else None,
            g_minor if ctx.needs_input_grad[3] else None,
            None,
            None,
        )


def _tap_grid(tap: _Tap, centre: torch.Tensor, major: torch.Tensor, minor: torch.Tensor) -> torch.Tensor:
    return torch.add(centre, major, alpha=tap.along).add_(minor, alpha=tap.across)


def _anisotropy(tensor: torch.Tensor) -> torch.Tensor:
    """``(l1 - l2) / (l1 + l2)`` of the structure tensor's eigenvalues, 0 where it vanishes. ``(B, 1, H, W)``."""
    xx, xy, yy = tensor[:, 0:1], tensor[:, 1:2], tensor[:, 2:3]
    half_difference = 0.5 * (xx - yy)
    discriminant = half_difference * half_difference + xy * xy
    # sqrt(d + eps) - sqrt(eps) is 0 at d = 0 with a finite slope, and never exceeds the trace
    eigen_difference = 2.0 * (torch.sqrt(discriminant + _DISCRIMINANT_EPS) - math.sqrt(_DISCRIMINANT_EPS))
    return eigen_difference / ((xx + yy).clamp_min(0.0) + _TRACE_EPS)


def _check_structure_tensor(tensor: torch.Tensor, image: torch.Tensor) -> None:
    check_image(tensor, name="structure_tensor", channels=3)
    if tensor.shape[0] not in (1, image.shape[0]) or tensor.shape[-2:] != image.shape[-2:]:
        raise WiseError(f"structure_tensor {tuple(tensor.shape)} does not match the image {tuple(image.shape)}")


def _sector_weights(variances: torch.Tensor, sharpness: torch.Tensor) -> torch.Tensor:
    """Normalised ``a_i = 1 / (1 + s_i^q)``, computed as a softmax of ``log a_i``. ``(N, B, 1, H, W)``."""
    log_std_q = (0.5 * sharpness) * torch.log(variances.clamp_min(0.0) * VARIANCE_SCALE + _VARIANCE_EPS)
    return torch.softmax(-F.softplus(log_std_q), dim=0)


def anisotropic_kuwahara(
    image: torch.Tensor,
    structure_tensor: torch.Tensor,
    radius: ParamLike,
    sharpness: ParamLike = 8.0,
    anisotropy_strength: ParamLike = 1.0,
    scale: float | None = None,
    sectors: int = 8,
    samples_per_sector: int = 3,
) -> torch.Tensor:
    """Anisotropic Kuwahara filter (Kyprianidis, Kang & Döllner 2009) from a fixed set of samples.

    The kernel is an ellipse along the edge tangent (minor eigenvector of the structure
    tensor) with semi-axes ``r (alpha + A) / alpha`` along and ``r alpha / (alpha + A)``
    across the edge, A = (l1 - l2) / (l1 + l2) the anisotropy, ``alpha`` =
    ``anisotropy_strength`` and ``r = radius * scale``. Its unit disc is split into N =
    ``sectors`` sectors; each sector's weighted mean ``m_i`` and variance ``s_i^2``
    (summed over channels) give the output ``sum a_i m_i / sum a_i`` with
    ``a_i = 1 / (1 + (255 s_i^2)^(q / 2))``, q = ``sharpness`` (the 255 as in the paper's
    shaders, for [0, 1] images).

    Sample layout (in the unit disc, mapped through the ellipse, bilinearly sampled): the
    centre pixel, in every sector with weight 1, and ``samples_per_sector`` rings. Ring
    ``j`` lies at the radius below which a fraction ``(j + 0.5) / samples_per_sector``
    of a Gaussian of sigma 0.5 (cut at 1) lies, so samples are spread by the radial
    Gaussian and all weigh the same; it carries one sample per sector, at the sector's
    axis turned by ``frac(j * 0.618 + 0.5) - 0.5`` of a sector (golden-ratio stagger).
    A sample ``delta`` from its sector's axis weighs ``cos^2(pi delta / 2 Delta)`` in
    that sector and ``sin^2`` in the neighbour it leans towards (``Delta`` = sector
    width), a smooth angular window. In all ``sectors * samples_per_sector`` samples plus
    the centre; the defaults take 24.

    Gradients reach the image, the structure tensor, ``radius``, ``sharpness`` and
    ``anisotropy_strength``; backward recomputes the samples instead of storing them.

    Args:
        image: ``(B, C, H, W)``, values in [0, 1] (e.g. RGB).
        structure_tensor: ``(B, 3, H, W)`` smoothed structure tensor ``(fx*fx, fx*fy, fy*fy)``,
            e.g. from :func:`wise.filters.structure.smoothed_structure_tensor`.
        radius: kernel radius in pixels of a 512-pixel short side; float, ``(B,)`` or ``(B, 1, H, W)``.
        sharpness: q, how strongly low-variance sectors win.
        anisotropy_strength: alpha; large values make the ellipse a disc.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).
        sectors: N, the number of sectors.
        samples_per_sector: off-centre samples per sector (rings).

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    _check_structure_tensor(structure_tensor, image)
    if sectors < 2 or samples_per_sector < 1:
        raise WiseError(f"need at least 2 sectors and 1 sample per sector, got {sectors} and {samples_per_sector}")
    s = resolution_scale(image) if scale is None else scale
    r = (as_map(radius, image, "radius") * s).clamp_min(0.0)
    alpha = as_map(anisotropy_strength, image, "anisotropy_strength").clamp_min(MIN_ANISOTROPY_STRENGTH)
    q = as_map(sharpness, image, "sharpness")

    b, _, h, w = image.shape
    structure_tensor = structure_tensor.to(image.dtype).expand(b, -1, -1, -1)
    tangent = edge_tangent_flow(structure_tensor)
    stretch = (alpha + _anisotropy(structure_tensor)) / alpha
    centre = offset_grid(image.new_zeros(1, 2, h, w))
    major = offset_grid(tangent * (r * stretch)) - centre
    minor = offset_grid(gradient_direction(tangent) * (r / stretch)) - centre

    taps = _sample_layout(sectors, samples_per_sector)
    total_weight = samples_per_sector + CENTRE_WEIGHT
    if fused.enabled(image, major, minor, q):
        from wise.filters.fused.kuwahara import AnisotropicKuwahara

        settings = (taps, sectors, float(total_weight), VARIANCE_SCALE, _VARIANCE_EPS, torch.is_grad_enabled())
        return AnisotropicKuwahara.apply(image, major, minor, q, *settings)
    sums, square_sums = _SectorSums.apply(image, centre, major, minor, taps, sectors)
    mean_offsets = sums / total_weight
    variances = square_sums / total_weight - (mean_offsets * mean_offsets).sum(dim=2, keepdim=True)
    weights = _sector_weights(variances, q)
    return image + (weights * mean_offsets).sum(dim=0)
