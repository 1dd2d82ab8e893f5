"""Training examples made on the fly: photo crops, random global parameters, the effect's output.

Any folder of photos serves (searched recursively). Each example is a random crop of a random
photo at a random scale, flipped at random, with normalized global parameters drawn uniformly
over [-0.5, 0.5] (or around a random preset), and the example the effect renders from them
without autograd. A validation split keeps whole photos apart from training.
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch.utils.data import Dataset

from wise import effects
from wise.errors import WiseError
from wise.io import read_image

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".webp", ".tif", ".tiff"}
MIN_PHOTOS = 4
"""Fewest readable photos a training run accepts."""
SCALE_RANGE = (0.6, 1.0)
"""A crop covers this fraction of the photo's short side (before it is resized to the training size)."""
PRESET_SPREAD = 0.1
"""Standard deviation (normalized units) of parameters drawn around a preset."""
SAMPLINGS = ("uniform", "presets")


def photo_files(folder: str | Path) -> list[Path]:
    """The image files under ``folder`` (recursively), sorted."""
    root = Path(folder)
    if not root.is_dir():
        raise WiseError(f"{root}: not a directory of photos")
    return sorted(p for p in root.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())


def read_photos(files: list[Path], min_side: int) -> tuple[list[torch.Tensor], list[Path]]:
    """The readable photos with a short side of at least ``min_side``, and the files skipped."""
    photos, skipped = [], []
    for path in files:
        try:
            photo = read_image(path)
        except WiseError:
            skipped.append(path)
            continue
        if min(photo.shape[-2:]) < min_side:
            skipped.append(path)
            continue
        photos.append(photo)
    return photos, skipped


def checked_photos(folder: str | Path, files: list[Path], min_side: int) -> tuple[list[torch.Tensor], str | None]:
    """The readable photos of ``files`` and one note on those skipped (None when none were);
    refuses fewer than :data:`MIN_PHOTOS`."""
    photos, skipped = read_photos(files, min_side)
    if len(photos) < MIN_PHOTOS:
        raise WiseError(
            f"{folder}: {len(photos)} readable photos of at least {min_side} pixels a side "
            f"({len(skipped)} skipped); training needs at least {MIN_PHOTOS}"
        )
    note = f"{folder}: skipped {len(skipped)} unreadable or too small files" if skipped else None
    return photos, note


def split_files(files: list[Path], validation: float, seed: int) -> tuple[list[Path], list[Path]]:
    """Photos for training and for validation, disjoint; at least one of each when there are two."""
    if not 0.0 <= validation < 1.0:
        raise WiseError(f"the validation share must be in [0, 1), got {validation}")
    order = torch.randperm(len(files), generator=torch.Generator().manual_seed(seed)).tolist()
    count = min(len(files) - 1, max(1, math.floor(validation * len(files)))) if validation > 0 else 0
    held_out = set(order[:count])
    return [f for i, f in enumerate(files) if i not in held_out], [f for i, f in enumerate(files) if i in held_out]


class ExampleDataset(Dataset):
    """``length`` examples of ``effect`` on ``size`` x ``size`` crops of ``photos``.

    Item ``i`` is the same every time it is asked for (drawn from a generator seeded with
    ``seed`` and ``i``), so runs are reproducible and validation sets fixed. Returns dicts of
    ``photo`` and ``example`` ``(3, size, size)`` and ``params`` ``(P,)``.
    """

    def __init__(
        self,
        photos: list[torch.Tensor],
        effect: str,
        size: int,
        length: int,
        sampling: str = "uniform",
        seed: int = 0,
    ) -> None:
        if sampling not in SAMPLINGS:
            raise WiseError(f"unknown sampling {sampling!r}; use one of {', '.join(SAMPLINGS)}")
        if not photos:
            raise WiseError("no photos to make examples from")
        self.photos, self.effect_name, self.size, self.length = photos, effect, size, length
        self.sampling, self.seed = sampling, seed
        self._effect = effects.create(effect).eval()

    def __len__(self) -> int:
        return self.length

    def _crop(self, photo: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        low, high = SCALE_RANGE
        fraction = low + (high - low) * float(torch.rand((), generator=generator))
        side = max(8, round(min(photo.shape[-2:]) * fraction))
        top = int(torch.randint(0, photo.shape[-2] - side + 1, (), generator=generator))
        left = int(torch.randint(0, photo.shape[-1] - side + 1, (), generator=generator))
        crop = photo[..., top : top + side, left : left + side]
        crop = F.interpolate(crop, size=(self.size, self.size), mode="area" if side > self.size else "bilinear")
        if float(torch.rand((), generator=generator)) < 0.5:
            crop = crop.flip(-1)
        return crop.clamp(0.0, 1.0)

    def _params(self, generator: torch.Generator) -> torch.Tensor:
        count = len(self._effect.param_specs)
        if self.sampling == "uniform":
            return torch.rand(count, generator=generator) - 0.5
        names = sorted(self._effect.presets)
        preset = self._effect.preset(names[int(torch.randint(0, len(names), (), generator=generator))])
        return (preset + PRESET_SPREAD * torch.randn(count, generator=generator)).clamp(-0.5, 0.5)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        if not 0 <= index < self.length:
            raise IndexError(index)
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + index)
        photo = self.photos[int(torch.randint(0, len(self.photos), (), generator=generator))]
        crop = self._crop(photo, generator)
        params = self._params(generator)
        with torch.no_grad():
            example = self._effect(crop, params[None])
        return {"photo": crop[0], "example": example[0].clamp(0.0, 1.0), "params": params}
