"""Inputs for the filter tests: seeded float64 tensors and unit vector fields."""

import math

import torch

DOUBLE = torch.float64


def rand(*shape: int, low: float = 0.0, high: float = 1.0, seed: int = 0) -> torch.Tensor:
    """Seeded uniform values in [low, high), float64, requiring grad."""
    g = torch.Generator().manual_seed(seed)
    return (torch.rand(*shape, generator=g, dtype=DOUBLE) * (high - low) + low).requires_grad_()


def unit_field(b: int, h: int, w: int, seed: int = 1) -> torch.Tensor:
    """A seeded ``(B, 2, H, W)`` field of random unit vectors, float64, requiring grad."""
    g = torch.Generator().manual_seed(seed)
    angle = torch.rand(b, 1, h, w, generator=g, dtype=DOUBLE) * 2 * math.pi
    return torch.cat((angle.cos(), angle.sin()), dim=1).requires_grad_()


def unit(v: torch.Tensor) -> torch.Tensor:
    """Normalize a ``(B, 2, H, W)`` field (differentiably)."""
    return v / torch.sqrt(v[:, 0:1] * v[:, 0:1] + v[:, 1:2] * v[:, 1:2])
