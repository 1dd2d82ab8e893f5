"""Bump mapping (Blinn 1978) of a height map, lit with Phong (1975) shading."""

from __future__ import annotations

import math

import torch

from wise.errors import WiseError
from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image, resolution_scale

DEFAULT_LIGHT_DIRECTION = (-1.0, -1.0, 1.0)
"""Towards the light, in (x right, y down, z towards the viewer): from the top left."""
DEFAULT_AMBIENT = 0.5
DEFAULT_SPECULAR = 0.2
DEFAULT_SHININESS = 16.0
POW_FLOOR = 1e-8
"""Floor of the specular base, keeping the gradient of ``pow`` w.r.t. shininess finite at 0."""


def _unit_light(light_direction: tuple[float, float, float]) -> tuple[float, float, float]:
    if len(light_direction) != 3:
        raise WiseError(f"light_direction must be an (x, y, z) tuple, got {light_direction!r}")
    length = math.sqrt(sum(float(c) * float(c) for c in light_direction))
    if length == 0.0:
        raise WiseError("light_direction must not be the zero vector")
    x, y, z = (float(c) / length for c in light_direction)
    return x, y, z


def _central_difference(height: torch.Tensor, dim: int) -> torch.Tensor:
    # replicate one border pixel with cat (F.pad's replicate mode is far slower on CPU)
    size = height.shape[dim]
    padded = torch.cat((height.narrow(dim, 0, 1), height, height.narrow(dim, size - 1, 1)), dim=dim)
    return padded.narrow(dim, 2, size) - padded.narrow(dim, 0, size)


def height_gradient(height: torch.Tensor, scale: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Central differences (dh/dx, dh/dy) of ``height`` (B, 1, H, W) per reference pixel.

    The border is replicated, so the outermost pixels use one-sided half differences.
    ``scale`` is pixels per reference pixel.
    """
    half_scale = 0.5 * scale
    return _central_difference(height, 3) * half_scale, _central_difference(height, 2) * half_scale


def _reflection(
    height: torch.Tensor, strength: torch.Tensor, light: tuple[float, float, float], scale: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """``N.L`` and ``R.V`` of the bump-mapped relief of ``height`` under the unit ``light``, seen
    from V = (0, 0, 1)."""
    light_x, light_y, light_z = light
    dh_dx, dh_dy = height_gradient(height, scale)
    normal_x = -strength * dh_dx
    normal_y = -strength * dh_dy
    normal_z = torch.rsqrt(normal_x * normal_x + normal_y * normal_y + 1.0)  # also 1/|(nx, ny, 1)|
    n_dot_l = (normal_x * light_x + normal_y * light_y + light_z) * normal_z
    return n_dot_l, 2.0 * n_dot_l * normal_z - light_z


def bump_phong(
    color: torch.Tensor,
    height: torch.Tensor,
    strength: ParamLike = 1.0,
    light_direction: tuple[float, float, float] = DEFAULT_LIGHT_DIRECTION,
    ambient: ParamLike = DEFAULT_AMBIENT,
    diffuse: ParamLike | None = None,
    specular: ParamLike = DEFAULT_SPECULAR,
    shininess: ParamLike = DEFAULT_SHININESS,
    scale: float | None = None,
) -> torch.Tensor:
    """Shade ``color`` by the relief of ``height`` with Phong's (1975) model.

    Normals are N = normalize(-strength dh/dx, -strength dh/dy, 1) with the height's
    central differences taken per pixel of a 512-pixel short side (so ``strength`` means
    the same at every resolution). With L the unit ``light_direction``, V = (0, 0, 1) and
    R = 2 (N.L) N - L the reflected light,

        out = clamp(color (ambient + diffuse max(N.L, 0)) + specular max(R.V, 0)^shininess, 0, 1)

    so highlights are white. The clamps keep finite (zero) gradients where they cut.

    Args:
        color: ``(B, C, H, W)`` in [0, 1].
        height: ``(B, 1, H, W)`` height map (in units of colour values; a batch of 1
            broadcasts).
        strength, ambient, diffuse, specular, shininess: floats, ``(B,)`` tensors or
            ``(B, 1, H, W)`` maps; all differentiable. ``diffuse`` defaults to
            ``(1 - ambient) / L_z``, which keeps the colour of a flat area under any light.
        light_direction: fixed (x, y, z) towards the light, x right, y down (image rows),
            z towards the viewer; need not be unit length. Default: from the top left.
        scale: pixels per reference pixel; defaults to ``min(H, W) / 512``.

    Returns:
        ``(B, C, H, W)`` in [0, 1].
    """
    check_image(color, "color")
    check_image(height, "height", channels=1)
    if height.shape[-2:] != color.shape[-2:] or height.shape[0] not in (1, color.shape[0]):
        raise WiseError(f"height {tuple(height.shape)} must be a (B, 1, H, W) map matching color {tuple(color.shape)}")
    light_x, light_y, light_z = _unit_light(light_direction)
    pixels_per_reference = resolution_scale(color) if scale is None else scale
    strength_map = as_map(strength, color, "strength")
    ambient_map = as_map(ambient, color, "ambient")
    diffuse_map = (1.0 - ambient_map) / light_z if diffuse is None else as_map(diffuse, color, "diffuse")
    maps = [ambient_map, diffuse_map, as_map(specular, color, "specular")]
    shininess_map = as_map(shininess, color, "shininess")
    if fused.enabled(color, height, strength_map, shininess_map, *maps):
        from wise.filters.fused.shading import BumpPhong

        light = (light_x, light_y, light_z)
        half_scale = 0.5 * pixels_per_reference
        return BumpPhong.apply(color, height, strength_map, *maps, shininess_map, light, half_scale, POW_FLOOR)
    ambient_map, diffuse_map, specular_map = maps
    n_dot_l, r_dot_v = _reflection(height, strength_map, (light_x, light_y, light_z), pixels_per_reference)
    lighting = ambient_map + diffuse_map * n_dot_l.clamp_min(0.0)
    highlight = r_dot_v.clamp_min(POW_FLOOR) ** shininess_map
    shaded = torch.addcmul(specular_map * highlight, color, lighting)
    return shaded.clamp(0.0, 1.0)


def phong_highlight(
    height: torch.Tensor,
    strength: ParamLike = 1.0,
    light_direction: tuple[float, float, float] = DEFAULT_LIGHT_DIRECTION,
    shininess: ParamLike = DEFAULT_SHININESS,
    scale: float | None = None,
) -> torch.Tensor:
    """Phong's (1975) highlight ``max(R.V, 0)^shininess`` of the relief of ``height`` ``(B, 1, H, W)``,
    ``(B, 1, H, W)`` in [0, 1]: the specular term of :func:`bump_phong` alone, with the same
    normals, light and viewer, for a highlight that follows another relief than the shading."""
    check_image(height, "height", channels=1)
    pixels_per_reference = resolution_scale(height) if scale is None else scale
    strength_map = as_map(strength, height, "strength")
    _, r_dot_v = _reflection(height, strength_map, _unit_light(light_direction), pixels_per_reference)
    return r_dot_v.clamp_min(POW_FLOOR) ** as_map(shininess, height, "shininess")
