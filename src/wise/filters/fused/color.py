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
from wise.filters.fused._lanes import clamp


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
    high = dr.power((clamp(value, k.srgb_linear_limit) + 0.055) / 1.055, 2.4)
    return dr.select(value > k.srgb_linear_limit, high, value / 12.92)


def _linear_to_srgb(value, k: Constants):
    high = 1.055 * dr.power(clamp(value, k.srgb_encoded_limit), 1.0 / 2.4) - 0.055
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
            cube_root = dr.cbrt(clamp(ratio, constants.lab_epsilon))
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
        return [clamp(v, 0.0, 1.0) for v in rgb] if clip else rgb

    return _pointwise.apply(planes, lab)


def srgb_to_linear(image: torch.Tensor, constants: Constants) -> torch.Tensor:
    """sRGB-encoded values to linear light, per channel."""
    return _pointwise.apply(lambda channels: [_srgb_to_linear(v, constants) for v in channels], image)


def linear_to_srgb(image: torch.Tensor, constants: Constants) -> torch.Tensor:
    """Linear light to sRGB encoding, per channel."""
    return _pointwise.apply(lambda channels: [_linear_to_srgb(v, constants) for v in channels], image)


_SATURATION_FLOOR = 1e-8
_POW_FLOOR = 1e-8
_MIN_GAMMA = 0.1


def _first_of_three(a, b, c, take_a, take_b):
    return dr.select(take_a, a, dr.select(take_b, b, c))


def _value_and_low(r, g, b):
    """The largest and the smallest channel, each the first one among ties (as ``torch.max(dim)``)."""
    value = _first_of_three(r, g, b, (r >= g) & (r >= b), g >= b)
    low = _first_of_three(r, g, b, (r <= g) & (r <= b), g <= b)
    return value, low


def _scale_saturation(rgb: list, factor) -> list:
    value, low = _value_and_low(*rgb)
    chroma = value - low
    limit = value / clamp(chroma, _SATURATION_FLOOR)
    factor = clamp(factor, 0.0)
    k = dr.select(chroma > _SATURATION_FLOOR, dr.select(factor < limit, factor, limit), factor)
    return [value - k * (value - v) for v in rgb]


def _rotate_hue(rgb: list, shift) -> list:
    """HSV round trip with the hue turned by ``shift`` (Smith 1978), as ``rgb_to_hsv`` and ``hsv_to_rgb``."""
    r, g, b = rgb
    value, low = _value_and_low(r, g, b)
    chroma = value - low
    saturation = chroma / clamp(value, _SATURATION_FLOOR)
    safe = clamp(chroma, _SATURATION_FLOOR)
    sector = _first_of_three((g - b) / safe, (b - r) / safe + 2.0, (r - g) / safe + 4.0, (r >= g) & (r >= b), g >= b)
    hue = sector / 6.0
    hue = dr.select(chroma > 0, hue - dr.floor(hue), 0.0)
    hue = hue + shift
    hue = hue - dr.floor(hue)
    out = []
    for phase in (0.0, 2.0 / 3.0, 1.0 / 3.0):
        turned = hue + phase
        ramp = clamp(dr.abs((turned - dr.floor(turned)) * 6.0 - 3.0) - 1.0, 0.0, 1.0)
        out.append(value * (1.0 + saturation * (ramp - 1.0)))
    return out


def adjust_color(image: torch.Tensor, amounts: dict[str, torch.Tensor], white_balance: bool) -> torch.Tensor:
    """:func:`wise.filters.color.adjust_color` with plain clamps, in one pass: ``amounts`` holds the
    maps of brightness, exposure and contrast and of those of temperature, tint, saturation,
    hue_shift and gamma that change the picture (``white_balance``: temperature and tint)."""
    names = list(amounts)

    def planes(rgb, *maps):
        m = {name: planes_[0] for name, planes_ in zip(names, maps)}
        out = [(v + m["brightness"]) * m["exposure"] for v in rgb]
        out = [(v - 0.5) * m["contrast"] + 0.5 for v in out]
        if white_balance:
            temperature, tint = m["temperature"], m["tint"]
            shift = (0.5 * (temperature + tint), -tint, 0.5 * (tint - temperature))
            out = [v + s for v, s in zip(out, shift)]
        out = [clamp(v, 0.0, 1.0) for v in out]
        if "saturation" in m:
            out = _scale_saturation(out, m["saturation"])
        if "hue_shift" in m:
            out = _rotate_hue(out, m["hue_shift"])
        if "gamma" in m:
            exponent = 1.0 / clamp(m["gamma"], _MIN_GAMMA)
            out = [dr.power(clamp(v, _POW_FLOOR), exponent) for v in out]
        return [clamp(v, 0.0, 1.0) for v in out]

    return _pointwise.apply(planes, image, *amounts.values())
