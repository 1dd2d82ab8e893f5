"""Pictures kept below the reference size (training pairs, a model's working size) render at the
reference scale, so that they look like a reduced reference-size render."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from skimage import data

from wise import effects
from wise.effects.base import LEAST_WINDOW_SCALE, window_scale


def test_window_scale_is_the_own_scale_above_the_reference_and_one_below() -> None:
    assert window_scale(256, 341) == LEAST_WINDOW_SCALE == 1.0
    assert window_scale(48, 4000) == 1.0
    assert window_scale(1024, 768) == 1.5
    assert window_scale(512, 512) == 1.0


def _ink(image: torch.Tensor) -> float:
    """The share of dark pixels of a drawing."""
    return float((image.clamp(0.0, 1.0).mean(dim=1) < 0.5).float().mean())


def test_a_small_xdog_picture_keeps_the_ink_of_the_reduced_reference_render() -> None:
    photo = torch.from_numpy(data.coffee()).permute(2, 0, 1)[None].float() / 255.0
    photo = F.interpolate(photo, size=(512, 683), mode="area")
    small = F.interpolate(photo, size=(256, 341), mode="area")
    xdog = effects.create("xdog").eval()
    params = xdog.preset("sketch")[None]
    with torch.no_grad():
        reference = F.interpolate(xdog(photo, params), size=small.shape[-2:], mode="area")
        own_scale = xdog(small, params)
        windowed = xdog(small, params, scale=window_scale(*small.shape[-2:]))
    ratio_windowed, ratio_own = _ink(windowed) / _ink(reference), _ink(own_scale) / _ink(reference)
    assert 0.8 <= ratio_windowed <= 1.5, ratio_windowed
    assert abs(ratio_windowed - 1.0) < abs(ratio_own - 1.0), (ratio_windowed, ratio_own)
