"""Fused kernel of :func:`wise.filters.shading.bump_phong`: bump mapping (Blinn 1978) lit with
Phong's (1975) model, forward and analytic backward, in Dr.Jit.

Per pixel, with the height's central differences ``(h_x, h_y)`` (border replicated, per reference
pixel) and the strength ``k``: ``n = (-k h_x, -k h_y, 1) / |(-k h_x, -k h_y, 1)|``,
``N.L = n . L``, ``R.V = 2 (N.L) n_z - L_z`` and
``out = clamp(C (ambient + diffuse max(N.L, 0)) + specular max(R.V, floor)^shininess, 0, 1)``.
The PyTorch path makes some twenty full-size temporaries in forward and as many in backward; here
one kernel computes it with a lane per pixel. Backward takes a second kernel for the height's
gradient: each pixel gathers the gradients of the differences that read it.
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import torch

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import flat, float_type, kernel_threads, to_torch
from wise.filters.fused._lanes import Grid, maximum, minimum, runtime


@dataclass
class _Shading:
    """A pixel's colour, parameters, scaled height slopes, bumped normal and its dot products."""

    grid: Grid
    color: list
    strength: object
    ambient: object
    diffuse: object
    specular: object
    shininess: object
    light: tuple
    slope_x: object
    slope_y: object
    normal_x: object
    normal_y: object
    normal_z: object
    n_dot_l: object
    r_dot_v: object

    @classmethod
    def of(cls, color, height, strength, ambient, diffuse, specular, shininess, light, half_scale) -> "_Shading":
        b, c, h, w = color.shape
        Float = float_type(color.dtype)
        grid = Grid(b, h, w, Float)
        heights = flat(height.to(color.dtype), Float)
        row, column, width = grid.row, grid.column, grid.runtime_width
        half_scale = runtime(Float, half_scale)
        picture = grid.picture * grid.runtime_plane if height.shape[0] > 1 else 0  # a height of batch 1 is shared
        in_row, in_column = picture + row * width, picture + column
        left, right = dr.select(column > 0, column - 1, 0), dr.minimum(column + 1, width - 1)
        up, down = dr.select(row > 0, row - 1, 0), dr.minimum(row + 1, grid.runtime_height - 1)
        slope_x = (dr.gather(Float, heights, in_row + right) - dr.gather(Float, heights, in_row + left)) * half_scale
        slope_y = dr.gather(Float, heights, in_column + down * width) - dr.gather(
            Float, heights, in_column + up * width
        )
        slope_y = slope_y * half_scale
        k = grid.load_broadcast(strength)
        light_x, light_y, light_z = (runtime(Float, value) for value in light)
        normal_x = -k * slope_x
        normal_y = -k * slope_y
        normal_z = 1.0 / dr.sqrt(normal_x * normal_x + normal_y * normal_y + 1.0)
        n_dot_l = (normal_x * light_x + normal_y * light_y + light_z) * normal_z
        pixels = flat(color, Float)
        return cls(
            grid,
            [grid.load(pixels, channel, c) for channel in range(c)],
            k,
            *[grid.load_broadcast(m) for m in (ambient, diffuse, specular, shininess)],
            (light_x, light_y, light_z),
            slope_x,
            slope_y,
            normal_x,
            normal_y,
            normal_z,
            n_dot_l,
            2.0 * n_dot_l * normal_z - light_z,
        )


def _shade_forward(shading: _Shading, floor: float) -> list:
    """The shaded channels, evaluated in one kernel."""
    lighting = shading.ambient + shading.diffuse * maximum(shading.n_dot_l, 0.0)
    base = maximum(shading.r_dot_v, floor)
    highlight = shading.specular * dr.exp(shading.shininess * dr.log(base))
    out = [minimum(maximum(dr.fma(value, lighting, highlight), 0.0), 1.0) for value in shading.color]
    dr.eval(*out)
    return out


def _shade_backward(shading: _Shading, half_scale: float, floor: float, grad: list, need: tuple) -> list:
    """Gradients of :func:`_shade_forward`: ``[*g_color, g_strength, g_ambient, g_diffuse,
    g_specular, g_shininess, g_slope_x, g_slope_y]`` per lane (``None`` where ``need`` has no use
    for them), those of the height's differences ``h[x + 1] - h[x - 1]`` last. The clamp passes the
    gradient where ``0 <= out <= 1``, ``max(N.L, 0)`` where ``N.L >= 0`` and ``max(R.V, floor)``
    where ``R.V >= floor``, as PyTorch's clamps do. All that is needed is evaluated in one kernel."""
    Float = shading.grid.Float
    light_x, light_y, light_z = shading.light
    n_dot_l, r_dot_v = shading.n_dot_l, shading.r_dot_v
    normal_x, normal_y, normal_z = shading.normal_x, shading.normal_y, shading.normal_z
    diffuse_term = maximum(n_dot_l, 0.0)
    lighting = shading.ambient + shading.diffuse * diffuse_term
    base = maximum(r_dot_v, floor)
    log_base = dr.log(base)
    power = dr.exp(shading.shininess * log_base)  # base^shininess, sharing the logarithm with its gradient
    highlight = shading.specular * power
    g_color, g_lighting, g_power = [], Float(0.0), Float(0.0)
    for value, g in zip(shading.color, grad):
        shaded = dr.fma(value, lighting, highlight)
        g = dr.select((shaded >= 0.0) & (shaded <= 1.0), g, 0.0)
        g_color.append(g * lighting)
        g_lighting = dr.fma(g, value, g_lighting)
        g_power += g
    g_specular = g_power * power
    g_power = g_power * shading.specular
    g_shininess = g_power * power * log_base
    g_n_dot_l = dr.select(n_dot_l >= 0.0, g_lighting * shading.diffuse, 0.0)
    g_r_dot_v = dr.select(r_dot_v >= floor, g_power * shading.shininess * power / base, 0.0)
    # R.V = 2 (N.L) n_z - L_z and N.L = (n_x L_x + n_y L_y + L_z) n_z
    g_n_dot_l = dr.fma(2.0 * normal_z, g_r_dot_v, g_n_dot_l)
    tilt = normal_x * light_x + normal_y * light_y + light_z
    g_normal_z = 2.0 * n_dot_l * g_r_dot_v + g_n_dot_l * tilt
    g_tilt = g_n_dot_l * normal_z
    cubed = normal_z * normal_z * normal_z
    g_normal_x = g_tilt * light_x - g_normal_z * normal_x * cubed
    g_normal_y = g_tilt * light_y - g_normal_z * normal_y * cubed
    g_strength = -(g_normal_x * shading.slope_x + g_normal_y * shading.slope_y)
    g_slopes = [-g_normal_x * shading.strength * half_scale, -g_normal_y * shading.strength * half_scale]
    outputs = [*g_color, g_strength, g_lighting, g_lighting * diffuse_term, g_specular, g_shininess, *g_slopes]
    wanted = [need[0]] * len(g_color) + list(need[2:7]) + [need[1]] * 2
    outputs = [o if w else None for o, w in zip(outputs, wanted)]
    dr.eval(*[o for o in outputs if o is not None])
    return outputs


def _slopes_adjoint(grid: Grid, g_slope_x, g_slope_y):
    """The height's gradient from the (evaluated) gradients of its differences ``h[x + 1] - h[x - 1]``
    and ``h[y + 1] - h[y - 1]`` (indices clamped): each pixel gathers from the neighbours that read it."""
    Float, w, h = grid.Float, grid.runtime_width, grid.runtime_height
    row, column = grid.row, grid.column
    index = dr.arange(type(grid.pixel), grid.lanes)

    def at(g, offset, ahead: bool, active):
        moved = index + offset if ahead else index - offset
        return dr.gather(Float, g, dr.select(active, moved, index), active)

    first_x, last_x = column == 0, column == w - 1
    first_y, last_y = row == 0, row == h - 1
    own_x, own_y = g_slope_x, g_slope_y  # the lane's own pixel
    total = at(g_slope_x, 1, False, ~first_x) - at(g_slope_x, 1, True, ~last_x)
    total += dr.select(last_x, own_x, 0.0) - dr.select(first_x, own_x, 0.0)
    total += at(g_slope_y, w, False, ~first_y) - at(g_slope_y, w, True, ~last_y)
    total += dr.select(last_y, own_y, 0.0) - dr.select(first_y, own_y, 0.0)
    dr.eval(total)
    return total


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
        inputs = (color, height, strength, ambient, diffuse, specular, shininess)
        with kernel_threads():
            out = _shade_forward(_Shading.of(*inputs, light, half_scale), floor)
            result = to_torch(out, (b, h, w))
        ctx.save_for_backward(*inputs)
        ctx.settings = (light, half_scale, floor)
        return result

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        color, *maps = ctx.saved_tensors
        light, half_scale, floor = ctx.settings
        b, c, h, w = color.shape
        need = ctx.needs_input_grad
        with kernel_threads():
            shading = _Shading.of(color, *maps, light, half_scale)
            grid = shading.grid
            grads = flat(grad.to(color.dtype), grid.Float, color.shape)
            per_channel = [grid.load(grads, channel, c) for channel in range(c)]
            outputs = _shade_backward(shading, half_scale, floor, per_channel, need)
            g_color = to_torch(outputs[:c], (b, h, w)) if need[0] else None
            *g_maps, g_slope_x, g_slope_y = outputs[c:]
            if need[1]:
                g_maps.insert(0, _slopes_adjoint(grid, g_slope_x, g_slope_y))
            else:
                g_maps.insert(0, None)
            g_maps = [to_torch([g], (b, h, w)) if g is not None else None for g in g_maps]
        grads = [reduce_to(g, m.shape) if wanted else None for g, m, wanted in zip(g_maps, maps, need[1:7])]
        return (g_color, *grads, None, None, None)
