"""Procedural training pictures and augmentation."""

from __future__ import annotations

import torch

from wise.train.augment import augment
from wise.train.procedural import dead_leaves


def test_dead_leaves_are_reproducible_pictures_of_occluding_shapes() -> None:
    first = dead_leaves(96, torch.Generator().manual_seed(3))
    again = dead_leaves(96, torch.Generator().manual_seed(3))
    other = dead_leaves(96, torch.Generator().manual_seed(4))
    assert first.shape == (1, 3, 96, 96) and torch.equal(first, again) and not torch.equal(first, other)
    assert 0.0 <= float(first.min()) and float(first.max()) <= 1.0
    # occlusion edges: many neighbouring pixels differ strongly, as at the outlines of shapes
    steps = (first[..., 1:] - first[..., :-1]).abs().amax(dim=1)
    assert float((steps > 0.1).float().mean()) > 0.01
    # and many colours, not one shape on a flat ground
    assert float(first.std(dim=(2, 3)).mean()) > 0.05


def test_augmentation_keeps_the_range_and_is_drawn_from_the_generator() -> None:
    picture = torch.rand(1, 3, 16, 16)
    results = [augment(picture, torch.Generator().manual_seed(seed)) for seed in range(12)]
    assert all(r.shape == picture.shape and 0.0 <= float(r.min()) and float(r.max()) <= 1.0 for r in results)
    assert torch.equal(results[0], augment(picture, torch.Generator().manual_seed(0)))
    assert len({round(float(r.mean()), 5) for r in results}) > 6  # tones vary between draws
