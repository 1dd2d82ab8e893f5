"""Paired photos and drawings of the synthetic artist (``wise data drawing``).

The crops, the split by photo and the order of the pairs are those of ``wise data adaptive``
(:mod:`wise.train.adaptive`); the target of a crop is :func:`wise.train.drawing.draw` of it.
Layout (pix2pix's, read by :mod:`wise.train.pairs`)::

    PAIRS/drawing.json         what the set is made of (:data:`DESCRIPTION_FILE`)
    PAIRS/<split>/A/<name>.png photo crop
    PAIRS/<split>/B/<name>.png drawing
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TextIO

from wise.errors import WiseError
from wise.interrupt import ctrl_c
from wise.io import atomic_path, write_image, write_together
from wise.train.adaptive import SPLITS, Photo, pair_counts, pair_name, random_crop, schedule_pairs, split_photos
from wise.train.choices import DESCRIPTION_FILE
from wise.train.drawing import draw
from wise.train.pairs import PHOTO_FOLDER, TARGET_FOLDER

ARTIST = "wise.train.drawing (outlines and hatching)"


@dataclass(frozen=True)
class DrawingSettings:
    count: int = 200
    size: int = 256
    test_share: float = 0.2
    seed: int = 0

    def check(self) -> None:
        for name, value, low in (("count", self.count, 2), ("size", self.size, 8)):
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise WiseError(f"the {name} must be a whole number of at least {low}, got {value!r}")
        if not 0.0 < self.test_share < 1.0:
            raise WiseError(f"the test share must be above 0 and below 1, got {self.test_share}")


def _stable_seed(*values: object) -> int:
    """A seed from ``values`` that is the same in every process (unlike ``hash``)."""
    digest = hashlib.blake2b(repr(values).encode(), digest_size=8, person=b"wise-drawing").digest()
    return int.from_bytes(digest, "little") >> 1


def _write_pair(root: Path, split: str, name: str, photo: Photo, settings: DrawingSettings, k: int) -> None:
    """Photo crop and drawing of pair ``name``; on any error (Ctrl-C included) a file already
    written is removed again, so that a pair is complete or absent."""
    crop = random_crop(photo.pixels, settings.size, _stable_seed(settings.seed, photo.name, k))
    drawing = draw(crop)
    write_together(
        [
            (root / split / PHOTO_FOLDER / f"{name}.png", lambda path: write_image(crop, path)),
            (root / split / TARGET_FOLDER / f"{name}.png", lambda path: write_image(drawing, path)),
        ]
    )


def write_drawing_pairs(
    folder: str | Path, settings: DrawingSettings, photos: list[Photo], out: TextIO = sys.stdout
) -> dict:
    """Write the pairs into ``folder`` (which should hold none); returns the summary (the
    contents of ``drawing.json`` and ``interrupted``). The first Ctrl-C stops after the pair
    being written; ``drawing.json`` then describes the pairs written."""
    settings.check()
    splits = split_photos(photos, settings.test_share, settings.seed)
    schedule = schedule_pairs(splits, pair_counts(splits, settings.count))
    root = Path(folder)
    for split in SPLITS:
        for sub in (PHOTO_FOLDER, TARGET_FOLDER):
            (root / split / sub).mkdir(parents=True, exist_ok=True)
    print(
        f"drawing {len(schedule)} pairs of {len(photos)} photos "
        f"({len(splits['train'])} training and {len(splits['test'])} test photos)",
        file=out,
        flush=True,
    )
    made: dict[str, list[str]] = {split: [] for split in SPLITS}
    with ctrl_c(out) as interruption:
        with contextlib.suppress(KeyboardInterrupt):
            for split, photo, k in schedule:
                if interruption.received:
                    break
                _write_pair(root, split, pair_name(photo, k), photo, settings, k)
                made[split].append(photo.name)
        interruption.hold()
        description = {
            "artist": ARTIST,
            **asdict(settings),
            "pairs": {split: len(names) for split, names in made.items()},
            "train_photos": sorted(set(made["train"])),
            "test_photos": sorted(set(made["test"])),
        }
        with atomic_path(root / DESCRIPTION_FILE) as tmp:
            Path(tmp).write_text(json.dumps(description, indent=2) + "\n")
    print(
        f"{description['pairs']['train']} training and {description['pairs']['test']} test pairs in {root}",
        file=out,
        flush=True,
    )
    return {**description, "interrupted": interruption.received}
