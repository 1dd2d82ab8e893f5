"""A synthetic artist for developing image-to-image translation (``wise data drawing``).

Real paired drawings (APDrawing, Yi et al. 2019) hold what a filter pipeline alone cannot
make: strokes of a steady width whatever the edge's contrast, and tones drawn as hatching.
This drawing process makes both, so that a set of its pairs separates the variants of
``wise train local --post``: XDoG can find the edges and the dark areas, but only a CNN after
it can turn dark areas into hatching.

The drawing of a photo, on white paper (all lengths in pixels of a 512-pixel short side):

1. *outlines*: edges where the gradient magnitude of the slightly smoothed luminance is high
   compared with the picture's own (its :data:`EDGE_QUANTILE` quantile), grown into strokes
   :data:`STROKE_WIDTH` wide, of one darkness;
2. *hatching*: the luminance, smoothed into tone areas, is drawn as parallel lines, at 45°
   where it is below the first of :data:`HATCH_TONES`, crossed at -45° below the second,
   and with horizontal lines below the third;
3. the drawing is the darkest of the two, as grey RGB.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from wise.filters import gaussian_blur, resolution_scale
from wise.filters._checks import REFERENCE_SHORT_SIDE, check_image

LUMA = (0.299, 0.587, 0.114)
EDGE_SIGMA = 2.0
"""Smoothing of the luminance before its gradient: the artist ignores fine texture."""
EDGE_QUANTILE = 0.9
"""Gradient magnitudes are compared with this quantile of the picture's."""
EDGE_LEVELS = (1.0, 1.6)
"""Relative gradient magnitudes where an outline starts and where it is fully dark."""
STROKE_WIDTH = 5.0
OUTLINE_INK = 0.08
TONE_SIGMA = 6.0
"""Smoothing of the luminance into the tone areas the hatching fills."""
HATCH_TONES = (0.45, 0.3, 0.16)
"""Below these tones: one, two and three directions of hatching."""
HATCH_ANGLES = (45.0, -45.0, 0.0)
HATCH_PERIOD = 11.0
HATCH_WIDTH = 2.6
HATCH_INK = 0.25
TONE_SOFTNESS = 0.04
"""Tones within this distance of a threshold fade the hatching in (no hard tone borders)."""


def _ramp(value: torch.Tensor, start: float, full: float) -> torch.Tensor:
    """0 at ``start``, 1 at ``full``, linear in between (either order)."""
    return ((value - start) / (full - start)).clamp(0.0, 1.0)


def luminance(photo: torch.Tensor) -> torch.Tensor:
    """Rec. 601 luma; ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    weights = torch.tensor(LUMA, dtype=photo.dtype, device=photo.device).view(1, 3, 1, 1)
    return (photo * weights).sum(dim=1, keepdim=True)


def outlines(gray: torch.Tensor) -> torch.Tensor:
    """Coverage of the outline strokes in [0, 1]; ``(B, 1, H, W)``."""
    smooth = gaussian_blur(gray, EDGE_SIGMA)
    dy, dx = torch.gradient(smooth, dim=(2, 3))
    magnitude = torch.sqrt(dx.square() + dy.square())
    reference = torch.quantile(magnitude.flatten(1), EDGE_QUANTILE, dim=1).clamp_min(1e-4).view(-1, 1, 1, 1)
    edges = _ramp(magnitude / reference, *EDGE_LEVELS)
    radius = max(1, round(STROKE_WIDTH * resolution_scale(gray) / 2))
    return F.max_pool2d(edges, 2 * radius + 1, stride=1, padding=radius)


def hatch_lines(height: int, width: int, angle: float, period: float, like: torch.Tensor) -> torch.Tensor:
    """Anti-aliased parallel lines at ``angle`` degrees, ``period`` pixels apart and
    :data:`HATCH_WIDTH` wide at a 512-pixel short side, as coverage ``(1, 1, H, W)``."""
    scale = min(height, width) / REFERENCE_SHORT_SIDE
    ys = torch.arange(height, dtype=like.dtype, device=like.device).view(-1, 1)
    xs = torch.arange(width, dtype=like.dtype, device=like.device).view(1, -1)
    radians = math.radians(angle)
    across = xs * math.sin(radians) + ys * math.cos(radians)
    spacing = period * scale
    distance = (torch.remainder(across, spacing) - spacing / 2).abs()
    half_width = HATCH_WIDTH * scale / 2
    return (half_width + 0.5 - distance).clamp(0.0, 1.0).view(1, 1, height, width)


def hatching(gray: torch.Tensor) -> torch.Tensor:
    """Coverage of the hatching in [0, 1]; ``(B, 1, H, W)``."""
    tone = gaussian_blur(gray, TONE_SIGMA)
    height, width = gray.shape[-2:]
    covered = torch.zeros_like(gray)
    for threshold, angle in zip(HATCH_TONES, HATCH_ANGLES):
        lines = hatch_lines(height, width, angle, HATCH_PERIOD, gray)
        covered = torch.maximum(covered, lines * _ramp(tone, threshold, threshold - TONE_SOFTNESS))
    return covered


def draw(photo: torch.Tensor) -> torch.Tensor:
    """The synthetic artist's drawing of ``photo``; ``(B, 3, H, W)`` in [0, 1] -> grey
    ``(B, 3, H, W)`` in [0, 1]."""
    check_image(photo, "photo", channels=3)
    gray = luminance(photo)
    outline_paper = 1.0 - (1.0 - OUTLINE_INK) * outlines(gray)
    hatch_paper = 1.0 - (1.0 - HATCH_INK) * hatching(gray)
    return torch.minimum(outline_paper, hatch_paper).expand(-1, 3, -1, -1).contiguous()
