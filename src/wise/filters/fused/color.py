"""Fused colour space conversions of :mod:`wise.filters.color`, each one Dr.Jit kernel per pass.

The same formulas as the PyTorch functions (sRGB transfer function IEC 61966-2-1, CIE 1976
L*a*b* with the D65 white point), written per pixel on channel planes
(:mod:`wise.filters.fused._pointwise`); backward by Dr.Jit's automatic differentiation. The
constants are passed in by the PyTorch module, which stays their one source.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import torch

from wise.filters.fused import _pointwise
from wise.filters.fused._lanes import maximum, minimum


@dataclass(frozen=True)
class Constants:
    """The colour constants of :mod:`wise.filters.color`."""

    srgb_linear_limit: float
    srgb_encoded_limit: float
    white: tuple[float, float, float]
    lab_epsilon: float
    lab_kappa: float
    rgb_to_xyz: tuple[tuple[float, ...], ...]
    xyz_to_rgb: tuple[tuple[float, ...], ...]


def _srgb_to_linear(value, k: Constants):
    high = dr.power((maximum(value, k.srgb_linear_limit) + 0.055) / 1.055, 2.4)
    return dr.select(value > k.srgb_linear_limit, high, value / 12.92)


def _linear_to_srgb(value, k: Constants):
    high = 1.055 * dr.power(maximum(value, k.srgb_encoded_limit), 1.0 / 2.4) - 0.055
    return dr.select(value > k.srgb_encoded_limit, high, value * 12.92)


def _times(matrix: tuple[tuple[float, ...], ...], vector: list) -> list:
    return [row[0] * vector[0] + row[1] * vector[1] + row[2] * vector[2] for row in matrix]


def rgb_to_lab(image: torch.Tensor, constants: Constants) -> torch.Tensor:
    """sRGB ``(B, 3, H, W)`` in [0, 1] to CIE L*a*b* (D65)."""

    def planes(rgb):
        xyz = _times(constants.rgb_to_xyz, [_srgb_to_linear(v, constants) for v in rgb])
        f = []
        for value, white in zip(xyz, constants.white):
            ratio = value / white
            cube_root = dr.cbrt(maximum(ratio, constants.lab_epsilon))
            f.append(dr.select(ratio > constants.lab_epsilon, cube_root, (constants.lab_kappa * ratio + 16.0) / 116.0))
        return 116.0 * f[1] - 16.0, 500.0 * (f[0] - f[1]), 200.0 * (f[1] - f[2])

    return _pointwise.apply(planes, image)


def lab_to_rgb(lab: torch.Tensor, constants: Constants, clip: bool) -> torch.Tensor:
    """CIE L*a*b* (D65) ``(B, 3, H, W)`` to sRGB, clamped to [0, 1] where ``clip``."""

    def planes(channels):
        lightness, a, b = channels
        fy = (lightness + 16.0) / 116.0
        xyz = []
        for f, white in zip((fy + a / 500.0, fy, fy - b / 200.0), constants.white):
            cube = f * f * f
            ratio = dr.select(cube > constants.lab_epsilon, cube, (116.0 * f - 16.0) / constants.lab_kappa)
            xyz.append(ratio * white)
        rgb = [_linear_to_srgb(v, constants) for v in _times(constants.xyz_to_rgb, xyz)]
        return [minimum(maximum(v, 0.0), 1.0) for v in rgb] if clip else rgb

    return _pointwise.apply(planes, lab)


def srgb_to_linear(image: torch.Tensor, constants: Constants) -> torch.Tensor:
    """sRGB-encoded values to linear light, per channel."""
    return _pointwise.apply(lambda channels: [_srgb_to_linear(v, constants) for v in channels], image)


def linear_to_srgb(image: torch.Tensor, constants: Constants) -> torch.Tensor:
    """Linear light to sRGB encoding, per channel."""
    return _pointwise.apply(lambda channels: [_linear_to_srgb(v, constants) for v in channels], image)
