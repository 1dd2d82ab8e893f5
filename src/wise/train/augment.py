"""Photometric and geometric augmentation of training pictures, drawn from a generator.

Geometric: a horizontal flip and, for a share of the pictures, a quarter turn (the effects
have no preferred direction, so neither changes what the parameters mean). Photometric:
exposure, contrast, saturation and gamma jitter, so that the network meets the dim, flat,
washed-out and vivid photos users bring rather than only the training set's own.
"""

from __future__ import annotations

import torch

TURN_SHARE = 0.25
"""Share of the pictures given a quarter turn (either way or half)."""
EXPOSURE = 0.15
"""Largest brightness offset."""
CONTRAST = (0.6, 1.3)
SATURATION = (0.3, 1.4)
GAMMA = (0.7, 1.4)
PHOTOMETRIC_SHARE = 0.8
"""Share of the pictures whose tones and colours are jittered."""


def _uniform(generator: torch.Generator, low: float, high: float) -> float:
    return low + (high - low) * float(torch.rand((), generator=generator))


def augment(picture: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """A randomly flipped, turned and tone-jittered copy of a ``(1, 3, S, S)`` picture in [0, 1]."""
    if float(torch.rand((), generator=generator)) < 0.5:
        picture = picture.flip(-1)
    if float(torch.rand((), generator=generator)) < TURN_SHARE:
        picture = picture.rot90(int(torch.randint(1, 4, (), generator=generator)), dims=(-2, -1))
    if float(torch.rand((), generator=generator)) >= PHOTOMETRIC_SHARE:
        return picture.contiguous()
    gamma = _uniform(generator, *GAMMA)
    contrast = _uniform(generator, *CONTRAST)
    saturation = _uniform(generator, *SATURATION)
    exposure = _uniform(generator, -EXPOSURE, EXPOSURE)
    picture = picture.clamp_min(0.0).pow(gamma)
    grey = picture.mean(dim=1, keepdim=True)
    picture = grey + (picture - grey) * saturation
    mean = picture.mean()
    picture = mean + (picture - mean) * contrast + exposure
    return picture.clamp(0.0, 1.0).contiguous()
