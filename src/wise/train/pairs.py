"""Paired images for conditional-GAN training (pix2pix style): listing, checking and reading.

A pairs folder holds one folder per split (``train``, ``val``, ``test``) in one of two layouts,
detected per split and read as they are:

- separate files: ``<split>/A/<name>.<ext>`` photos and ``<split>/B/<name>.<ext>`` targets, matched
  by file stem (``a.jpg`` pairs with ``a.png``);
- pix2pix's aligned layout: ``<split>/<name>.<ext>``, each one image of even width with A on the
  left half and B on the right half.

APDrawingDB (Yi et al. 2019) is read as it is distributed: its root holds ``data/train`` and
``data/test`` in the aligned layout (beside ``landmark/`` and ``mask/``, which are not used), so
either the root or its ``data`` folder may be passed.

Either layout may hold ``<split>/regions/<name>.<ext>`` grey region masks (of the size of one A
image) and the separate layout ``<split>/params/<name>.safetensors`` (only listed here). Hidden
files (names starting with a dot) are left out.

:func:`pair_files` lists a split from file names (and, for the aligned layout, image headers),
:func:`check_pairs` reads every header, and :class:`PairDataset` reads the pairs with pix2pix's
training jitter (resize, random square crop, horizontal flip), applied alike to photo, target
and region.

Direction: :func:`pair_files` orients each :class:`Pair` (``photo`` is the input side's file) and
records it in ``Pair.direction``; :class:`PairDataset`'s ``direction`` is the orientation of what
it returns, whatever the pairs' own, so passing the same direction to both swaps once.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from PIL import Image
from torch.utils.data import Dataset

from wise.effects.base import window_scale
from wise.errors import WiseError, size_text
from wise.files import open_regular
from wise.io import IMAGE_SUFFIXES, MAX_IMAGE_BYTES, READ_FORMATS, pixel_limit, read_image
from wise.io.common import one_line
from wise.io.formats import webp_size
from wise.io.limits import check_pixels
from wise.io.read import _decoding
from wise.train.choices import DIRECTIONS

SPLITS = ("train", "val", "test")
"""Split folders of a pairs folder (pix2pix's names)."""
PHOTO_FOLDER, TARGET_FOLDER = "A", "B"
REGION_FOLDER = "regions"
PARAMS_FOLDER = "params"
PARAMS_SUFFIX = ".safetensors"
MAX_NAMED = 5
"""Most files a message names; it gives the count of all."""
FLIP_PROBABILITY = 0.5
EXIF_ORIENTATION = 0x0112
TRANSPOSING_ORIENTATIONS = frozenset({5, 6, 7, 8})
"""EXIF orientations that swap width and height."""
_HEAD_BYTES = 64


@dataclass(frozen=True)
class Pair:
    """The files of one pair; ``target`` is None in the aligned layout (both halves in ``photo``).

    ``photo`` is the input side's file as :func:`pair_files` oriented the pair (``direction``:
    ``"AtoB"`` makes it the A file, ``"BtoA"`` the B file; in the aligned layout ``photo`` is the
    AB file either way and ``direction`` says which half is the input). ``region`` is the
    pair's region mask and ``params`` its parameter file, when the split has them.
    """

    name: str
    photo: Path
    target: Path | None
    region: Path | None
    params: Path | None = None
    direction: str = "AtoB"


def _check_direction(direction: str) -> None:
    if direction not in DIRECTIONS:
        raise WiseError(f"unknown direction {direction!r}; use {' or '.join(DIRECTIONS)}")


def _named(items: list[str]) -> str:
    """Up to :data:`MAX_NAMED` of ``items`` and how many more there are."""
    shown = ", ".join(items[:MAX_NAMED])
    more = len(items) - MAX_NAMED
    return f"{shown} and {more} more" if more > 0 else shown


def _plural(count: int, word: str) -> str:
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


def _images(folder: Path) -> dict[str, Path]:
    """The image files directly in ``folder`` by stem; refuses two files with one stem."""
    by_stem: dict[str, list[Path]] = {}
    for path in sorted(folder.iterdir()):
        if path.name.startswith(".") or path.suffix.lower() not in IMAGE_SUFFIXES or not path.is_file():
            continue
        by_stem.setdefault(path.stem, []).append(path)
    clashes = [" and ".join(p.name for p in paths) for paths in by_stem.values() if len(paths) > 1]
    if clashes:
        raise WiseError(
            f"{folder}: {_plural(len(clashes), 'name')} used by two files ({_named(clashes)}); keep one file per name"
        )
    return {stem: paths[0] for stem, paths in by_stem.items()}


DATA_FOLDER = "data"
"""APDrawingDB's folder of the aligned splits."""


def dataset_root(folder: str | Path) -> Path:
    """The folder that holds the splits: ``folder``, or its ``data/`` when ``folder`` is the root
    of a data set distributed like APDrawingDB (splits only in ``data/``)."""
    root = Path(folder)
    inner = root / DATA_FOLDER
    if not any((root / s).is_dir() for s in SPLITS) and any((inner / s).is_dir() for s in SPLITS):
        return inner
    return root


def _split_folder(folder: str | Path, split: str) -> Path:
    root = dataset_root(folder)
    if split not in SPLITS:
        raise WiseError(f"unknown split {split!r}; use one of {', '.join(SPLITS)}")
    if not root.is_dir():
        raise WiseError(f"{root}: not a directory of image pairs; pass a folder with train/ (and test/) in it")
    path = root / split
    if not path.is_dir():
        found = [s for s in SPLITS if (root / s).is_dir()]
        present = f"it has {', '.join(found)}" if found else f"it has none of {', '.join(SPLITS)}"
        raise WiseError(f"{root}: no {split}/ folder ({present}); add {split}/ with A/ and B/ or AB images in it")
    return path


def _unmatched(split: Path, photos: dict[str, Path], targets: dict[str, Path]) -> None:
    only_a = sorted(set(photos) - set(targets))
    only_b = sorted(set(targets) - set(photos))
    if not only_a and not only_b:
        return
    parts = []
    if only_a:
        parts.append(f"{_plural(len(only_a), 'photo')} in A/ without a target in B/ ({_named(only_a)})")
    if only_b:
        parts.append(f"{_plural(len(only_b), 'target')} in B/ without a photo in A/ ({_named(only_b)})")
    raise WiseError(f"{split}: {' and '.join(parts)}; add the missing files or remove the extra ones")


def _regions(split: Path, names: list[str]) -> dict[str, Path]:
    """The region masks of ``names`` by stem (none without a regions/ folder); all or none."""
    folder = split / REGION_FOLDER
    if not folder.is_dir():
        return {}
    regions = _images(folder)
    missing = sorted(set(names) - set(regions))
    extra = sorted(set(regions) - set(names))
    if missing or extra:
        parts = []
        if missing:
            parts.append(f"{_plural(len(missing), 'pair')} without a region mask ({_named(missing)})")
        if extra:
            parts.append(f"{_plural(len(extra), 'region mask')} without a pair ({_named(extra)})")
        raise WiseError(f"{folder}: {' and '.join(parts)}; give every pair a region mask or remove {REGION_FOLDER}/")
    return regions


def _params(split: Path) -> dict[str, Path]:
    folder = split / PARAMS_FOLDER
    if not folder.is_dir():
        return {}
    return {p.stem: p for p in folder.iterdir() if p.suffix == PARAMS_SUFFIX and p.is_file()}


def pair_files(folder: str | Path, split: str, direction: str = "AtoB") -> list[Pair]:
    """All pairs of ``split`` in ``folder``, sorted by name, oriented by ``direction``.

    Raises :class:`WiseError` (one line naming the problem and what to do) for a missing folder
    or split, a split without images, photos without a target and targets without a photo, two
    files with one stem in a folder, region masks missing for some pairs, and aligned (AB)
    images of odd width. Whether the files are readable is left to :func:`check_pairs`.
    """
    return pairs_in(_split_folder(folder, split), direction)


def pairs_in(path: Path, direction: str = "AtoB") -> list[Pair]:
    """All pairs of one split folder ``path`` (see :func:`pair_files`)."""
    _check_direction(direction)
    a_dir, b_dir = path / PHOTO_FOLDER, path / TARGET_FOLDER
    if a_dir.is_dir() or b_dir.is_dir():
        if not (a_dir.is_dir() and b_dir.is_dir()):
            have, lack = (PHOTO_FOLDER, TARGET_FOLDER) if a_dir.is_dir() else (TARGET_FOLDER, PHOTO_FOLDER)
            raise WiseError(f"{path}: has {have}/ but no {lack}/; add {lack}/ with the matching images")
        photos, targets = _images(a_dir), _images(b_dir)
        if not photos and not targets:
            raise WiseError(f"{path}: no images in {PHOTO_FOLDER}/ and {TARGET_FOLDER}/; add the image pairs")
        _unmatched(path, photos, targets)
        names = sorted(photos)
        regions, params = _regions(path, names), _params(path)
        swap = direction == "BtoA"
        return [
            Pair(
                name=name,
                photo=targets[name] if swap else photos[name],
                target=photos[name] if swap else targets[name],
                region=regions.get(name),
                params=params.get(name),
                direction=direction,
            )
            for name in names
        ]
    aligned = _images(path)
    if not aligned:
        raise WiseError(
            f"{path}: no images; add {PHOTO_FOLDER}/ and {TARGET_FOLDER}/ folders of matching images "
            "or images with A on the left half and B on the right half"
        )
    names = sorted(aligned)
    regions = _regions(path, names)
    pairs = [Pair(name, aligned[name], None, regions.get(name), None, direction) for name in names]
    _refuse_odd_widths(path, pairs)
    return pairs


def _refuse_odd_widths(split: Path, pairs: list[Pair]) -> None:
    """Refuse aligned images of odd width (those whose header cannot be read are left to check_pairs)."""
    odd = []
    for pair in pairs:
        try:
            width, height = image_size(pair.photo)
        except WiseError:
            continue
        if width % 2:
            odd.append(f"{pair.photo.name} ({size_text(width, height)})")
    if odd:
        raise WiseError(
            f"{split}: {_plural(len(odd), 'AB image')} of odd width ({_named(odd)}); an AB image is A and B "
            "side by side, so its width must be even: crop one column"
        )


def image_size(path: Path) -> tuple[int, int]:
    """``(width, height)`` of the image file as :func:`read_image` reads it (EXIF orientation
    applied), from its header where it can; raises :class:`WiseError` when the file is unreadable
    or over the pixel limit."""
    limit = pixel_limit()
    try:
        f = open_regular(path, "image", MAX_IMAGE_BYTES)
        with f, _decoding():
            head = f.read(_HEAD_BYTES)
            if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
                size = webp_size(head)
                if size is None:
                    raise ValueError("no image size in the WebP header")
                check_pixels(str(path), *size, limit)  # libwebp allocates the canvas when Pillow opens it
            f.seek(0)
            with Image.open(f) as img:
                if img.format not in READ_FORMATS:
                    raise ValueError(f"unsupported format {img.format}")
                width, height = img.size
                if img.getexif().get(EXIF_ORIENTATION) in TRANSPOSING_ORIENTATIONS:
                    width, height = height, width
    except WiseError:
        raise
    except Exception:  # not readable from the header: a full read gives the size or the reason
        height, width = read_image(path, limit).shape[-2:]
        return width, height
    if width == 0 or height == 0:
        raise WiseError(f"{path}: the image is empty ({size_text(width, height)} pixels)")
    check_pixels(str(path), width, height, limit)
    return width, height


def _reason(error: WiseError, path: Path) -> str:
    """The message of ``error`` without the path it starts with."""
    text = one_line(error)
    prefix = f"{path}: "
    return text[len(prefix) :] if text.startswith(prefix) else text


def check_pairs(pairs: list[Pair]) -> None:
    """Read every header of ``pairs`` and refuse, in one :class:`WiseError` line naming up to
    :data:`MAX_NAMED` of each, unreadable files and pairs whose photo, target and region sizes
    differ (an AB image's halves of odd width count as differing)."""
    unreadable: list[str] = []
    mismatched: list[str] = []
    for pair in pairs:
        sizes: dict[str, tuple[int, int]] = {}
        for role, path in (("photo", pair.photo), ("target", pair.target), ("region", pair.region)):
            if path is None:
                continue
            try:
                sizes[role] = image_size(path)
            except WiseError as e:
                unreadable.append(f"{path} ({_reason(e, path)})")
        if "photo" not in sizes:
            continue
        if pair.target is None:
            width, height = sizes["photo"]
            if width % 2:
                mismatched.append(f"{pair.photo} (AB image of odd width {size_text(width, height)})")
                continue
            sizes["photo"] = (width // 2, height)
        if len(set(sizes.values())) > 1:
            listed = ", ".join(f"{role} {size_text(*size)}" for role, size in sizes.items())
            mismatched.append(f"{pair.name} ({listed})")
    parts = []
    if unreadable:
        parts.append(f"{_plural(len(unreadable), 'unreadable image')}: {_named(unreadable)}")
    if mismatched:
        parts.append(f"{_plural(len(mismatched), 'pair')} of differing sizes: {_named(mismatched)}")
    if parts:
        raise WiseError(f"{'; '.join(parts)}; replace or remove these files")


def _resize(image: torch.Tensor, size: tuple[int, int], soft_mask: bool = False) -> torch.Tensor:
    """``(1, C, H, W)`` at ``size`` (height, width): antialiased reduction, bilinear enlargement, in [0, 1]."""
    if tuple(image.shape[-2:]) == size:
        return image
    reducing = size[0] < image.shape[-2] or size[1] < image.shape[-1]
    if soft_mask:
        resized = F.interpolate(image, size=size, mode="bilinear", align_corners=False, antialias=reducing)
    elif reducing:
        resized = F.interpolate(image, size=size, mode="area")
    else:
        resized = F.interpolate(image, size=size, mode="bilinear", align_corners=False)
    return resized.clamp(0.0, 1.0)


def _seed(*values: int) -> int:
    """A 63-bit generator seed from ``values``, different for different tuples."""
    digest = hashlib.blake2b(repr(values).encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") >> 1


class PairDataset(Dataset):
    """``(photo, target)`` tensors of one split, with pix2pix's training jitter.

    Each item resizes the whole picture so that its short side is ``load_size`` (keeping the
    aspect ratio; None: no resize), takes a random ``crop_size`` square (None: the whole
    picture, so batches need pictures of one size) and, when ``flip``, flips it horizontally
    with probability 1/2; photo, target and region go through the same resize, crop and flip.
    The draws come from a generator seeded with ``(seed, epoch, index)``: an item is the same
    in any worker process and batch, and changes with :meth:`set_epoch`. The epoch lives in
    shared memory, so a DataLoader's persistent workers see it when it is set before the
    epoch's iterator is made.

    ``direction`` is the orientation returned (``"BtoA"``: B is the photo), whatever the one
    the pairs were listed with. Items are dicts: ``photo`` and ``target`` ``(3, h, w)``
    float32 in [0, 1], ``region`` ``(1, h, w)`` in [0, 1] when the pair has one, ``scale``
    (the effect's scale of the resized whole picture: :func:`wise.effects.base.window_scale`),
    ``origin`` (y, x) long: the crop's top-left in the resized whole picture, after a flip in
    the flipped whole picture (x = width - left - crop, the crop being the window at
    ``origin`` of the mirrored picture), and ``name``.
    """

    def __init__(
        self,
        pairs: list[Pair],
        load_size: int | None,
        crop_size: int | None,
        flip: bool,
        seed: int = 0,
        direction: str = "AtoB",
    ) -> None:
        _check_direction(direction)
        for what, value in (("load size", load_size), ("crop size", crop_size)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
                raise WiseError(f"the {what} must be a positive whole number of pixels or None, got {value!r}")
        if load_size is not None and crop_size is not None and crop_size > load_size:
            raise WiseError(f"the crop size {crop_size} is larger than the load size {load_size}; reduce the crop")
        if not pairs:
            raise WiseError("no image pairs to train on")
        self.pairs, self.load_size, self.crop_size = list(pairs), load_size, crop_size
        self.flip, self.seed, self.direction = flip, seed, direction
        self._epoch = torch.zeros((), dtype=torch.int64).share_memory_()

    def __len__(self) -> int:
        return len(self.pairs)

    @property
    def epoch(self) -> int:
        return int(self._epoch)

    def set_epoch(self, epoch: int) -> None:
        """Draw the jitter of ``epoch`` from now on (in this process and the DataLoader's workers)."""
        self._epoch.fill_(int(epoch))

    def _read(self, pair: Pair) -> tuple[torch.Tensor, torch.Tensor]:
        """Photo and target ``(1, 3, H, W)`` of ``pair`` in this data set's direction."""
        if pair.target is None:
            both = read_image(pair.photo)
            width = both.shape[-1]
            if width % 2:
                raise WiseError(
                    f"{pair.photo}: an AB image of odd width {width}; its width must be even: crop one column"
                )
            a, b = both[..., : width // 2], both[..., width // 2 :]
            return (b, a) if self.direction == "BtoA" else (a, b)
        photo, target = read_image(pair.photo), read_image(pair.target)
        if photo.shape != target.shape:
            photo_size = size_text(photo.shape[-1], photo.shape[-2])
            target_size = size_text(target.shape[-1], target.shape[-2])
            raise WiseError(
                f"{pair.photo} ({photo_size}) and {pair.target} ({target_size}): a pair of differing sizes; "
                "make them the same size"
            )
        return (target, photo) if pair.direction != self.direction else (photo, target)

    def _region(self, pair: Pair, size: tuple[int, int]) -> torch.Tensor | None:
        if pair.region is None:
            return None
        region = read_image(pair.region).mean(dim=1, keepdim=True)
        if tuple(region.shape[-2:]) != size:
            raise WiseError(
                f"{pair.region}: a region mask of {size_text(region.shape[-1], region.shape[-2])} for a pair of "
                f"{size_text(size[1], size[0])}; make it the pair's size"
            )
        return region

    def _loaded_size(self, height: int, width: int) -> tuple[int, int]:
        """The whole picture's size after the resize to ``load_size``."""
        if self.load_size is None:
            return height, width
        short = min(height, width)
        factor = self.load_size / short
        if height <= width:
            return self.load_size, max(self.load_size, round(width * factor))
        return max(self.load_size, round(height * factor)), self.load_size

    def __getitem__(self, index: int) -> dict[str, torch.Tensor | float | str]:
        if not 0 <= index < len(self.pairs):
            raise IndexError(index)
        pair = self.pairs[index]
        photo, target = self._read(pair)
        region = self._region(pair, tuple(photo.shape[-2:]))
        height, width = self._loaded_size(*photo.shape[-2:])
        images = [_resize(photo, (height, width)), _resize(target, (height, width))]
        if region is not None:
            images.append(_resize(region, (height, width), soft_mask=True))
        generator = torch.Generator().manual_seed(_seed(self.seed, self.epoch, index))
        top = left = 0
        if self.crop_size is not None:
            crop = self.crop_size
            if crop > min(height, width):
                raise WiseError(
                    f"{pair.photo}: {size_text(width, height)} pixels (after the resize) is smaller than the "
                    f"crop size {crop}; use a smaller crop or set a load size"
                )
            top = int(torch.randint(0, height - crop + 1, (), generator=generator))
            left = int(torch.randint(0, width - crop + 1, (), generator=generator))
            images = [image[..., top : top + crop, left : left + crop] for image in images]
        window_width = images[0].shape[-1]
        if self.flip and float(torch.rand((), generator=generator)) < FLIP_PROBABILITY:
            images = [image.flip(-1) for image in images]
            left = width - left - window_width
        item: dict[str, torch.Tensor | float | str] = {
            "photo": images[0][0].contiguous(),
            "target": images[1][0].contiguous(),
            "scale": window_scale(height, width),
            "origin": torch.tensor([top, left], dtype=torch.int64),
            "name": pair.name,
        }
        if region is not None:
            item["region"] = images[2][0].contiguous()
        return item
