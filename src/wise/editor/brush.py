"""Painting on parameter masks: brush strokes as per-pixel weights, and how they change a mask.

A stroke is a polyline in image coordinates normalized to [0, 1] (x to the right, y down),
so the same stroke lands on the same place of a mask of any resolution. Its weight at a
pixel is 1 within ``hardness * radius`` of the polyline, falls smoothly to 0 at ``radius``,
and is the maximum over the stroke: going over a spot twice in one stroke does not paint
it twice.
"""

from __future__ import annotations

from typing import Sequence

import torch

from wise.errors import WiseError
from wise.params import clamp_edit

MODES = ("increase", "decrease", "set")
MAX_POINTS = 4096
"""Most points in one stroke (a long drag at screen rate stays well below this)."""


def _smoothstep(t: torch.Tensor) -> torch.Tensor:
    t = t.clamp(0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def check_stroke(points: Sequence[Sequence[float]], radius: float, hardness: float) -> None:
    """Raise :class:`WiseError` unless the stroke is well-formed."""
    if not 1 <= len(points) <= MAX_POINTS:
        raise WiseError(f"a stroke needs 1 to {MAX_POINTS} points, got {len(points)}")
    for point in points:
        if len(point) != 2 or not all(-1.0 <= float(c) <= 2.0 for c in point):
            raise WiseError(f"stroke point {list(point)} is not an (x, y) pair near the image (0 to 1)")
    if not 0.0 < radius <= 0.5:
        raise WiseError(f"brush radius must be above 0 and at most 0.5 of the short side, got {radius}")
    if not 0.0 <= hardness <= 1.0:
        raise WiseError(f"brush hardness must be from 0 to 1, got {hardness}")


def stroke_weights(
    size: tuple[int, int], points: Sequence[Sequence[float]], radius: float, hardness: float
) -> torch.Tensor:
    """Weights ``(h, w)`` in [0, 1] of a brush stroke on a mask of ``size`` = (h, w).

    Args:
        size: the mask's (rows, columns).
        points: the polyline, (x, y) pairs in [0, 1] of the image's width and height.
        radius: brush radius as a fraction of the image's short side.
        hardness: fraction of the radius painted at full strength (0: soft, 1: hard edge).
    """
    check_stroke(points, radius, hardness)
    height, width = size
    short = min(height, width)
    radius_px = radius * short
    # Pixel centres and stroke points in mask pixels; distances are isotropic in pixels.
    path = torch.tensor([[float(x) * width, float(y) * height] for x, y in points], dtype=torch.float64)
    starts, ends = path[:-1] if len(path) > 1 else path, path[1:] if len(path) > 1 else path
    weights = torch.zeros(height, width, dtype=torch.float32)
    inner = hardness * radius_px
    for start, end in zip(starts, ends):
        x0 = max(0, int(torch.floor(torch.minimum(start[0], end[0]) - radius_px)))
        x1 = min(width, int(torch.ceil(torch.maximum(start[0], end[0]) + radius_px)) + 1)
        y0 = max(0, int(torch.floor(torch.minimum(start[1], end[1]) - radius_px)))
        y1 = min(height, int(torch.ceil(torch.maximum(start[1], end[1]) + radius_px)) + 1)
        if x0 >= x1 or y0 >= y1:
            continue
        ys = torch.arange(y0, y1, dtype=torch.float64).view(-1, 1) + 0.5
        xs = torch.arange(x0, x1, dtype=torch.float64).view(1, -1) + 0.5
        segment = end - start
        length_sq = float(segment.dot(segment))
        if length_sq > 0.0:
            t = (((xs - start[0]) * segment[0] + (ys - start[1]) * segment[1]) / length_sq).clamp(0.0, 1.0)
        else:
            t = torch.zeros(1, 1, dtype=torch.float64)
        distance = torch.hypot(xs - (start[0] + t * segment[0]), ys - (start[1] + t * segment[1]))
        falloff = 1.0 - _smoothstep((distance - inner) / max(radius_px - inner, 1e-6))
        falloff = torch.where(distance <= inner, torch.ones_like(falloff), falloff).to(torch.float32)
        region = weights[y0:y1, x0:x1]
        torch.maximum(region, falloff, out=region)
    return weights


def paint(mask: torch.Tensor, weights: torch.Tensor, mode: str, amount: float) -> torch.Tensor:
    """A normalized mask ``(h, w)`` after a stroke of ``weights``; painted pixels are clamped to
    the declared range or, where they lay outside it (a preset, a mask fitted to a reference),
    kept from going further out; the others keep their values.

    ``increase`` / ``decrease`` add / subtract ``amount`` (a fraction of the parameter's
    range) at full weight; ``set`` blends towards the normalized value ``amount``.
    """
    if mode not in MODES:
        raise WiseError(f"unknown brush mode {mode!r}; use one of {', '.join(MODES)}")
    if mode == "set":
        painted = mask + (amount - mask) * weights
    else:
        painted = mask + (amount if mode == "increase" else -amount) * weights
    return torch.where(weights > 0, clamp_edit(painted, mask), mask)
