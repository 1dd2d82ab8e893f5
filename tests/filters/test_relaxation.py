"""Flow relaxation (Semmo et al. 2016): calm, coherent flow in flat regions, the local flow at edges."""

from __future__ import annotations

import math

import torch

from wise.filters import coarse_structure_tensor, edge_tangent_flow, relaxed_structure_tensor, smoothed_structure_tensor
from wise.filters.structure import anisotropy

RELAX = {"sigma": 24.0, "threshold": 16.0, "gain": 8.0, "wide_sigma": 48.0}


def coherence(tangent: torch.Tensor) -> float:
    """How parallel unit vectors are, ignoring their sign: |mean of exp(2i angle)| in [0, 1]."""
    angle = torch.atan2(tangent[:, 1], tangent[:, 0])
    return float(torch.complex(torch.cos(2 * angle), torch.sin(2 * angle)).mean().abs())


def flat_with_an_edge(size: int = 128) -> torch.Tensor:
    """Lightness (CIE L* scale) of a flat, slightly noisy grey with a strong vertical edge at x = 24."""
    generator = torch.Generator().manual_seed(0)
    image = 50.0 + 1.5 * torch.randn(1, 1, size, size, generator=generator)
    image[..., :24] += 40.0
    return image


def tensors(image: torch.Tensor, scale: float = 1.0) -> tuple[torch.Tensor, torch.Tensor]:
    local = smoothed_structure_tensor(image, 1.0, 4.0, scale) * scale**2
    coarse = coarse_structure_tensor(image, 8.0, 1.0, scale) * scale**2
    return local, relaxed_structure_tensor(local, coarse, scale=scale, **RELAX)


def test_flat_regions_become_coherent() -> None:
    local, relaxed = tensors(flat_with_an_edge())
    flat = (..., slice(40, 120), slice(60, 120))
    before = coherence(edge_tangent_flow(local)[flat])
    after = coherence(edge_tangent_flow(relaxed)[flat])
    assert before < 0.35, before
    assert after > 0.9, after


def test_strong_edges_keep_their_direction() -> None:
    local, relaxed = tensors(flat_with_an_edge())
    edge = (..., slice(16, 112), slice(22, 27))
    assert float(anisotropy(local)[edge].mean()) > 4 * RELAX["threshold"]
    along_local, along_relaxed = edge_tangent_flow(local)[edge], edge_tangent_flow(relaxed)[edge]
    agreement = (along_local * along_relaxed).sum(dim=1).abs()
    assert float(agreement.min()) > 0.99  # still along the vertical edge
    assert float(along_relaxed[:, 1].abs().mean()) > 0.99


def test_weak_regions_follow_the_wide_structure_and_commute_with_a_mirror() -> None:
    """A faint diagonal shading (far below the threshold) under noise sets the flow of a flat
    region, and the flow of the mirrored picture is the mirrored flow: no direction is built in."""
    generator = torch.Generator().manual_seed(2)
    ys, xs = torch.meshgrid(torch.arange(128.0), torch.arange(128.0), indexing="ij")
    image = (50.0 + 0.15 * (xs + 2.0 * ys) + 0.5 * torch.randn(128, 128, generator=generator))[None, None]
    _, relaxed = tensors(image)
    _, relaxed_mirrored = tensors(image.flip(-1))
    tangent = edge_tangent_flow(relaxed)[..., 16:112, 16:112]
    shading_gradient = torch.tensor((1.0, 2.0)) / math.sqrt(5.0)
    across = (tangent * shading_gradient.view(1, 2, 1, 1)).sum(dim=1).abs()
    assert float(across.mean()) < 0.1  # the strokes run along the isophotes of the shading
    mirrored = edge_tangent_flow(relaxed_mirrored).flip(-1)
    mirrored = torch.stack((-mirrored[:, 0], mirrored[:, 1]), dim=1)  # x-components change sign
    agreement = (edge_tangent_flow(relaxed) * mirrored).sum(dim=1).abs()
    assert float(agreement.min()) > 0.999


def test_relaxation_is_differentiable() -> None:
    image = flat_with_an_edge(48).requires_grad_()
    local, relaxed = tensors(image)
    relaxed.sum().backward()
    assert image.grad is not None and torch.isfinite(image.grad).all() and image.grad.abs().sum() > 0
