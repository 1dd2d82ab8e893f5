"""Training examples made on the fly: pictures, random global parameters, the effect's output.

Any folder of photos serves (searched recursively). Each example is a random window of a random
photo at a random scale (or, for a share of the examples, a procedural dead-leaves picture),
augmented (flips, quarter turns, exposure, contrast, saturation and gamma), with normalized
global parameters drawn uniformly over [-0.5, 0.5], around a random preset, or from a mixture
of both, and the example the effect renders from them without autograd. A validation split
keeps whole photos apart from training.

The effect renders at ``render_size`` (the resolution the network's predictions are used at,
512 pixels by default in ``wise train``) and photo and example are then reduced to the
network's ``size``: an effect rendered small is not the same picture as a large rendering
reduced (lines thin out, textures average), and the network sees the latter when it predicts.
Rendering dominates the cost of training, so training takes windows of the pictures (rendered
as tiles of the whole picture's scale) and renders the examples of a batch together. A fixed
set keeps each example (8-bit) for later epochs; a fresh stream draws new ones every epoch.
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
from wise.effects.base import window_scale
from wise.errors import WiseError
from wise.files import read_safetensors
from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.io import IMAGE_SUFFIXES, atomic_path, read_image
from wise.optimize.trials import MAX_DRAWS, MIN_REFERENCE_CONTRAST
from wise.train.augment import augment
from wise.train.choices import MIXTURE_PRESET_SHARE, SAMPLINGS
from wise.train.procedural import dead_leaves

MIN_PHOTOS = 4
"""Fewest readable photos a training run accepts."""
SCALE_RANGE = (0.6, 1.0)
"""A crop covers this fraction of the photo's short side (before it is resized to the training size)."""
PRESET_SPREAD = 0.1
"""Standard deviation (normalized units) of parameters drawn around a preset."""
REDRAWS_AT_ONCE = 4
"""Draws rendered together for an example whose first draw was blank."""
PROCEDURAL_PICTURES = 96
"""Dead-leaves pictures a data set draws its procedural windows from (each made on first use)."""
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
    """Examples of ``effect`` on square windows of ``photos``, ``length`` to an epoch.

    ``size`` is the network's input size for a whole picture (its short side) and
    ``render_size`` the short side the effect renders the whole picture at; training sees
    windows of ``window`` network pixels of such pictures (``size`` by default). The effect
    renders only the window, at the whole picture's ``scale``, so a window of half the size
    costs a quarter of the rendering. Examples asked for together (a batch, through
    ``__getitems__``) are rendered in one call of the effect.

    Example ``i`` is the same every time it is asked for (drawn from a generator seeded with
    ``seed`` and ``i``, whatever batch it comes in), so runs are reproducible and validation
    sets fixed. A fixed set (``fresh`` False) takes indices below ``length`` and keeps each
    example once rendered; a fresh stream takes any index (the sampler moves on by ``length``
    every epoch) and keeps nothing. A window and parameters whose example is nearly blank are
    drawn again (a flat patch of sky shows nothing of the parameters), as the benchmarks
    redraw blank references.

    Returns dicts of ``photo``, ``example`` and ``target`` ``(3, window, window)`` in [0, 1] and
    ``params`` ``(P,)``. ``target`` is what the effect makes of ``photo`` at the network's size,
    the reference of image-space losses: the example itself when ``render_size`` is ``size``.
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
        fresh: bool = False,
        procedural: float = 0.0,
        augmentation: bool = False,
    ) -> None:
        if sampling not in SAMPLINGS:
            raise WiseError(f"unknown sampling {sampling!r}; use one of {', '.join(SAMPLINGS)}")
        if not 0.0 <= procedural <= 1.0:
            raise WiseError(f"the procedural share must be in [0, 1], got {procedural}")
        if not photos and procedural < 1.0:
            raise WiseError("no photos to make examples from")
        self.photos, self.effect_name, self.size, self.length = photos, effect, size, length
        self.render_size = render_size or size
        self.window = min(window or size, size)
        self.tile = max(8, round(self.window * self.render_size / size))
        """The window's side in rendered pixels."""
        self.sampling, self.seed = sampling, seed
        self.fresh, self.procedural, self.augmentation = fresh, procedural, augmentation
        self._effect = effects.create(effect).eval()
        self._kept: dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]] = {}
        self._pictures: dict[int, torch.Tensor] = {}

    def __len__(self) -> int:
        return self.length

    @property
    def render_scale(self) -> float:
        """The effect's scale of the whole picture (pixels per reference pixel)."""
        return self.render_size / REFERENCE_SHORT_SIDE

    @property
    def network_scale(self) -> float:
        """The effect's scale of the whole picture at the network's size (the reference scale
        below the reference size: :func:`wise.effects.base.window_scale`)."""
        return window_scale(self.size, self.size)

    def _tile(self, photo: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """A random window of a random picture of ``photo`` (a square part of ``SCALE_RANGE``
        of its short side, at ``render_size``), at ``tile`` pixels."""
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
        return tile.clamp(0.0, 1.0)

    def _procedural(self, number: int) -> torch.Tensor:
        """Dead-leaves picture ``number`` of this data set (8-bit, as large as a photo is read)."""
        if number not in self._pictures:
            side = math.ceil(self.render_size / SCALE_RANGE[0])
            generator = torch.Generator().manual_seed((self.seed * 1_000_003 + number) % 2**63 ^ 0x5EED)
            self._pictures[number] = _as_bytes(dead_leaves(side, generator))
        return self._pictures[number]

    def _picture(self, photo: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """A window of ``photo``, augmented, in 8-bit steps."""
        picture = self._tile(photo, generator)
        if self.augmentation:
            picture = augment(picture, generator)
        return _as_floats(_as_bytes(picture))

    def _params(self, generator: torch.Generator) -> torch.Tensor:
        count = len(self._effect.param_specs)
        sampling = self.sampling
        if sampling == "mixture":
            sampling = "presets" if float(torch.rand((), generator=generator)) < MIXTURE_PRESET_SHARE else "uniform"
        if sampling == "uniform":
            return torch.rand(count, generator=generator) - 0.5
        names = sorted(self._effect.presets)
        preset = self._effect.preset(names[int(torch.randint(0, len(names), (), generator=generator))])
        return (preset + PRESET_SPREAD * torch.randn(count, generator=generator)).clamp(-0.5, 0.5)

    def reduced(self, image: torch.Tensor) -> torch.Tensor:
        if image.shape[-1] == self.window:
            return image
        return F.interpolate(image, size=(self.window, self.window), mode="area")

    def render(self, tile: torch.Tensor, params: torch.Tensor) -> torch.Tensor:
        """The effect on tiles at ``tile`` pixels as parts of the whole picture, without autograd."""
        with torch.no_grad():
            return self._effect(tile, params, scale=self.render_scale).clamp(0.0, 1.0)

    def _source(self, generator: torch.Generator) -> torch.Tensor:
        """The photo or dead-leaves picture an example is a window of."""
        if self.procedural > 0.0 and float(torch.rand((), generator=generator)) < self.procedural:
            return self._procedural(int(torch.randint(0, PROCEDURAL_PICTURES, (), generator=generator)))
        return self.photos[int(torch.randint(0, len(self.photos), (), generator=generator))]

    def _make(self, indices: list[int]) -> list[tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]]:
        """Examples ``indices`` (8-bit photo, example and target, and parameters), rendered together."""
        generators = [torch.Generator().manual_seed((self.seed * 1_000_003 + i) % 2**63) for i in indices]
        sources = [self._source(g) for g in generators]
        made: dict[int, tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = {}
        draws = [0] * len(indices)
        pending = list(range(len(indices)))
        while pending:
            # an example blank at its first draw is often blank again: draw several at once for it
            # (taking the first that is not blank keeps the result independent of the batching)
            candidates = [
                k for k in pending for _ in range(min(MAX_DRAWS - draws[k], 1 if draws[k] == 0 else REDRAWS_AT_ONCE))
            ]
            drawn = [(self._picture(sources[k], generators[k]), self._params(generators[k])) for k in candidates]
            pictures, params = torch.cat([d[0] for d in drawn]), torch.stack([d[1] for d in drawn])
            examples = self.render(pictures, params)
            blank = (examples.flatten(1).std(dim=1) < MIN_REFERENCE_CONTRAST).tolist()
            for row, k in enumerate(candidates):
                if k in made:
                    continue
                draws[k] += 1
                if not blank[row] or draws[k] == MAX_DRAWS:
                    made[k] = (pictures[row], examples[row], params[row])
            pending = [k for k in pending if k not in made]
        pictures = torch.stack([made[k][0] for k in range(len(indices))])
        examples = self.reduced(torch.stack([made[k][1] for k in range(len(indices))]))
        params = torch.stack([made[k][2] for k in range(len(indices))])
        photos = _as_bytes(self.reduced(pictures))
        if self.render_size == self.size:
            targets = _as_bytes(examples)
        else:
            with torch.no_grad():
                rendered = self._effect(_as_floats(photos), params, scale=self.network_scale)
            targets = _as_bytes(rendered)
        examples = _as_bytes(examples)
        return [(photos[k], examples[k], targets[k], params[k]) for k in range(len(indices))]

    def cache_key(self) -> str:
        """A digest of everything the examples depend on: settings, photos and package version."""
        digest = hashlib.sha256()
        sizes = (self.size, self.render_size, self.network_scale, self.window, self.length)
        fields = (wise.__version__, self.effect_name, *sizes)
        digest.update(repr((*fields, self.sampling, self.seed, self.procedural, self.augmentation)).encode())
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
        if self.fresh or not path.is_file():
            return 0
        tensors, metadata = read_safetensors(path, "example cache", MAX_CACHE_BYTES)
        indices = tensors.get("index")
        if metadata.get("key") != self.cache_key() or indices is None or indices.dim() != 1:
            raise WiseError(f"{path}: an example cache of other settings; remove it or choose another --cache folder")
        count = indices.shape[0]
        for name in ("photo", "example", "target"):
            found = tensors.get(name)
            shape = (count, 3, self.window, self.window)
            if found is None or found.dtype != torch.uint8 or tuple(found.shape) != shape:
                raise WiseError(f"{path}: a damaged example cache; remove it")
        params = tensors.get("params")
        if params is None or tuple(params.shape) != (count, len(self._effect.param_specs)):
            raise WiseError(f"{path}: a damaged example cache; remove it")
        for row, index in enumerate(indices.tolist()):
            if 0 <= index < self.length:
                kept = (tensors["photo"][row], tensors["example"][row], tensors["target"][row], params[row].float())
                self._kept[index] = kept
        return count

    def save_cache(self, folder: str | Path) -> Path | None:
        """Write the examples rendered so far into ``folder`` for later runs (atomically); a
        fresh stream keeps nothing to write (None)."""
        if self.fresh:
            return None
        indices = sorted(self._kept)
        path = self.cache_path(folder)
        path.parent.mkdir(parents=True, exist_ok=True)
        tensors = {"index": torch.tensor(indices, dtype=torch.int64)}
        for position, name in enumerate(("photo", "example", "target", "params")):
            tensors[name] = torch.stack([self._kept[i][position] for i in indices])
        with atomic_path(path) as tmp:
            Path(tmp).write_bytes(st_save(tensors, metadata={"key": self.cache_key()}))
        return path

    def __getitems__(self, indices: list[int]) -> list[dict[str, torch.Tensor]]:
        for index in indices:
            if index < 0 or (not self.fresh and index >= self.length):
                raise IndexError(index)
        if self.fresh:
            examples = self._make(list(indices))
        else:
            missing = sorted({i for i in indices if i not in self._kept})
            if missing:
                self._kept.update(zip(missing, self._make(missing)))
            examples = [self._kept[i] for i in indices]
        return [
            {"photo": _as_floats(photo), "example": _as_floats(example), "target": _as_floats(target), "params": params}
            for photo, example, target, params in examples
        ]

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        return self.__getitems__([index])[0]
