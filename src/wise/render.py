"""Rendering: large images tile by tile, small ones at the reference scale.

A tile is rendered with a halo of the pixels its pipeline reads around it, with the scale and
position of the whole picture, and only its core is kept, so the tiles join without seams.
Parameter masks are resampled for each tile from the mask itself, exactly as
:func:`wise.params.resize_masks` would resample them for the whole picture, without ever
building full-resolution masks.

A picture whose short side is below the reference (512 pixels) is enlarged to it, rendered and
reduced again: its look is the reference render's reduced to the picture, where a render at the
picture's own size would shrink every structure scale of the effects under a pixel (lines break
into dashes, brush strokes vanish). The medium's own texture (bristles and paint relief, pigment
speckles, paper grain) is enlarged with the picture, so that reduced again it keeps its
reference size in the pixels shown (:attr:`~wise.effects.base.RenderContext.medium`).

:func:`render` renders without autograd; :class:`Look` draws a picture, or a box of it, the same
way with autograd, for the optimizations that fit parameters to an example of that size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator

import torch
import torch.nn.functional as F

from wise.effects.base import Effect
from wise.filters import gaussian_blur
from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.filters.resize import bilinear_resize
from wise.params import check_params

MAX_SPLITS = 64
"""Most tiles along one side considered when choosing the tile layout."""
ENLARGEMENT_SHARPENING = 1.0
"""Sigma of the unsharp mask after enlarging a small picture, per unit of enlargement (at 0.5,
XDoG ``pencil`` on a grassy landscape kept half the ink of the reference render)."""
TILE_ALIGNMENT = 8
"""Tiles and halos start on multiples of this, so stages that work at a reduced resolution
see the same pixel grid in every tile."""
GUIDE_MAX_SCALE = 2.0
"""A picture rendered in tiles above this scale gets its guide made on a copy reduced to it and
enlarged: the guide's finest structure is a reference pixel (two pixels at this scale), while
its reach at full size (the flow of oil paint reads 300 reference pixels around each pixel)
would need halos of thousands of pixels."""


@dataclass(frozen=True)
class Tile:
    """A tile's core ``[y0, y1) x [x0, x1)`` and the padded box ``[py0, py1) x [px0, px1)`` read for it."""

    y0: int
    y1: int
    x0: int
    x1: int
    py0: int
    py1: int
    px0: int
    px1: int


def tiles(height: int, width: int, tile: int | tuple[int, int], halo: int) -> Iterator[Tile]:
    """Cover ``height x width`` with cores of at most ``tile`` (rows, columns) pixels, padded by ``halo``."""
    tile_h, tile_w = (tile, tile) if isinstance(tile, int) else tile
    for y0 in range(0, height, tile_h):
        for x0 in range(0, width, tile_w):
            y1, x1 = min(y0 + tile_h, height), min(x0 + tile_w, width)
            yield Tile(
                y0, y1, x0, x1, max(0, y0 - halo), min(height, y1 + halo), max(0, x0 - halo), min(width, x1 + halo)
            )


def _align(value: int) -> int:
    return -(-value // TILE_ALIGNMENT) * TILE_ALIGNMENT


def tile_shape(height: int, width: int, halo: int, max_pixels: int) -> tuple[int, int]:
    """The core (rows, columns) that covers the picture with the fewest pixels processed,
    halos included, while no padded tile exceeds ``max_pixels`` (strips when that is cheapest)."""
    best: tuple[int, tuple[int, int]] | None = None
    for rows in range(1, min(MAX_SPLITS, -(-height // TILE_ALIGNMENT)) + 1):
        for columns in range(1, min(MAX_SPLITS, -(-width // TILE_ALIGNMENT)) + 1):
            shape = (_align(-(-height // rows)), _align(-(-width // columns)))
            padded = [(t.py1 - t.py0) * (t.px1 - t.px0) for t in tiles(height, width, shape, halo)]
            if max(padded) <= max_pixels:
                if best is None or sum(padded) < best[0]:
                    best = (sum(padded), shape)
                break  # more columns only add halo
    if best is None:
        side = max(TILE_ALIGNMENT, _align(int(max_pixels**0.5) - 2 * halo))
        return side, side
    return best[1]


def masks_for_box(masks: torch.Tensor, size: tuple[int, int], box: tuple[int, int, int, int]) -> torch.Tensor:
    """``resize_masks(masks, size)[..., y0:y1, x0:x1]`` without the full-size intermediate.

    Args:
        masks: ``(B, P, h, w)``.
        size: (H, W) of the whole picture.
        box: (y0, y1, x0, x1) in the whole picture.
    """
    height, width = size
    y0, y1, x0, x1 = box
    ys = (torch.arange(y0, y1, dtype=masks.dtype, device=masks.device) + 0.5) * (2.0 / height) - 1.0
    xs = (torch.arange(x0, x1, dtype=masks.dtype, device=masks.device) + 0.5) * (2.0 / width) - 1.0
    grid = torch.stack(torch.meshgrid(xs, ys, indexing="xy"), dim=-1).unsqueeze(0).expand(masks.shape[0], -1, -1, -1)
    return F.grid_sample(masks, grid, mode="bilinear", padding_mode="border", align_corners=False)


def enlarged(image: torch.Tensor) -> torch.Tensor:
    """``image`` (B, C, H, W) enlarged so that its short side is the reference's: bicubic, then
    sharpened by an unsharp mask of the enlargement's own scale, which gives back the edge contrast
    that the interpolation spreads (an XDoG of the bare enlargement draws a third fewer lines)."""
    height, width = image.shape[-2:]
    factor = REFERENCE_SHORT_SIDE / min(height, width)
    shortest = math.ceil(REFERENCE_SHORT_SIDE)
    size = (max(shortest, round(height * factor)), max(shortest, round(width * factor)))
    smooth = F.interpolate(image, size=size, mode="bicubic", align_corners=False)
    detail = smooth - gaussian_blur(smooth, ENLARGEMENT_SHARPENING * factor, scale=1.0)
    return (smooth + detail).clamp(0.0, 1.0)


def reduced(image: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """``image`` (B, C, H, W) reduced to ``size`` with an antialiasing filter."""
    return F.interpolate(image, size=size, mode="bilinear", antialias=True, align_corners=False).clamp(0.0, 1.0)


def reduction_weights(source: int, size: int, like: torch.Tensor) -> torch.Tensor:
    """The ``(size, source)`` matrix of :func:`reduced` along one side: row ``i`` holds the
    weights of the source pixels that make pixel ``i`` of the reduction."""
    identity = torch.eye(source, dtype=like.dtype, device=like.device).reshape(1, 1, source, source)
    return F.interpolate(identity, size=(size, source), mode="bilinear", antialias=True, align_corners=False)[0, 0]


class Look:
    """How :func:`render` draws ``content`` (1, 3, H, W) with ``effect``, differentiable in the
    parameters: a picture whose short side is below the reference enlarged to it
    (:func:`enlarged`, the medium with it) and the render reduced back (:func:`reduced`), so that
    descent fits the look the user's render shows; ``at_reference=False`` draws it at its own
    scale (a reduced working copy, where that look is an approximation taken for speed)."""

    def __init__(self, effect: Effect, content: torch.Tensor, at_reference: bool = True) -> None:
        self.effect = effect
        self.size: tuple[int, int] = (content.shape[-2], content.shape[-1])
        short = min(self.size)
        self.enlargement = REFERENCE_SHORT_SIDE / short if at_reference and short < REFERENCE_SHORT_SIDE else 1.0
        self.source = enlarged(content) if self.enlargement > 1.0 else content
        self.scale = min(self.source.shape[-2:]) / REFERENCE_SHORT_SIDE
        self.medium = self.enlargement if self.enlargement > 1.0 else None
        # the reduction back to the picture along each side (None: drawn at its own size)
        self.rows: torch.Tensor | None = None
        self.columns: torch.Tensor | None = None
        if self.enlargement > 1.0:
            self.rows = reduction_weights(self.source.shape[-2], self.size[0], content)
            self.columns = reduction_weights(self.source.shape[-1], self.size[1], content)

    def __call__(self, params: torch.Tensor) -> torch.Tensor:
        """The whole picture, (1, 3, H, W)."""
        output = self.effect(self.source, params, scale=self.scale, medium=self.medium)
        if self.enlargement == 1.0:
            return output
        return F.interpolate(output, size=self.size, mode="bilinear", antialias=True, align_corners=False)

    def box(self, params: torch.Tensor, top: int, left: int, height: int, width: int, context: int) -> torch.Tensor:
        """The picture's ``[top, top + height) x [left, left + width)``, rendered from the
        pixels it reads plus ``context`` pixels of the render around them (the rest of the
        picture's pipeline reaches that far), at the scale and position of the whole picture.
        The rendered window has the same size wherever the box lies (shifted inward at the
        picture's edges), so that the fused kernels compile once."""
        if self.rows is None or self.columns is None:
            rows, columns = None, None
            (r0, r1), (c0, c1) = (top, top + height), (left, left + width)
        else:
            rows, (r0, r1) = _weights_and_span(self.rows, top, height)
            columns, (c0, c1) = _weights_and_span(self.columns, left, width)
        y0, y1 = _window(r0, r1, self._span(height), context, self.source.shape[-2])
        x0, x1 = _window(c0, c1, self._span(width), context, self.source.shape[-1])
        output = self.effect(
            self.source[..., y0:y1, x0:x1], params, scale=self.scale, origin=(y0, x0), medium=self.medium
        )[..., r0 - y0 : r1 - y0, c0 - x0 : c1 - x0]
        if rows is None or columns is None:
            return output
        return rows @ output @ columns.T

    def _span(self, count: int) -> int:
        """The most source pixels that ``count`` pixels of the picture read (the reduction's
        filter reaches one enlargement beyond each side)."""
        if self.enlargement == 1.0:
            return count
        return math.ceil((count + 2) * self.enlargement) + 2


def _window(first: int, end: int, span: int, context: int, length: int) -> tuple[int, int]:
    """``[start, start + span + 2 context)`` within ``[0, length)`` around ``[first, end)``."""
    size = min(length, span + 2 * context)
    start = min(max(0, first - context - (span - (end - first)) // 2), length - size)
    return start, start + size


def _weights_and_span(weights: torch.Tensor, first: int, count: int) -> tuple[torch.Tensor, tuple[int, int]]:
    """The reduction's rows ``[first, first + count)`` restricted to the source pixels they read,
    and that span ``[start, end)``."""
    rows = weights[first : first + count]
    read = rows.abs().sum(dim=0).nonzero().flatten()
    start, end = int(read[0]), int(read[-1]) + 1
    return rows[:, start:end], (start, end)


@torch.no_grad()
def render(
    effect: Effect,
    image: torch.Tensor,
    params: torch.Tensor,
    tile: int | None = None,
    device: torch.device | str | None = None,
    at_reference: bool = True,
) -> torch.Tensor:
    """Render ``effect`` on ``image`` (B, 3, H, W) without autograd, in tiles when it is large,
    at the reference scale and reduced when it is small (see the module; ``at_reference=False``
    renders a small picture at its own scale, as ``effect(image, params)`` does).

    ``tile`` forces square cores of that size; by default the layout processes the fewest
    pixels with no padded tile above the effect's ``tile_pixels``. Memory stays that of one padded
    tile; the result, on ``image``'s device, equals rendering the whole picture at once up
    to floating-point rounding, and above :data:`GUIDE_MAX_SCALE` up to a guide made at that scale.
    """
    return _render(effect, image, params, tile, device, at_reference, None)


def _render(
    effect: Effect,
    image: torch.Tensor,
    params: torch.Tensor,
    tile: int | None,
    device: torch.device | str | None,
    at_reference: bool,
    medium: float | None,
) -> torch.Tensor:
    device = torch.device(device) if device is not None else image.device
    batch, _, height, width = image.shape
    params = check_params(params, effect.param_specs, batch)
    if at_reference and min(height, width) < REFERENCE_SHORT_SIDE:
        # the medium enlarged as much as the picture: reduced again, its texture keeps the
        # reference size in the pixels shown instead of falling under a pixel
        enlargement = REFERENCE_SHORT_SIDE / min(height, width)
        return reduced(_render(effect, enlarged(image), params, tile, device, False, enlargement), (height, width))
    scale = min(height, width) / REFERENCE_SHORT_SIDE
    if (tile is None and height * width <= effect.tile_pixels) or (tile is not None and max(height, width) <= tile):
        return effect(image.to(device), params.to(device), scale=scale, medium=medium).to(image.device)
    guide = _guide(effect, image, params, scale, device) if effect.guide_channels else None
    halo = _align(effect.halo(max(scale, medium or scale)))
    shape = tile_shape(height, width, halo, effect.tile_pixels) if tile is None else (_align(tile), _align(tile))
    out = torch.empty_like(image)
    for t, crop, crop_params in _tile_inputs(image, params, shape, halo, device):
        tile_guide = None if guide is None else guide[..., t.py0 : t.py1, t.px0 : t.px1].to(device)
        result = effect(crop, crop_params, scale=scale, origin=(t.py0, t.px0), guide=tile_guide, medium=medium)
        out[..., t.y0 : t.y1, t.x0 : t.x1] = _core(result, t).to(out.device)
    return out


def _guide(
    effect: Effect, image: torch.Tensor, params: torch.Tensor, scale: float, device: torch.device
) -> torch.Tensor:
    """The effect's :meth:`~wise.effects.base.Effect.guide` for the whole picture, made in tiles
    with the guide's own halo (above :data:`GUIDE_MAX_SCALE` on a reduced copy), kept on
    ``image``'s device."""
    batch, _, height, width = image.shape
    if scale > GUIDE_MAX_SCALE:
        factor = scale / GUIDE_MAX_SCALE
        size = (max(1, round(height / factor)), max(1, round(width / factor)))
        small = _guide(effect, reduced(image, size), params, min(size) / REFERENCE_SHORT_SIDE, device)
        return bilinear_resize(small, (height, width))
    halo = _align(effect.guide_halo(scale))
    guide = image.new_empty((batch, effect.guide_channels, height, width))
    for t, crop, crop_params in _tile_inputs(
        image, params, tile_shape(height, width, halo, effect.guide_tile_pixels), halo, device
    ):
        result = effect.guide(crop, crop_params, scale=scale, origin=(t.py0, t.px0))
        guide[..., t.y0 : t.y1, t.x0 : t.x1] = _core(result, t).to(guide.device)
    return guide


def _tile_inputs(
    image: torch.Tensor, params: torch.Tensor, shape: tuple[int, int], halo: int, device: torch.device
) -> Iterator[tuple[Tile, torch.Tensor, torch.Tensor]]:
    """Each tile with its padded crop of the image and of the parameters, on ``device``."""
    height, width = image.shape[-2:]
    for t in tiles(height, width, shape, halo):
        crop = image[..., t.py0 : t.py1, t.px0 : t.px1].to(device)
        crop_params = (
            params if params.dim() == 2 else masks_for_box(params, (height, width), (t.py0, t.py1, t.px0, t.px1))
        )
        yield t, crop, crop_params.to(device)


def _core(result: torch.Tensor, t: Tile) -> torch.Tensor:
    """The tile's core of a result computed on its padded box."""
    return result[..., t.y0 - t.py0 : t.y1 - t.py0, t.x0 - t.px0 : t.x1 - t.px0]


def changed_box(params: torch.Tensor, before: torch.Tensor, size: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """The box ``(y0, y1, x0, x1)`` of the picture of ``size`` over which the masks ``params``
    differ from ``before`` (both ``(B, P, h, w)``), widened by the footprint of a mask pixel;
    ``None`` where they are equal."""
    differs = (params != before).flatten(0, 1).any(dim=0)
    if not bool(differs.any()):
        return None
    rows, columns = differs.any(dim=1).nonzero().flatten(), differs.any(dim=0).nonzero().flatten()
    (height, width), (mask_h, mask_w) = size, params.shape[-2:]
    # a mask pixel is read by the bilinear resampling up to one mask pixel beyond its own area
    return (
        max(0, (int(rows[0]) - 1) * height // mask_h),
        min(height, -(-(int(rows[-1]) + 2) * height // mask_h)),
        max(0, (int(columns[0]) - 1) * width // mask_w),
        min(width, -(-(int(columns[-1]) + 2) * width // mask_w)),
    )


REDRAW_FRACTION = 0.5
"""Above this fraction of the picture, :func:`rerender` renders the whole picture again."""


@torch.no_grad()
def rerender(
    effect: Effect,
    image: torch.Tensor,
    params: torch.Tensor,
    before: torch.Tensor,
    rendered: torch.Tensor,
    at_reference: bool = True,
) -> torch.Tensor:
    """``render(effect, image, params)`` given ``rendered``, the render with the masks ``before``:
    only the pixels that the changed part of the masks can reach are rendered again, from a crop
    with the pixels the pipeline reads around them (a painted stroke costs a fraction of a render).

    ``params`` and ``before`` are masks ``(B, P, h, w)`` of the same shape; the result equals a
    whole render up to floating-point rounding, like a render in tiles. A picture below the
    reference size is rendered whole (see :func:`render`).
    """
    height, width = image.shape[-2:]
    small = at_reference and min(height, width) < REFERENCE_SHORT_SIDE  # enlarged: a whole render is cheap
    if small or params.dim() != 4 or params.shape != before.shape or height * width > effect.tile_pixels:
        return render(effect, image, params, at_reference=at_reference)
    box = changed_box(params, before, (height, width))
    if box is None:
        return rendered.clone()
    scale = min(height, width) / REFERENCE_SHORT_SIDE
    reach = effect.halo(scale) + (effect.guide_halo(scale) if effect.guide_channels else 0)
    y0, y1, x0, x1 = (
        max(0, box[0] - reach),
        min(height, box[1] + reach),
        max(0, box[2] - reach),
        min(width, box[3] + reach),
    )
    crop = Tile(
        y0,
        y1,
        x0,
        x1,
        max(0, y0 - reach) // TILE_ALIGNMENT * TILE_ALIGNMENT,
        min(height, y1 + reach),
        max(0, x0 - reach) // TILE_ALIGNMENT * TILE_ALIGNMENT,
        min(width, x1 + reach),
    )
    if (crop.py1 - crop.py0) * (crop.px1 - crop.px0) > REDRAW_FRACTION * height * width:
        return render(effect, image, params, at_reference=at_reference)
    masks = check_params(params, effect.param_specs, image.shape[0])
    result = effect(
        image[..., crop.py0 : crop.py1, crop.px0 : crop.px1],
        masks_for_box(masks, (height, width), (crop.py0, crop.py1, crop.px0, crop.px1)),
        scale=scale,
        origin=(crop.py0, crop.px0),
    )
    out = rendered.clone()
    out[..., y0:y1, x0:x1] = _core(result, crop)
    return out
