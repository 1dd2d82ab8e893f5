"""Fused CPU kernel of :func:`wise.filters.shading.bump_phong`: bump mapping (Blinn 1978) lit with
Phong's (1975) model, forward and analytic backward in one loop over pixels.

Per pixel, with the height's central differences ``(h_x, h_y)`` (border replicated, per reference
pixel) and the strength ``k``: ``n = (-k h_x, -k h_y, 1) / |(-k h_x, -k h_y, 1)|``,
``N.L = n . L``, ``R.V = 2 (N.L) n_z - L_z`` and
``out = clamp(C (ambient + diffuse max(N.L, 0)) + specular max(R.V, floor)^shininess, 0, 1)``.
The PyTorch path makes some twenty full-size temporaries in forward and as many in backward.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from numba import njit, prange

from wise.filters.fused import FASTMATH, full, kernel_threads, reduce_to


@njit(inline="always")
def _central_differences(height, b, y, x, rows, columns, half_scale):
    """``(dh/dx, dh/dy)`` of ``height`` ``(B, 1, H, W)`` at ``(y, x)``, border replicated."""
    dx = height[b, 0, y, min(x + 1, columns - 1)] - height[b, 0, y, max(x - 1, 0)]
    dy = height[b, 0, min(y + 1, rows - 1), x] - height[b, 0, max(y - 1, 0), x]
    return dx * half_scale, dy * half_scale


@njit(inline="always")
def _normal(slope_x, slope_y, strength, light_x, light_y, light_z):
    """``(n_x, n_y, n_z, N.L, R.V)`` of the bumped normal; ``n_x``, ``n_y`` before normalization."""
    normal_x = -strength * slope_x
    normal_y = -strength * slope_y
    normal_z = 1.0 / math.sqrt(normal_x * normal_x + normal_y * normal_y + 1.0)
    n_dot_l = (normal_x * light_x + normal_y * light_y + light_z) * normal_z
    return normal_x, normal_y, normal_z, n_dot_l, 2.0 * n_dot_l * normal_z - light_z


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _shade_forward(color, height, strength, ambient, diffuse, specular, shininess, light, half_scale, floor, out):
    """``out`` ``(B, C, H, W)`` from ``color``, ``height`` ``(B, 1, H, W)`` and the five parameter
    maps ``(B, 1, H, W)``; ``light`` is the unit direction towards the light."""
    batch, channels, rows, columns = color.shape
    light_x, light_y, light_z = light[0], light[1], light[2]
    for task in prange(batch * rows):
        b, y = task // rows, task % rows
        for x in range(columns):
            slope_x, slope_y = _central_differences(height, b, y, x, rows, columns, half_scale)
            _, _, _, n_dot_l, r_dot_v = _normal(slope_x, slope_y, strength[b, 0, y, x], light_x, light_y, light_z)
            lighting = ambient[b, 0, y, x] + diffuse[b, 0, y, x] * max(n_dot_l, 0.0)
            highlight = specular[b, 0, y, x] * max(r_dot_v, floor) ** shininess[b, 0, y, x]
            for c in range(channels):
                out[b, c, y, x] = min(max(highlight + color[b, c, y, x] * lighting, 0.0), 1.0)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _shade_backward(
    color,
    height,
    strength,
    ambient,
    diffuse,
    specular,
    shininess,
    light,
    half_scale,
    floor,
    grad,
    g_color,
    g_slopes,
    g_strength,
    g_ambient,
    g_diffuse,
    g_specular,
    g_shininess,
):
    """Gradients of :func:`_shade_forward` for the colour and the parameter maps, and of the
    height's scaled central differences into ``g_slopes`` ``(B, 2, H, W)`` (see :func:`_slopes_adjoint`).
    The clamp passes the gradient where ``0 <= out <= 1``, ``max(N.L, 0)`` where ``N.L >= 0`` and
    ``max(R.V, floor)`` where ``R.V >= floor``, as PyTorch's clamps do."""
    batch, channels, rows, columns = color.shape
    light_x, light_y, light_z = light[0], light[1], light[2]
    for task in prange(batch * rows):
        b, y = task // rows, task % rows
        for x in range(columns):
            slope_x, slope_y = _central_differences(height, b, y, x, rows, columns, half_scale)
            k = strength[b, 0, y, x]
            normal_x, normal_y, normal_z, n_dot_l, r_dot_v = _normal(slope_x, slope_y, k, light_x, light_y, light_z)
            diffuse_weight = diffuse[b, 0, y, x]
            lighting = ambient[b, 0, y, x] + diffuse_weight * max(n_dot_l, 0.0)
            base = max(r_dot_v, floor)
            exponent = shininess[b, 0, y, x]
            log_base = math.log(base)
            power = math.exp(exponent * log_base)  # base^exponent, sharing the logarithm with its gradient
            specular_weight = specular[b, 0, y, x]
            highlight = specular_weight * power
            g_lighting = g_power = 0.0
            for c in range(channels):
                value = color[b, c, y, x]
                shaded = highlight + value * lighting
                g = grad[b, c, y, x] if 0.0 <= shaded <= 1.0 else 0.0
                g_color[b, c, y, x] = g * lighting
                g_lighting += g * value
                g_power += g
            g_specular[b, 0, y, x] = g_power * power
            g_power *= specular_weight
            g_ambient[b, 0, y, x] = g_lighting
            g_diffuse[b, 0, y, x] = g_lighting * max(n_dot_l, 0.0)
            g_shininess[b, 0, y, x] = g_power * power * log_base
            g_n_dot_l = g_lighting * diffuse_weight if n_dot_l >= 0.0 else 0.0
            g_r_dot_v = g_power * exponent * power / base if r_dot_v >= floor else 0.0
            # R.V = 2 (N.L) n_z - L_z and N.L = (n_x L_x + n_y L_y + L_z) n_z
            g_n_dot_l += 2.0 * normal_z * g_r_dot_v
            g_normal_z = 2.0 * n_dot_l * g_r_dot_v + g_n_dot_l * (normal_x * light_x + normal_y * light_y + light_z)
            g_tilt = g_n_dot_l * normal_z
            cubed = normal_z * normal_z * normal_z
            g_normal_x = g_tilt * light_x - g_normal_z * normal_x * cubed
            g_normal_y = g_tilt * light_y - g_normal_z * normal_y * cubed
            g_strength[b, 0, y, x] = -(g_normal_x * slope_x + g_normal_y * slope_y)
            g_slopes[b, 0, y, x] = -g_normal_x * k * half_scale
            g_slopes[b, 1, y, x] = -g_normal_y * k * half_scale


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _slopes_adjoint(g_slopes, g_height):
    """The height's gradient from the gradients ``g_slopes`` ``(B, 2, H, W)`` of its differences
    ``h[x + 1] - h[x - 1]`` (indices clamped): each pixel gathers from the neighbours that read it."""
    batch, _, rows, columns = g_slopes.shape
    for task in prange(batch * rows):
        b, y = task // rows, task % rows
        for x in range(columns):
            total = 0.0
            if x >= 1:
                total += g_slopes[b, 0, y, x - 1]
            if x == columns - 1:
                total += g_slopes[b, 0, y, x]
            if x + 1 < columns:
                total -= g_slopes[b, 0, y, x + 1]
            if x == 0:
                total -= g_slopes[b, 0, y, x]
            if y >= 1:
                total += g_slopes[b, 1, y - 1, x]
            if y == rows - 1:
                total += g_slopes[b, 1, y, x]
            if y + 1 < rows:
                total -= g_slopes[b, 1, y + 1, x]
            if y == 0:
                total -= g_slopes[b, 1, y, x]
            g_height[b, 0, y, x] = total


class BumpPhong(torch.autograd.Function):
    """:func:`wise.filters.shading.bump_phong` on ``color`` ``(B, C, H, W)``, ``height`` and the maps
    ``strength``, ``ambient``, ``diffuse``, ``specular``, ``shininess`` (each broadcasting to
    ``(B, 1, H, W)``), the unit ``light`` direction, ``half_scale`` (half the pixels per reference
    pixel) and the specular base's ``floor``. Gradients reach the colour, the height and the maps."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx,
        color: torch.Tensor,
        height: torch.Tensor,
        strength: torch.Tensor,
        ambient: torch.Tensor,
        diffuse: torch.Tensor,
        specular: torch.Tensor,
        shininess: torch.Tensor,
        light: tuple[float, float, float],
        half_scale: float,
        floor: float,
    ) -> torch.Tensor:
        b, c, h, w = color.shape
        maps = [full(m, (b, 1, h, w)) for m in (height, strength, ambient, diffuse, specular, shininess)]
        pixels = full(color, color.shape)
        out = np.empty_like(pixels)
        light_array = np.asarray(light, dtype=pixels.dtype)
        with kernel_threads():
            _shade_forward(pixels, *maps, light_array, half_scale, floor, out)
        ctx.save_for_backward(color, height, strength, ambient, diffuse, specular, shininess)
        ctx.settings = (light_array, half_scale, floor)
        return torch.from_numpy(out)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        color, *maps = ctx.saved_tensors
        b, c, h, w = color.shape
        pixels = full(color, color.shape)
        g_color = np.empty_like(pixels)
        g_slopes = np.empty((b, 2, h, w), dtype=pixels.dtype)
        g_height = np.empty((b, 1, h, w), dtype=pixels.dtype)
        g_maps = [np.empty((b, 1, h, w), dtype=pixels.dtype) for _ in range(5)]
        with kernel_threads():
            _shade_backward(
                pixels,
                *[full(m, (b, 1, h, w)) for m in maps],
                *ctx.settings,
                full(grad, color.shape),
                g_color,
                g_slopes,
                *g_maps,
            )
            if ctx.needs_input_grad[1]:
                _slopes_adjoint(g_slopes, g_height)
        need = ctx.needs_input_grad
        grads = [
            reduce_to(torch.from_numpy(g), m.shape) if wanted else None
            for g, m, wanted in zip([g_height, *g_maps], maps, need[1:7])
        ]
        return (torch.from_numpy(g_color) if need[0] else None, *grads, None, None, None)
