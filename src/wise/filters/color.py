"""Colour space conversions and colour adjustment."""

from __future__ import annotations

import functools

import torch

from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image
from wise.filters.clamp import inward_clamp, inward_gradients_active

# sRGB (IEC 61966-2-1) transfer function
_SRGB_LINEAR_LIMIT = 0.04045
_SRGB_ENCODED_LIMIT = 0.0031308
# CIE 1976 L*a*b* with the D65 white point
_D65_WHITE = (0.95047, 1.0, 1.08883)
_LAB_EPSILON = 216.0 / 24389.0
_LAB_KAPPA = 24389.0 / 27.0
_RGB_TO_XYZ = (
    (0.4124564, 0.3575761, 0.1804375),
    (0.2126729, 0.7151522, 0.0721750),
    (0.0193339, 0.1191920, 0.9503041),
)
# tiny floor keeping pow()'s gradient finite at zero
_POW_FLOOR = 1e-8


@functools.cache
def _fused_constants():
    from wise.filters.fused.color import Constants

    inverse = torch.linalg.inv(torch.tensor(_RGB_TO_XYZ, dtype=torch.float64))
    return Constants(
        _SRGB_LINEAR_LIMIT,
        _SRGB_ENCODED_LIMIT,
        _D65_WHITE,
        _LAB_EPSILON,
        _LAB_KAPPA,
        _RGB_TO_XYZ,
        tuple(tuple(float(v) for v in row) for row in inverse),
    )


def _matrix(rows: tuple[tuple[float, ...], ...], ref: torch.Tensor) -> torch.Tensor:
    return torch.tensor(rows, dtype=ref.dtype, device=ref.device)


def _apply_matrix(image: torch.Tensor, matrix: torch.Tensor) -> torch.Tensor:
    return torch.einsum("ij,bjhw->bihw", matrix, image)


def srgb_to_linear(image: torch.Tensor) -> torch.Tensor:
    """sRGB-encoded values in [0, 1] to linear light (IEC 61966-2-1)."""
    if fused.enabled(image):
        from wise.filters.fused import color

        return color.srgb_to_linear(image, _fused_constants())
    high = ((image.clamp_min(_SRGB_LINEAR_LIMIT) + 0.055) / 1.055) ** 2.4
    return torch.where(image > _SRGB_LINEAR_LIMIT, high, image / 12.92)


def linear_to_srgb(image: torch.Tensor) -> torch.Tensor:
    """Linear light to sRGB encoding (IEC 61966-2-1)."""
    if fused.enabled(image):
        from wise.filters.fused import color

        return color.linear_to_srgb(image, _fused_constants())
    high = 1.055 * image.clamp_min(_SRGB_ENCODED_LIMIT) ** (1.0 / 2.4) - 0.055
    return torch.where(image > _SRGB_ENCODED_LIMIT, high, image * 12.92)


def rgb_to_lab(image: torch.Tensor) -> torch.Tensor:
    """sRGB in [0, 1] to CIE L*a*b* (D65): L in [0, 100], a and b roughly in [-128, 127].

    Args:
        image: ``(B, 3, H, W)`` sRGB image.

    Returns:
        ``(B, 3, H, W)`` L*a*b* image.
    """
    check_image(image, channels=3)
    if fused.enabled(image):
        from wise.filters.fused import color

        return color.rgb_to_lab(image, _fused_constants())
    xyz = _apply_matrix(srgb_to_linear(image), _matrix(_RGB_TO_XYZ, image))
    white = image.new_tensor(_D65_WHITE).view(1, 3, 1, 1)
    ratio = xyz / white
    f = torch.where(
        ratio > _LAB_EPSILON,
        ratio.clamp_min(_LAB_EPSILON) ** (1.0 / 3.0),
        (_LAB_KAPPA * ratio + 16.0) / 116.0,
    )
    fx, fy, fz = f.unbind(dim=1)
    return torch.stack((116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)), dim=1)


def lab_to_rgb(lab: torch.Tensor, clip: bool = True) -> torch.Tensor:
    """CIE L*a*b* (D65) to sRGB; the inverse of :func:`rgb_to_lab`.

    Args:
        lab: ``(B, 3, H, W)`` with L in [0, 100].
        clip: clamp the result to [0, 1] (colours outside the sRGB gamut).
    """
    check_image(lab, name="lab", channels=3)
    if fused.enabled(lab):
        from wise.filters.fused import color

        return color.lab_to_rgb(lab, _fused_constants(), clip)
    lightness, a, b = lab.unbind(dim=1)
    fy = (lightness + 16.0) / 116.0
    f = torch.stack((fy + a / 500.0, fy, fy - b / 200.0), dim=1)
    cube = f**3
    ratio = torch.where(cube > _LAB_EPSILON, cube, (116.0 * f - 16.0) / _LAB_KAPPA)
    white = lab.new_tensor(_D65_WHITE).view(1, 3, 1, 1)
    xyz_to_rgb = torch.linalg.inv(_matrix(_RGB_TO_XYZ, lab).double()).to(lab.dtype)
    rgb = linear_to_srgb(_apply_matrix(ratio * white, xyz_to_rgb))
    return rgb.clamp(0.0, 1.0) if clip else rgb


def rgb_to_hsv(image: torch.Tensor) -> torch.Tensor:
    """RGB in [0, 1] to HSV with hue in [0, 1) (Smith 1978). ``(B, 3, H, W)`` both."""
    check_image(image, channels=3)
    value, argmax = image.max(dim=1)
    chroma = value - image.min(dim=1).values
    saturation = chroma / value.clamp_min(1e-8)
    safe_chroma = chroma.clamp_min(1e-8)
    r, g, b = image.unbind(dim=1)
    sector = torch.stack(((g - b) / safe_chroma, (b - r) / safe_chroma + 2.0, (r - g) / safe_chroma + 4.0), dim=1)
    hue = torch.gather(sector, 1, argmax.unsqueeze(1)).squeeze(1) / 6.0
    hue = torch.where(chroma > 0, torch.remainder(hue, 1.0), torch.zeros_like(hue))
    return torch.stack((hue, saturation, value), dim=1)


def hsv_to_rgb(hsv: torch.Tensor) -> torch.Tensor:
    """HSV (hue in [0, 1)) to RGB; the inverse of :func:`rgb_to_hsv`."""
    check_image(hsv, name="hsv", channels=3)
    hue, saturation, value = hsv[:, 0:1], hsv[:, 1:2], hsv[:, 2:3]
    phase = hsv.new_tensor([0.0, 2.0 / 3.0, 1.0 / 3.0]).view(1, 3, 1, 1)
    ramp = (torch.remainder(hue + phase, 1.0) * 6.0 - 3.0).abs() - 1.0
    return value * torch.lerp(torch.ones_like(ramp), ramp.clamp(0.0, 1.0), saturation)


def _scale_saturation(image: torch.Tensor, factor: torch.Tensor) -> torch.Tensor:
    # HSV keeps hue and value while saturation S scales the distance to the value V:
    # rgb = V - S * V * f(hue), so multiplying S by k is V - k (V - rgb), with k*S capped at 1.
    value = image.max(dim=1, keepdim=True).values
    chroma = value - image.min(dim=1, keepdim=True).values
    limit = value / chroma.clamp_min(1e-8)
    k = torch.where(chroma > 1e-8, torch.minimum(factor.clamp_min(0.0), limit), factor.clamp_min(0.0))
    return value - k * (value - image)


def _is_number(value: ParamLike, number: float) -> bool:
    return isinstance(value, (int, float)) and value == number


def _white_balance_shift(temperature: torch.Tensor, tint: torch.Tensor) -> torch.Tensor:
    """RGB offsets (B, 3, H, W) of a white-balance change: warm/cool and magenta/green."""
    red = 0.5 * (temperature + tint)
    green = -tint
    blue = 0.5 * (tint - temperature)
    return torch.cat(torch.broadcast_tensors(red, green, blue), dim=1)


def adjust_color(
    image: torch.Tensor,
    brightness: ParamLike = 0.0,
    contrast: ParamLike = 1.0,
    saturation: ParamLike = 1.0,
    gamma: ParamLike = 1.0,
    exposure: ParamLike = 1.0,
    hue_shift: ParamLike = 0.0,
    temperature: ParamLike = 0.0,
    tint: ParamLike = 0.0,
) -> torch.Tensor:
    """Colour adjustment as in the WISE cartoon/XDoG pipelines (Lötzsch et al. 2022, Fig. 3).

    In order: add ``brightness``, multiply by ``exposure``, scale ``contrast`` around
    mid-grey, shift the white balance by ``temperature`` (red up and blue down by half of it)
    and ``tint`` (green down by it, red and blue up by half of it), clamp to [0, 1] (an
    :func:`~wise.filters.clamp.inward_clamp`: within
    :func:`~wise.filters.clamp.inward_gradients` saturated pixels keep a gradient back), scale the
    HSV ``saturation``, rotate the hue by ``hue_shift`` (in turns), and apply ``gamma``
    (``x ** (1 / gamma)``). Brightness, temperature and tint are orthogonal RGB offsets: as
    masks they can set any colour per pixel.

    Args:
        image: ``(B, 3, H, W)`` RGB in [0, 1].
        brightness, contrast, saturation, gamma, exposure, hue_shift, temperature, tint: floats,
            ``(B,)`` tensors or ``(B, 1, H, W)`` maps.

    Returns:
        ``(B, 3, H, W)`` RGB in [0, 1].
    """
    check_image(image, channels=3)
    if fused.enabled(image) and not (torch.is_grad_enabled() and inward_gradients_active()):
        return _fused_adjust_color(
            image, brightness, contrast, saturation, gamma, exposure, hue_shift, temperature, tint
        )
    out = (image + as_map(brightness, image, "brightness")) * as_map(exposure, image, "exposure")
    out = (out - 0.5) * as_map(contrast, image, "contrast") + 0.5
    if not (_is_number(temperature, 0.0) and _is_number(tint, 0.0)):
        out = out + _white_balance_shift(as_map(temperature, image, "temperature"), as_map(tint, image, "tint"))
    out = inward_clamp(out)
    if not _is_number(saturation, 1.0):
        out = _scale_saturation(out, as_map(saturation, image, "saturation"))
    if not _is_number(hue_shift, 0.0):
        hsv = rgb_to_hsv(out)
        hue = torch.remainder(hsv[:, 0:1] + as_map(hue_shift, image, "hue_shift"), 1.0)
        out = hsv_to_rgb(torch.cat((hue, hsv[:, 1:]), dim=1))
    if not _is_number(gamma, 1.0):
        out = out.clamp_min(_POW_FLOOR) ** (1.0 / as_map(gamma, image, "gamma").clamp_min(0.1))
    return inward_clamp(out)


def _fused_adjust_color(
    image: torch.Tensor,
    brightness: ParamLike,
    contrast: ParamLike,
    saturation: ParamLike,
    gamma: ParamLike,
    exposure: ParamLike,
    hue_shift: ParamLike,
    temperature: ParamLike,
    tint: ParamLike,
) -> torch.Tensor:
    """:func:`adjust_color` as one Dr.Jit kernel (its clamps plain: no inward gradients asked)."""
    from wise.filters.fused import color

    amounts = {"brightness": brightness, "exposure": exposure, "contrast": contrast}
    white_balance = not (_is_number(temperature, 0.0) and _is_number(tint, 0.0))
    if white_balance:
        amounts.update(temperature=temperature, tint=tint)
    for name, value, neutral in (("saturation", saturation, 1.0), ("hue_shift", hue_shift, 0.0), ("gamma", gamma, 1.0)):
        if not _is_number(value, neutral):
            amounts[name] = value
    maps = {name: as_map(value, image, name) for name, value in amounts.items()}
    return color.adjust_color(image, maps, white_balance)
