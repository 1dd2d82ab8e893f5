"""Seeded procedural noise and a watercolor-paper texture, consistent across tiles and resolutions.

Everything here is computed, never loaded: value noise whose lattice values come from an
integer hash of the lattice coordinates and a seed (torch integer ops on the tensor's
device; no random-number-generator state). The value at a pixel depends only on its
position in reference pixels, ``(origin + index + 0.5) / scale`` (the pixel centre), on
the seed and on the parameters, so

* the same call gives the same values on every run (and, up to rounding, on every device),
* tiles of a large image rendered separately with their ``origin`` (and the large image's
  ``scale``, since the default comes from the tile's own size) join seamlessly,
* at twice the resolution (``scale`` doubled) the texture is the same pattern, sampled finer,
* a texture asked for again (the next frame of a video, the next preview in the editor, the
  next picture of a batch at the same size) is a copy of the one made before.

These textures are inputs to the filters: they are not differentiable with respect to
their arguments (they carry no gradient).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Callable

import torch

from wise.errors import WiseError
from wise.filters import fused
from wise.filters._checks import check_image, resolution_scale

_MASK_32 = 0xFFFFFFFF
# Odd multipliers below 2**31: a 32-bit value times one of them stays below 2**63, so the
# products never overflow int64 and the low 32 bits are exact.
_MIX_A = 0x7FEB352D
_MIX_B = 0x5BD1E995
_SEED_STRIDE = 0x61C88647
_VALUE_BITS = 24
"""Bits of the hash used for a lattice value: exactly representable in float32."""

LACUNARITY = 2.0
"""Each fBm octave halves the cell size."""
OCTAVE_TURN = math.pi * (3.0 - math.sqrt(5.0))
"""Rotation between successive octaves (the golden angle), against grid artefacts."""


def _mix(h: torch.Tensor) -> torch.Tensor:
    """Avalanche a 32-bit value held in int64 (xor-shift-multiply rounds)."""
    h = h ^ (h >> 16)
    h = (h * _MIX_A) & _MASK_32
    h = h ^ (h >> 15)
    h = (h * _MIX_B) & _MASK_32
    return h ^ (h >> 16)


def _layer_key(seed: int, layer: int) -> int:
    """A 32-bit key per (seed, layer) pair so that octaves and layers are independent."""
    return (seed * _SEED_STRIDE + layer * _MIX_B + layer) & _MASK_32


def _lattice_values(us: torch.Tensor, vs: torch.Tensor, key: int, dtype: torch.dtype) -> torch.Tensor:
    """Values in [0, 1) at the integer lattice points ``vs x us``: ``(len(vs), len(us))``."""
    h = _mix(torch.full_like(us, key) ^ (us & _MASK_32))
    h = _mix(h.view(1, -1) ^ (vs.view(-1, 1) & _MASK_32))
    return (h >> (32 - _VALUE_BITS)).to(dtype) * (2.0**-_VALUE_BITS)


def _fade(t: torch.Tensor) -> torch.Tensor:
    """Quintic smoothstep ``6t^5 - 15t^4 + 10t^3``: continuous first and second derivatives."""
    return (t * 6.0 - 15.0).mul_(t).add_(10.0).mul_(t * t * t)


def _interpolate_lattice(u: torch.Tensor, v: torch.Tensor, key: int, dtype: torch.dtype) -> torch.Tensor:
    """Value noise at lattice coordinates ``u`` and ``v`` (float64, broadcastable to ``(H, W)``).

    The lattice values are hashed once on the bounding box of the needed lattice points and
    gathered per pixel, so the cost per pixel is four gathers and three blends.
    """
    u_floor, v_floor = torch.floor(u), torch.floor(v)
    fade_u = _fade((u - u_floor).to(dtype))
    fade_v = _fade((v - v_floor).to(dtype))
    iu, iv = u_floor.long(), v_floor.long()
    u_min, u_max = (int(e) for e in torch.aminmax(iu))
    v_min, v_max = (int(e) for e in torch.aminmax(iv))
    device = u.device
    lattice = _lattice_values(
        torch.arange(u_min, u_max + 2, device=device), torch.arange(v_min, v_max + 2, device=device), key, dtype
    ).reshape(-1)
    row_length = u_max - u_min + 2
    top_left = torch.add(iu, iv, alpha=row_length).sub_(v_min * row_length + u_min)
    top = torch.lerp(lattice[top_left], lattice[top_left + 1], fade_u)
    top_left += row_length
    bottom = torch.lerp(lattice[top_left], lattice[top_left + 1], fade_u)
    return top.lerp_(bottom, fade_v)


def _reference_positions(
    like: torch.Tensor, origin: tuple[int, int], scale: float | None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Pixel-centre positions in reference pixels, float64: rows ``(H, 1)`` and columns ``(1, W)``."""
    s = resolution_scale(like) if scale is None else float(scale)
    if not s > 0.0:
        raise WiseError(f"scale must be positive, got {s}")
    oy, ox = (int(o) for o in origin)
    h, w = like.shape[-2:]
    ys = (torch.arange(h, dtype=torch.float64, device=like.device) + (oy + 0.5)) / s
    xs = (torch.arange(w, dtype=torch.float64, device=like.device) + (ox + 0.5)) / s
    return ys.view(-1, 1), xs.view(1, -1)


def _check_positive(value: float, name: str) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise WiseError(f"{name} must be a positive number, got {value!r}")


def _fbm(
    ys: torch.Tensor,
    xs: torch.Tensor,
    cells: tuple[float, float],
    angle: float,
    key: int,
    octaves: int,
    persistence: float,
    dtype: torch.dtype,
) -> torch.Tensor:
    """Fractal sum of value noise, normalized to [0, 1]; cells may be stretched and rotated.

    ``cells`` are the cell sizes (along, across) the direction ``angle`` (radians from the
    x axis towards y). Octave ``o`` is turned by a further ``o`` times the golden angle so
    that the lattices of the octaves do not line up into a visible grid.
    """
    cell_along, cell_across = cells
    total: torch.Tensor | None = None
    weight, weights = 1.0, 0.0
    for octave in range(octaves):
        shrink = LACUNARITY**octave
        turn = angle + octave * OCTAVE_TURN
        if turn == 0.0:
            u, v = xs * (shrink / cell_along), ys * (shrink / cell_across)
        else:
            cos, sin = math.cos(turn), math.sin(turn)
            u = (xs * (cos * shrink / cell_along)).add(ys * (sin * shrink / cell_along))
            v = (ys * (cos * shrink / cell_across)).sub(xs * (sin * shrink / cell_across))
        layer = _interpolate_lattice(u, v, _layer_key(key, octave + 1), dtype)
        total = layer.mul_(weight) if total is None else total.add_(layer, alpha=weight)
        weights += weight
        weight *= persistence
    assert total is not None
    return total.div_(weights)


REMEMBERED_TEXTURES = 8
"""Textures kept for the next call with the same arguments at the same size."""
REMEMBERED_MAX_PIXELS = 1 << 21
"""Larger textures are made each time (tiles of a large picture each have their own)."""
_remembered: OrderedDict[tuple, torch.Tensor] = OrderedDict()
_remembered_lock = threading.Lock()


def _texture(like: torch.Tensor, arguments: tuple, make: Callable[[], torch.Tensor]) -> torch.Tensor:
    """``make()``'s ``(H, W)`` texture as ``(B, 1, H, W)``, made once per size, device, dtype,
    path and ``arguments`` among the last :data:`REMEMBERED_TEXTURES`; each caller gets its own copy."""
    height, width = like.shape[-2:]
    if height * width > REMEMBERED_MAX_PIXELS:
        return _as_batch(make(), like)
    key = (*arguments, height, width, like.dtype, like.device, fused.enabled(like))
    with _remembered_lock:
        texture = _remembered.get(key)
        if texture is not None:
            _remembered.move_to_end(key)
    if texture is None:
        texture = make().view(1, 1, height, width)
        with _remembered_lock:
            _remembered[key] = texture
            while len(_remembered) > REMEMBERED_TEXTURES:
                _remembered.popitem(last=False)
    return texture.expand(like.shape[0], 1, -1, -1).clone()


def value_noise(
    like: torch.Tensor,
    cell_size: float,
    seed: int = 0,
    octaves: int = 1,
    persistence: float = 0.5,
    origin: tuple[int, int] = (0, 0),
    scale: float | None = None,
) -> torch.Tensor:
    """Seeded value noise (fractal Brownian motion for ``octaves > 1``).

    Lattice values are an integer hash of the lattice coordinates and the seed, blended
    with a quintic fade (Perlin 2002) between the four surrounding lattice points. Octave
    ``o`` has cells ``cell_size / 2**o``, turned by ``o`` golden angles, and weight
    ``persistence**o``; the sum is divided
    by the total weight, so values stay in [0, 1] with mean 0.5. Not differentiable.

    Args:
        like: any ``(B, C, H, W)`` tensor; gives the batch, size, device and dtype.
        cell_size: lattice spacing of the first octave, in pixels of a 512-pixel short side.
        seed: any integer; different seeds give independent noise.
        octaves: number of fBm octaves (at least 1).
        persistence: weight ratio between successive octaves.
        origin: (y, x) pixel position of this image's top-left corner in a larger image
            (pass that image's ``scale`` too when rendering tiles).
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, 1, H, W)`` in [0, 1], identical for every batch element.
    """
    check_image(like, name="like")
    _check_positive(cell_size, "cell_size")
    if octaves < 1:
        raise WiseError(f"octaves must be at least 1, got {octaves}")
    key = _layer_key(int(seed), 0)

    def make() -> torch.Tensor:
        if fused.enabled(like):
            layer = _fused_layer((cell_size, cell_size), 0.0, key, octaves, persistence)
            return _fused_noise(like, [layer], origin, scale)
        ys, xs = _reference_positions(like, origin, scale)
        return _fbm(ys, xs, (cell_size, cell_size), 0.0, key, octaves, persistence, like.dtype)

    arguments = ("value", float(cell_size), key, int(octaves), float(persistence), *_place(like, origin, scale))
    return _texture(like, arguments, make)


@dataclass(frozen=True)
class _PaperLayer:
    """One noise layer of the paper texture; cell sizes are multiples of the grain."""

    cell_along: float
    cell_across: float
    angle: float
    weight: float
    octaves: int = 1


PAPER_GRAIN = 3.0
"""Default grain of the paper: the cell size of its main grain layer, in reference pixels."""

_PAPER_LAYERS = (
    _PaperLayer(4.0, 4.0, 0.3, 0.35, octaves=2),  # the broad bumps of cold-pressed paper
    _PaperLayer(1.0, 1.0, 1.1, 0.35),  # the grain
    _PaperLayer(0.45, 0.45, 0.7, 0.15),  # the fine tooth of the surface
    _PaperLayer(6.0, 0.5, 0.45, 0.075),  # faint fibres, stretched along two directions
    _PaperLayer(6.0, 0.5, 2.1, 0.075),
)
PAPER_PERSISTENCE = 0.5
"""Weight ratio between the octaves of a paper layer."""
_PAPER_CONTRAST = 2.0
"""Gain around 0.5 applied to the mixed layers, whose averaging flattens the contrast."""


def paper_texture(
    like: torch.Tensor,
    seed: int = 0,
    grain: float = PAPER_GRAIN,
    origin: tuple[int, int] = (0, 0),
    scale: float | None = None,
) -> torch.Tensor:
    """A watercolor-paper height map.

    A weighted mix of value-noise layers: broad bumps (two octaves), the grain, a fine
    tooth and two layers of fibres (noise cells stretched along two directions); the mix
    is stretched around 0.5 and clamped to [0, 1]. Used for the paper granulation and the
    wobbling of the watercolor effect (Bousseau et al. 2006). Not differentiable.

    Args:
        like: any ``(B, C, H, W)`` tensor; gives the batch, size, device and dtype.
        seed: any integer; different seeds give different sheets of paper.
        grain: the grain's cell size in pixels of a 512-pixel short side; every layer scales with it.
        origin: (y, x) pixel position of this image's top-left corner in a larger image
            (pass that image's ``scale`` too when rendering tiles).
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, 1, H, W)`` in [0, 1] with mean near 0.5.
    """
    check_image(like, name="like")
    _check_positive(grain, "grain")

    def make() -> torch.Tensor:
        if fused.enabled(like):
            layers = [
                _fused_layer(
                    (layer.cell_along * grain, layer.cell_across * grain),
                    layer.angle,
                    _layer_key(int(seed), index + 1),
                    layer.octaves,
                    PAPER_PERSISTENCE,
                    layer.weight,
                )
                for index, layer in enumerate(_PAPER_LAYERS)
            ]
            return _fused_noise(like, layers, origin, scale, contrast=_PAPER_CONTRAST)
        ys, xs = _reference_positions(like, origin, scale)
        total: torch.Tensor | None = None
        for index, layer in enumerate(_PAPER_LAYERS):
            key = _layer_key(int(seed), index + 1)
            cells = (layer.cell_along * grain, layer.cell_across * grain)
            noise = _fbm(ys, xs, cells, layer.angle, key, layer.octaves, PAPER_PERSISTENCE, like.dtype)
            total = noise * layer.weight if total is None else total.add_(noise, alpha=layer.weight)
        assert total is not None
        return ((total - 0.5) * _PAPER_CONTRAST + 0.5).clamp_(0.0, 1.0)

    return _texture(like, ("paper", int(seed), float(grain), *_place(like, origin, scale)), make)


def _fused_layer(cells: tuple[float, float], angle: float, key: int, octaves: int, persistence: float, weight=1.0):
    from wise.filters.fused.noise import Layer

    keys = tuple(_layer_key(key, octave + 1) for octave in range(octaves))
    return Layer(cells[0], cells[1], angle, keys, persistence, weight)


def _fused_noise(like: torch.Tensor, layers: list, origin: tuple[int, int], scale: float | None, contrast=None):
    """The Dr.Jit kernel of :func:`_fbm` (and the paper's mix of layers), ``(H, W)``."""
    from wise.filters.fused.noise import Hash, mixed_noise

    s = resolution_scale(like) if scale is None else float(scale)
    if not s > 0.0:
        raise WiseError(f"scale must be positive, got {s}")
    constants = Hash(_MIX_A, _MIX_B, _VALUE_BITS, LACUNARITY, OCTAVE_TURN)
    origin = (int(origin[0]), int(origin[1]))
    return mixed_noise(like.shape[-2], like.shape[-1], like.dtype, layers, constants, origin, s, contrast)


def _place(like: torch.Tensor, origin: tuple[int, int], scale: float | None) -> tuple[int, int, float]:
    """Where the texture lies in the picture: its origin and its resolved scale."""
    return int(origin[0]), int(origin[1]), resolution_scale(like) if scale is None else float(scale)


def _as_batch(texture: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    return texture.view(1, 1, *texture.shape[-2:]).expand(like.shape[0], 1, -1, -1).contiguous()
