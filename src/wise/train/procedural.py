"""Procedural training pictures: dead-leaves images of occluding shapes.

A dead-leaves image (Matheron 1968; Lee, Mumford & Huang 2001) stacks random shapes whose
sizes follow a power law, so it has the scale invariance, occlusions and sharp edges of
natural photos without being one. Baradad et al. 2021 ("Learning to See by Looking at Noise")
showed such images train vision networks nearly as well as photos. Here each shape is a disk
or a turned rectangle filled with a colour gradient and, at random, stripes or blotches, and
the picture gets a little blur and noise, so that the effects' line, colour and texture
stages all have something to work on.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

SHAPES_PER_PICTURE = (60, 200)
"""How many shapes a picture stacks (uniform between the two)."""
RADIUS_RANGE = (0.02, 0.5)
"""Smallest and largest shape radius as a fraction of the picture's side."""
RADIUS_POWER = 2.0
"""Radii are drawn with density proportional to ``r ** -RADIUS_POWER`` (scale invariance)."""
TEXTURE_SHARE = 0.4
"""Share of the shapes with stripes or blotches on their gradient."""


class _Draws:
    """Uniform numbers taken one by one from a block drawn at once (one generator call per shape)."""

    def __init__(self, generator: torch.Generator, count: int) -> None:
        self._values = iter(torch.rand(count, generator=generator).tolist())

    def __call__(self, low: float = 0.0, high: float = 1.0) -> float:
        return low + (high - low) * next(self._values)


DRAWS_PER_SHAPE = 24
"""Uniform numbers a shape may take (position, size, form, two colours, gradient, texture)."""


def _power_law_radius(u: float) -> float:
    low, high = RADIUS_RANGE
    exponent = 1.0 - RADIUS_POWER
    return (low**exponent + u * (high**exponent - low**exponent)) ** (1.0 / exponent)


def _colour(draw: _Draws) -> torch.Tensor:
    """A random colour ``(3, 1, 1)``, mostly of the muted saturation of photos."""
    red, green, blue = draw(), draw(), draw()
    grey = (red + green + blue) / 3.0
    saturation = draw(0.1, 1.0) ** 1.5
    return torch.tensor([grey + (c - grey) * saturation for c in (red, green, blue)]).view(3, 1, 1)


def _fill(ys: torch.Tensor, xs: torch.Tensor, draw: _Draws) -> torch.Tensor:
    """A shape's colour at rows ``ys`` ``(H, 1)`` and columns ``xs`` ``(1, W)`` of the picture:
    a linear gradient between two colours, with stripes or blotches on some shapes."""
    first, second = _colour(draw), _colour(draw)
    angle = draw(0.0, math.pi)
    along = (xs * math.cos(angle) + ys * math.sin(angle)) * draw(0.0, 2.0)
    colour = first + (second - first) * along.frac().mul(2.0).sub(1.0).abs()
    if draw() < TEXTURE_SHARE:
        turn, frequency, strength, blotches = draw(0.0, math.pi), draw(10.0, 60.0), draw(0.05, 0.3), draw() < 0.5
        pattern = torch.sin((xs * math.cos(turn) + ys * math.sin(turn)) * frequency)
        if blotches:
            pattern = pattern * torch.sin((xs * math.sin(turn) - ys * math.cos(turn)) * frequency * 0.7)
        colour = colour + strength * pattern
    return colour


def dead_leaves(side: int, generator: torch.Generator) -> torch.Tensor:
    """A ``(1, 3, side, side)`` dead-leaves picture in [0, 1], the same for the same generator state."""
    coordinates = (torch.arange(side, dtype=torch.float32) + 0.5) / side
    ys, xs = coordinates.view(-1, 1), coordinates.view(1, -1)
    picture = _fill(ys, xs, _Draws(generator, DRAWS_PER_SHAPE)).expand(3, side, side).clone()
    count = int(torch.randint(SHAPES_PER_PICTURE[0], SHAPES_PER_PICTURE[1] + 1, (), generator=generator))
    for _ in range(count):
        draw = _Draws(generator, DRAWS_PER_SHAPE)
        radius = _power_law_radius(draw())
        centre_y, centre_x = draw(-0.1, 1.1), draw(-0.1, 1.1)
        is_disk = draw() < 0.6
        turn, aspect = draw(0.0, math.pi), draw(0.2, 1.0)
        # only the shape's bounding box is painted (a rectangle reaches sqrt(2) radii from its centre)
        reach = radius * 1.5 + 1.0 / side
        rows = slice(max(0, math.floor((centre_y - reach) * side)), min(side, math.ceil((centre_y + reach) * side)))
        columns = slice(max(0, math.floor((centre_x - reach) * side)), min(side, math.ceil((centre_x + reach) * side)))
        if rows.start >= rows.stop or columns.start >= columns.stop:
            continue
        dy, dx = ys[rows] - centre_y, xs[:, columns] - centre_x
        if is_disk:
            distance = torch.sqrt(dy * dy + dx * dx) - radius
        else:
            along = (dx * math.cos(turn) + dy * math.sin(turn)).abs() - radius
            across = (dy * math.cos(turn) - dx * math.sin(turn)).abs() - radius * aspect
            distance = torch.maximum(along, across)
        coverage = (0.5 - distance * side).clamp(0.0, 1.0)  # anti-aliased edge one pixel wide
        region = picture[:, rows, columns]
        region.lerp_(_fill(ys[rows], xs[:, columns], draw).expand_as(region), coverage.expand_as(region))
    finish = _Draws(generator, 2)
    blur, noise = finish(), finish(0.0, 0.04)
    picture = picture[None]
    if blur > 0.3:
        kernel = torch.exp(-0.5 * (torch.arange(-2, 3, dtype=torch.float32) / blur) ** 2)
        kernel = (kernel / kernel.sum()).view(1, 1, 1, 5).expand(3, 1, 1, 5)
        padded = F.pad(picture, (2, 2, 0, 0), mode="replicate")
        picture = F.conv2d(padded, kernel, groups=3)
        padded = F.pad(picture, (0, 0, 2, 2), mode="replicate")
        picture = F.conv2d(padded, kernel.transpose(-1, -2), groups=3)
    picture = picture + noise * torch.randn(picture.shape, generator=generator)
    return picture.clamp(0.0, 1.0)
