"""Fused procedural noise of :mod:`wise.filters.noise`: value noise, fBm and the paper texture in
one Dr.Jit kernel, each lattice value hashed where a pixel needs it.

The same hash (xor-shift-multiply rounds on 32-bit words, whose wrapping products are the low
32 bits the PyTorch path keeps in int64), the same quintic fade and octave layout, positions in
float64 and the blend in the texture's dtype; the PyTorch module passes its constants in. Not
differentiable, as the textures there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import drjit as dr
import torch
from drjit.llvm import Float64, Int32, UInt32

from wise.filters.fused._drjit import float_type, kernel_threads
from wise.filters.fused._lanes import clamp, divide, runtime


@dataclass(frozen=True)
class Hash:
    """The constants of the lattice hash and of the fBm."""

    mix_a: int
    mix_b: int
    value_bits: int
    lacunarity: float
    octave_turn: float


@dataclass(frozen=True)
class Layer:
    """One fBm: cell sizes (along, across) the direction ``angle``, the hash key of each octave,
    the octaves' weight ratio, and the layer's weight in a mix."""

    cell_along: float
    cell_across: float
    angle: float
    octave_keys: tuple[int, ...]
    persistence: float
    weight: float = 1.0


def _mix(h, constants: Hash):
    h = h ^ (h >> 16)
    h = h * constants.mix_a
    h = h ^ (h >> 15)
    h = h * constants.mix_b
    return h ^ (h >> 16)


def _fade(t):
    return ((t * 6.0 - 15.0) * t + 10.0) * (t * t * t)


def _lattice(u, v, key: int, Float, constants: Hash):
    """Value noise at lattice coordinates ``u``, ``v`` (float64 lanes)."""
    u_floor, v_floor = dr.floor(u), dr.floor(v)
    fade_u, fade_v = _fade(Float(u - u_floor)), _fade(Float(v - v_floor))
    left = dr.reinterpret_array(UInt32, Int32(u_floor))
    top = dr.reinterpret_array(UInt32, Int32(v_floor))
    unit = 2.0**-constants.value_bits
    shift = 32 - constants.value_bits

    key = runtime(UInt32, key)

    def value(column, row):
        h = _mix(_mix(key ^ column, constants) ^ row, constants)
        return Float(h >> shift) * unit

    upper = dr.lerp(value(left, top), value(left + 1, top), fade_u)
    lower = dr.lerp(value(left, top + 1), value(left + 1, top + 1), fade_u)
    return dr.lerp(upper, lower, fade_v)


def _fbm(x, y, layer: Layer, Float, constants: Hash):
    total, weight, weights = None, 1.0, 0.0
    for octave, key in enumerate(layer.octave_keys):
        shrink = constants.lacunarity**octave
        turn = layer.angle + octave * constants.octave_turn
        if turn == 0.0:
            u, v = x * runtime(Float64, shrink / layer.cell_along), y * runtime(Float64, shrink / layer.cell_across)
        else:
            cos, sin = math.cos(turn), math.sin(turn)
            along, across = shrink / layer.cell_along, shrink / layer.cell_across
            u = x * runtime(Float64, cos * along) + y * runtime(Float64, sin * along)
            v = y * runtime(Float64, cos * across) - x * runtime(Float64, sin * across)
        noise = _lattice(u, v, key, Float, constants) * weight
        total = noise if total is None else total + noise
        weights += weight
        weight *= layer.persistence
    return total / weights


def mixed_noise(
    height: int,
    width: int,
    dtype: torch.dtype,
    layers: Sequence[Layer],
    constants: Hash,
    origin: tuple[int, int],
    scale: float,
    contrast: float | None = None,
) -> torch.Tensor:
    """``(H, W)``: the weighted sum of the layers' fBm at the pixel centres in reference pixels,
    ``(origin + index + 0.5) / scale``; where ``contrast`` is given, stretched around 0.5 by it and
    clamped to [0, 1]."""
    Float = float_type(dtype)
    with kernel_threads():
        row, column = divide(dr.arange(UInt32, height * width), width)
        x = (Float64(column) + runtime(Float64, origin[1] + 0.5)) / runtime(Float64, scale)
        y = (Float64(row) + runtime(Float64, origin[0] + 0.5)) / runtime(Float64, scale)
        total = None
        for layer in layers:
            noise = _fbm(x, y, layer, Float, constants) * runtime(Float, layer.weight)
            total = noise if total is None else total + noise
        if contrast is not None:
            total = clamp((total - 0.5) * contrast + 0.5, 0.0, 1.0)
        dr.eval(total)
        return total.torch().view(height, width)
