"""Training examples made on the fly: photo crops, random global parameters, the effect's output.

Any folder of photos serves (searched recursively). Each example is a random crop of a random
photo at a random scale, flipped at random, with normalized global parameters drawn uniformly
over [-0.5, 0.5] (or around a random preset), and the example the effect renders from them
without autograd. A validation split keeps whole photos apart from training.

The effect renders at ``render_size`` (the resolution the network's predictions are used at,
512 pixels by default in ``wise train``) and photo and example are then reduced to the
network's ``size``: an effect rendered small is not the same picture as a large rendering
reduced (lines thin out, textures average), and the network sees the latter when it predicts.
Rendering dominates the cost of training, so training takes windows of the pictures (rendered
as tiles) and each example is rendered once and kept (8-bit) for later epochs.
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import torch
import torch.nn.functional as F
from safetensors.torch import save as st_save
from torch.utils.data import Dataset

import wise
from wise import effects
from wise.errors import WiseError
from wise.files import read_safetensors
from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.io import atomic_path, read_image
from wise.optimize.benchmark import MAX_DRAWS, MIN_REFERENCE_CONTRAST

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".webp", ".tif", ".tiff"}
MIN_PHOTOS = 4
"""Fewest readable photos a training run accepts."""
SCALE_RANGE = (0.6, 1.0)
"""A crop covers this fraction of the photo's short side (before it is resized to the training size)."""
PRESET_SPREAD = 0.1
"""Standard deviation (normalized units) of parameters drawn around a preset."""
SAMPLINGS = ("uniform", "presets")
MAX_CACHE_BYTES = 16 * 1000**3
"""Largest example cache read back."""


def photo_files(folder: str | Path) -> list[Path]:
    """The image files under ``folder`` (recursively), sorted."""
    root = Path(folder)
    if not root.is_dir():
        raise WiseError(f"{root}: not a directory of photos")
    return sorted(p for p in root.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())


def _as_bytes(image: torch.Tensor) -> torch.Tensor:
    return (image.clamp(0.0, 1.0) * 255.0).round().to(torch.uint8)


def _as_floats(image: torch.Tensor) -> torch.Tensor:
    return image.to(torch.float32) / 255.0


def read_photos(files: list[Path], min_side: int, max_side: int | None = None) -> tuple[list[torch.Tensor], list[Path]]:
    """The readable photos (8-bit ``(1, 3, H, W)``) with a short side of at least ``min_side``,
    reduced to a short side of ``max_side`` when larger, and the files skipped."""
    photos, skipped = [], []
    for path in files:
        try:
            photo = read_image(path)
        except WiseError:
            skipped.append(path)
            continue
        short = min(photo.shape[-2:])
        if short < min_side:
            skipped.append(path)
            continue
        if max_side is not None and short > max_side:
            factor = max_side / short
            shape = (max(1, round(photo.shape[-2] * factor)), max(1, round(photo.shape[-1] * factor)))
            photo = F.interpolate(photo, size=shape, mode="area")
        photos.append(_as_bytes(photo))
    return photos, skipped


def checked_photos(
    folder: str | Path, files: list[Path], min_side: int, max_side: int | None = None
) -> tuple[list[torch.Tensor], str | None]:
    """The readable photos of ``files`` and one note on those skipped (None when none were);
    refuses fewer than :data:`MIN_PHOTOS`."""
    photos, skipped = read_photos(files, min_side, max_side)
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
    """``length`` examples of ``effect`` on square windows of ``photos``.

    ``size`` is the network's input size for a whole picture (its short side) and
    ``render_size`` the short side the effect renders the whole picture at; training sees
    windows of ``window`` network pixels of such pictures (``size`` by default). The effect
    renders only the window, as a tile of the whole picture (its ``scale`` and ``origin``),
    so a window of half the size costs a quarter of the rendering.

    Item ``i`` is the same every time it is asked for (drawn from a generator seeded with
    ``seed`` and ``i``), so runs are reproducible and validation sets fixed; it is rendered on
    first use and kept. A window and parameters whose example is nearly blank are drawn
    again (a flat patch of sky shows nothing of the parameters), as the benchmarks redraw
    blank references. Returns dicts of ``photo`` and ``example`` ``(3, window, window)`` in [0, 1]
    and ``params`` ``(P,)``.
    """

    def __init__(
        self,
        photos: list[torch.Tensor],
        effect: str,
        size: int,
        length: int,
        sampling: str = "uniform",
        seed: int = 0,
        render_size: int | None = None,
        window: int | None = None,
    ) -> None:
        if sampling not in SAMPLINGS:
            raise WiseError(f"unknown sampling {sampling!r}; use one of {', '.join(SAMPLINGS)}")
        if not photos:
            raise WiseError("no photos to make examples from")
        self.photos, self.effect_name, self.size, self.length = photos, effect, size, length
        self.render_size = render_size or size
        self.window = min(window or size, size)
        self.tile = max(8, round(self.window * self.render_size / size))
        """The window's side in rendered pixels."""
        self.sampling, self.seed = sampling, seed
        self._effect = effects.create(effect).eval()
        self._kept: dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = {}

    def __len__(self) -> int:
        return self.length

    @property
    def render_scale(self) -> float:
        """The effect's scale of the whole picture (pixels per reference pixel)."""
        return self.render_size / REFERENCE_SHORT_SIDE

    def _tile(self, photo: torch.Tensor, generator: torch.Generator) -> tuple[torch.Tensor, tuple[int, int]]:
        """A random window of a random picture of ``photo`` (a square part of ``SCALE_RANGE``
        of its short side, at ``render_size``), at ``tile`` pixels, and its origin in the picture."""
        low, high = SCALE_RANGE
        fraction = low + (high - low) * float(torch.rand((), generator=generator))
        zoom = self.render_size / (fraction * min(photo.shape[-2:]))
        side = min(min(photo.shape[-2:]), max(8, round(self.tile / zoom)))
        top = int(torch.randint(0, photo.shape[-2] - side + 1, (), generator=generator))
        left = int(torch.randint(0, photo.shape[-1] - side + 1, (), generator=generator))
        tile = _as_floats(photo[..., top : top + side, left : left + side])
        size = self.tile
        tile = F.interpolate(tile, size=(size, size), mode="area" if side > size else "bilinear")
        if float(torch.rand((), generator=generator)) < 0.5:
            tile = tile.flip(-1)
        return tile.clamp(0.0, 1.0), (round(top * zoom), round(left * zoom))

    def _params(self, generator: torch.Generator) -> torch.Tensor:
        count = len(self._effect.param_specs)
        if self.sampling == "uniform":
            return torch.rand(count, generator=generator) - 0.5
        names = sorted(self._effect.presets)
        preset = self._effect.preset(names[int(torch.randint(0, len(names), (), generator=generator))])
        return (preset + PRESET_SPREAD * torch.randn(count, generator=generator)).clamp(-0.5, 0.5)

    def reduced(self, image: torch.Tensor) -> torch.Tensor:
        if image.shape[-1] == self.window:
            return image
        return F.interpolate(image, size=(self.window, self.window), mode="area")

    def render(self, tile: torch.Tensor, params: torch.Tensor, origin: tuple[int, int] = (0, 0)) -> torch.Tensor:
        """The effect on a tile at ``tile`` pixels as part of the whole picture, without autograd."""
        with torch.no_grad():
            return self._effect(tile, params, scale=self.render_scale, origin=origin).clamp(0.0, 1.0)

    def _make(self, index: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        generator = torch.Generator().manual_seed((self.seed * 1_000_003 + index) % 2**63)
        photo = self.photos[int(torch.randint(0, len(self.photos), (), generator=generator))]
        for _ in range(MAX_DRAWS):
            tile, origin = self._tile(photo, generator)
            params = self._params(generator)
            example = self.render(tile, params[None], origin)
            if float(example.std()) >= MIN_REFERENCE_CONTRAST:
                break
        return _as_bytes(self.reduced(tile))[0], _as_bytes(self.reduced(example))[0], params

    def cache_key(self) -> str:
        """A digest of everything the examples depend on: settings, photos and package version."""
        digest = hashlib.sha256()
        fields = (wise.__version__, self.effect_name, self.size, self.render_size, self.window, self.length)
        digest.update(repr((*fields, self.sampling, self.seed)).encode())
        for photo in self.photos:
            digest.update(repr(tuple(photo.shape)).encode())
            digest.update(photo.contiguous().numpy().tobytes())
        return digest.hexdigest()

    def cache_path(self, folder: str | Path) -> Path:
        return Path(folder) / f"{self.effect_name}-{self.cache_key()[:16]}.safetensors"

    def load_cache(self, folder: str | Path) -> int:
        """Take the examples rendered by an earlier run with the same settings and photos from
        ``folder`` (a safetensors file, checked); returns how many were taken."""
        path = self.cache_path(folder)
        if not path.is_file():
            return 0
        tensors, metadata = read_safetensors(path, "example cache", MAX_CACHE_BYTES)
        shapes = {"photo": (self.window,) * 2, "example": (self.window,) * 2}
        indices = tensors.get("index")
        if metadata.get("key") != self.cache_key() or indices is None or indices.dim() != 1:
            raise WiseError(f"{path}: an example cache of other settings; remove it or choose another --cache folder")
        count = indices.shape[0]
        for name, shape in shapes.items():
            found = tensors.get(name)
            if found is None or found.dtype != torch.uint8 or tuple(found.shape) != (count, 3, *shape):
                raise WiseError(f"{path}: a damaged example cache; remove it")
        params = tensors.get("params")
        if params is None or tuple(params.shape) != (count, len(self._effect.param_specs)):
            raise WiseError(f"{path}: a damaged example cache; remove it")
        for row, index in enumerate(indices.tolist()):
            if 0 <= index < self.length:
                self._kept[index] = (tensors["photo"][row], tensors["example"][row], params[row].float())
        return count

    def save_cache(self, folder: str | Path) -> Path:
        """Write the examples rendered so far into ``folder`` for later runs (atomically)."""
        indices = sorted(self._kept)
        path = self.cache_path(folder)
        path.parent.mkdir(parents=True, exist_ok=True)
        tensors = {
            "index": torch.tensor(indices, dtype=torch.int64),
            "photo": torch.stack([self._kept[i][0] for i in indices]),
            "example": torch.stack([self._kept[i][1] for i in indices]),
            "params": torch.stack([self._kept[i][2] for i in indices]),
        }
        with atomic_path(path) as tmp:
            Path(tmp).write_bytes(st_save(tensors, metadata={"key": self.cache_key()}))
        return path

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        if not 0 <= index < self.length:
            raise IndexError(index)
        if index not in self._kept:
            self._kept[index] = self._make(index)
        photo, example, params = self._kept[index]
        return {"photo": _as_floats(photo), "example": _as_floats(example), "params": params}
