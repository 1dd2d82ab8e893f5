"""Synthetic paired data sets for content-adaptive effects (``wise data adaptive``).

WISE (Lötzsch et al. 2022, Sec. 4.2) trains a local parameter prediction network to paint an
effect's parameter masks from the photo alone. To test that, a task's target is the effect at a
preset with ONE parameter changed inside a region that a hand-written rule of
:mod:`wise.train.regions` finds in the photo; the network is never told the rule.

Each pair is a random square crop of a photo (a random share :data:`CROP_SHARES` of its short
side at a random position, flipped horizontally half of the time) resized to the pairs' size.
The rule gives a soft region in [0, 1]; the parameter masks are the preset everywhere with the
task's parameter blended from the preset's value to the task's value by the soft region; the
effect renders the crop with them as the whole picture, at the scale training renders it at
(:func:`wise.effects.base.window_scale`: the reference scale for crops below 512 pixels).
Photos are split into training and test photos first, so all crops of a photo are in one
split. Layout (read by :mod:`wise.train.pairs`)::

    PAIRS/task.json                        the task (:func:`task_description`)
    PAIRS/<split>/A/<name>.png             photo crop
    PAIRS/<split>/B/<name>.png             target
    PAIRS/<split>/regions/<name>.png       true region (soft region > 0.5): 255 inside, 0 outside
    PAIRS/<split>/params/<name>.safetensors  the masks (normalized, local; wise.paramfile)

with ``<name>`` = ``<photo stem>_<k:03d>``, k counting the photo's crops.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import sys
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, TextIO

import torch
import torch.nn.functional as F

from wise import effects
from wise.effects.base import Effect, window_scale
from wise.errors import WiseError, WiseWarning
from wise.interrupt import ctrl_c
from wise.io import atomic_path, write_image, write_together
from wise.paramfile import save_params
from wise.train import regions
from wise.train.choices import ADAPTIVE_SPLITS, MIN_CHANGE, TASK_FILE
from wise.train.data import photo_files, read_photos, split_files
from wise.train.pairs import PARAMS_FOLDER, PARAMS_SUFFIX, PHOTO_FOLDER, REGION_FOLDER, TARGET_FOLDER
from wise.train.tasks import Change, Task, task_named

SPLITS = ADAPTIVE_SPLITS
FOLDERS = (PHOTO_FOLDER, TARGET_FOLDER, REGION_FOLDER, PARAMS_FOLDER)
MIN_PHOTOS = 2
"""Fewest readable photos: one for each split."""
CROP_SHARES = (0.5, 1.0)
"""A crop's side is a random share between these of the photo's short side."""
FLIP_PROBABILITY = 0.5
REACHABLE = 0.45
"""Largest normalized distance from the middle of a range a task's value may have: the local
network's output is ``tanh / 2`` (:mod:`wise.ppn.unet`), which reaches the ends only in the limit."""
BYTE = 255.0
NAME_DIGITS = 3
DISAMBIGUATOR_LENGTH = 6
"""Hexadecimal digits of a path's hash added to photo stems that several photos share."""
ATTEMPTS = 4
"""Crops tried for a pair before it is left out because the change never shows."""
DEFAULT_PRESETS = {"xdog": "portrait"}
"""An effect's default preset; the first one it declares for the others."""


def task_preset(task: Task, effect: Effect) -> str:
    """The preset a task starts from: its change's own for ``effect``, else :func:`default_preset`."""
    own = task.change(effect.name).preset
    return own if own is not None else default_preset(effect)


def default_preset(effect: Effect) -> str:
    """:data:`DEFAULT_PRESETS`' preset of ``effect``, else the first it declares."""
    name = DEFAULT_PRESETS.get(effect.name)
    if name in effect.presets:
        return name
    if not effect.presets:
        raise WiseError(f"effect {effect.name!r} has no presets to start from")
    return next(iter(effect.presets))


@dataclass(frozen=True)
class AdaptiveSettings:
    """What a pairs folder is made of (``task.json`` records all of it)."""

    task: str
    effect: str = "xdog"
    preset: str | None = None
    """None: :func:`task_preset`."""
    count: int = 200
    size: int = 256
    test_share: float = 0.2
    seed: int = 0
    min_change: float = MIN_CHANGE
    """Least mean absolute difference of a target from the preset's rendering (0: keep all)."""

    def resolve(self) -> tuple[Task, Effect, str, Change]:
        """Check the settings; the task, the effect, the preset's name and the change."""
        task = task_named(self.task)
        effect = effects.create(self.effect)
        change = task.change(effect.name)
        preset = self.preset if self.preset is not None else task_preset(task, effect)
        effect.preset(preset)
        for name, value, low in (("count", self.count, 2), ("size", self.size, 8)):
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise WiseError(f"the {name} must be a whole number of at least {low}, got {value!r}")
        if not 0.0 < self.test_share < 1.0:
            raise WiseError(f"the test share must be above 0 and below 1, got {self.test_share}")
        if not 0.0 <= self.min_change < 1.0:
            raise WiseError(f"the least change must be from 0 to below 1, got {self.min_change}")
        return task, effect, preset, change


@dataclass
class Photo:
    """A readable photo: its file, its name in ``task.json`` (the path below the photo folder)
    and the stem of its pairs' names; ``pixels`` 8-bit ``(1, 3, H, W)``."""

    path: Path
    name: str
    stem: str
    pixels: torch.Tensor = field(repr=False)


def _digest(*values: object) -> bytes:
    return hashlib.blake2b(repr(values).encode(), digest_size=8, person=b"wise-adaptive").digest()


def _stems(names: list[str]) -> list[str]:
    """Pair-name stems of photos by their relative paths: the file stem (without leading dots,
    which would hide the files), with a short hash of the path where several photos share it
    (compared without case, for file systems that ignore it)."""
    plain = [Path(name).stem.lstrip(".") or "photo" for name in names]
    shared = {stem.casefold() for stem in plain if sum(s.casefold() == stem.casefold() for s in plain) > 1}
    return [
        f"{stem}-{_digest(name).hex()[:DISAMBIGUATOR_LENGTH]}" if stem.casefold() in shared else stem
        for stem, name in zip(plain, names)
    ]


def load_photos(folder: str | Path, size: int) -> tuple[list[Photo], list[Path]]:
    """The readable photos under ``folder`` (searched recursively) with a short side of at least
    ``size``, reduced so that the smallest crop is ``size`` pixels, and the files skipped;
    refuses fewer than :data:`MIN_PHOTOS`."""
    root = Path(folder)
    files = photo_files(root)
    largest = math.ceil(size / CROP_SHARES[0])
    kept: list[Path] = []
    pixels: list[torch.Tensor] = []
    skipped: list[Path] = []
    for path in files:
        read, missed = read_photos([path], size, largest)
        kept += [path] * len(read)
        pixels += read
        skipped += missed
    if len(kept) < MIN_PHOTOS:
        raise WiseError(
            f"{root}: {len(kept)} readable photos of at least {size} pixels a side ({len(skipped)} skipped); "
            f"the pairs need at least {MIN_PHOTOS}, one for each split"
        )
    names = [path.relative_to(root).as_posix() for path in kept]
    return [Photo(p, n, s, x) for p, n, s, x in zip(kept, names, _stems(names), pixels)], skipped


def split_photos(photos: list[Photo], test_share: float, seed: int) -> dict[str, list[Photo]]:
    """Training and test photos (:func:`wise.train.data.split_files`: a seeded share, at least one
    photo in each split)."""
    train, test = split_files(photos, test_share, seed)  # type: ignore[arg-type]
    return {"train": train, "test": test}  # type: ignore[dict-item]


def pair_counts(splits: Mapping[str, list[Photo]], count: int) -> dict[str, list[int]]:
    """Pairs per photo of each split: the splits share ``count`` in proportion to their photos
    (at least one pair each), spread evenly over a split's photos."""
    photos = sum(len(p) for p in splits.values())
    test = min(count - 1, max(1, round(count * len(splits["test"]) / photos)))
    counts = {}
    for split, total in (("train", count - test), ("test", test)):
        share, extra = divmod(total, len(splits[split]))
        counts[split] = [share + (1 if i < extra else 0) for i in range(len(splits[split]))]
    return counts


def pair_name(photo: Photo, k: int) -> str:
    return f"{photo.stem}_{k:0{NAME_DIGITS}d}"


def random_crop(photo: torch.Tensor, size: int, seed: int) -> torch.Tensor:
    """A random square crop of the 8-bit ``photo`` ``(1, 3, H, W)`` (a share in
    :data:`CROP_SHARES` of its short side, random position, flipped with
    :data:`FLIP_PROBABILITY`), resized to ``size`` and rounded to 8-bit steps; ``(1, 3, size, size)``."""
    generator = torch.Generator().manual_seed(seed)
    low, high = CROP_SHARES
    short = min(photo.shape[-2:])
    share = low + (high - low) * float(torch.rand((), generator=generator))
    side = min(short, max(1, round(share * short)))
    top = int(torch.randint(0, photo.shape[-2] - side + 1, (), generator=generator))
    left = int(torch.randint(0, photo.shape[-1] - side + 1, (), generator=generator))
    crop = photo[..., top : top + side, left : left + side].to(torch.float32) / BYTE
    if side > size:
        crop = F.interpolate(crop, size=(size, size), mode="area")
    else:
        crop = F.interpolate(crop, size=(size, size), mode="bilinear", align_corners=False)
    if float(torch.rand((), generator=generator)) < FLIP_PROBABILITY:
        crop = crop.flip(-1)
    return (crop.clamp(0.0, 1.0) * BYTE).round() / BYTE


def preset_value(effect: Effect, preset: str, parameter: str) -> float:
    """The real value of ``parameter`` in ``preset`` (the default where the preset omits it)."""
    return float(effect.presets[preset].get(parameter, effect.spec(parameter).default))


def region_masks(effect: Effect, preset: str, change: Change, soft: torch.Tensor) -> torch.Tensor:
    """Normalized masks ``(B, P, H, W)``: ``preset`` everywhere, the changed parameter blended
    from the preset's value to ``change.inside`` by the soft region ``soft`` ``(B, 1, H, W)``."""
    values = effect.preset(preset).to(soft)
    index = effect.param_names.index(change.parameter)
    inside = effect.spec(change.parameter).to_normalized(change.inside)
    masks = values.view(1, -1, 1, 1).expand(soft.shape[0], -1, *soft.shape[-2:]).clone()
    masks[:, index : index + 1] = values[index] + (inside - values[index]) * soft
    return masks


def make_pair(effect: Effect, task: Task, preset: str, change: Change, crop: torch.Tensor) -> dict[str, torch.Tensor]:
    """The target, soft region and masks of a crop ``(1, 3, H, W)``: ``target`` ``(1, 3, H, W)``,
    ``soft`` ``(1, 1, H, W)``, ``masks`` ``(1, P, H, W)``, and ``change``: the mean absolute
    difference of the target from the preset's rendering (a scalar)."""
    scale = window_scale(*crop.shape[-2:])
    with torch.no_grad():
        soft = task.rule(crop)
        masks = region_masks(effect, preset, change, soft)
        target = effect(crop, masks, scale=scale).clamp(0.0, 1.0)
        at_preset = effect(crop, effect.preset(preset)[None], scale=scale).clamp(0.0, 1.0)
    return {"target": target, "soft": soft, "masks": masks, "change": (target - at_preset).abs().mean()}


def pair_paths(folder: Path, split: str, name: str) -> list[Path]:
    """The photo, target, region and parameter files of pair ``name``."""
    base = folder / split
    return [
        base / PHOTO_FOLDER / f"{name}.png",
        base / TARGET_FOLDER / f"{name}.png",
        base / REGION_FOLDER / f"{name}.png",
        base / PARAMS_FOLDER / f"{name}{PARAMS_SUFFIX}",
    ]


def _write_pair(folder: Path, split: str, name: str, crop: torch.Tensor, made: dict, effect: Effect) -> None:
    """The four files of a pair; on any error (Ctrl-C included) those already written are
    removed again, so that a pair is complete or absent."""
    paths = pair_paths(folder, split, name)
    writers = (
        lambda path: write_image(crop, path),
        lambda path: write_image(made["target"], path),
        lambda path: write_image(regions.true_region(made["soft"]).float(), path),
        lambda path: save_params(path, effect, made["masks"]),
    )
    write_together(list(zip(paths, writers)))


def task_description(
    settings: AdaptiveSettings, task: Task, effect: Effect, preset: str, change: Change, made: Mapping[str, list[str]]
) -> dict:
    """The contents of ``task.json``; ``made`` lists the photos with pairs in each split."""
    return {
        "task": task.name,
        "effect": effect.name,
        "preset": preset,
        "parameter": change.parameter,
        "inside": change.inside,
        "preset_value": preset_value(effect, preset, change.parameter),
        "size": settings.size,
        "scale": window_scale(settings.size, settings.size),
        "count": sum(len(names) for names in made.values()),
        "seed": settings.seed,
        "test_share": settings.test_share,
        "min_change": settings.min_change,
        "rule": task.description,
        "train_photos": sorted(set(made["train"])),
        "test_photos": sorted(set(made["test"])),
    }


def schedule_pairs(splits: Mapping[str, list[Photo]], counts: Mapping[str, list[int]]) -> list[tuple[str, Photo, int]]:
    """Every pair as (split, photo, k), in rounds over all photos (crop k of each photo before
    crop k + 1 of any), so that a set stopped early has pairs of both splits and many photos."""
    rounds = max(max(c, default=0) for c in counts.values())
    order = []
    for k in range(rounds):
        for split in SPLITS:
            order += [(split, photo, k) for photo, n in zip(splits[split], counts[split]) if k < n]
    return order


def write_pairs(
    folder: str | Path,
    settings: AdaptiveSettings,
    photos: list[Photo] | None = None,
    images: str | Path | None = None,
    out: TextIO = sys.stdout,
) -> dict:
    """Write the pairs of ``settings`` into ``folder`` from ``photos`` (or the photos under
    ``images``); returns the summary (``task.json``'s contents with ``pairs`` per split, the
    ``mean_region`` share and ``interrupted``). The first Ctrl-C stops after the pair being
    written; ``task.json`` then describes the pairs written. ``folder`` should hold no pairs yet
    (``wise data adaptive`` refuses one that does): a set of two runs would describe neither."""
    task, effect, preset, change = settings.resolve()
    if photos is None:
        if images is None:
            raise WiseError("no photos to make pairs of: pass photos or an images folder")
        photos, skipped = load_photos(images, settings.size)
        if skipped:
            warnings.warn(f"{images}: skipped {len(skipped)} unreadable or too small files", WiseWarning, stacklevel=2)
    effect = effect.eval()
    splits = split_photos(photos, settings.test_share, settings.seed)
    schedule = schedule_pairs(splits, pair_counts(splits, settings.count))
    root = Path(folder)
    created = [root / split for split in SPLITS if not (root / split).exists()]
    try:
        for split in SPLITS:
            for sub in FOLDERS:
                (root / split / sub).mkdir(parents=True, exist_ok=True)
        return _write_all(root, settings, task, effect, preset, change, photos, splits, schedule, out)
    except BaseException:
        # a failure (not the Ctrl-C that stops the work, which returns) leaves no split folders it made
        for path in created:
            shutil.rmtree(path, ignore_errors=True)
        raise


def _visible_pair(
    settings: AdaptiveSettings, effect: Effect, task: Task, preset: str, change: Change, photo: Photo, k: int
) -> tuple[dict[str, torch.Tensor] | None, torch.Tensor]:
    """Pair ``k`` of ``photo``: the first of :data:`ATTEMPTS` crops whose target differs from the
    preset's rendering by at least ``settings.min_change`` (None when none does)."""
    for attempt in range(ATTEMPTS):
        key = (settings.seed, photo.name, k) if attempt == 0 else (settings.seed, photo.name, k, attempt)
        crop = random_crop(photo.pixels, settings.size, int.from_bytes(_digest(*key), "little") >> 1)
        pair = make_pair(effect, task, preset, change, crop)
        if float(pair["change"]) >= settings.min_change:
            return pair, crop
    return None, crop


def _write_all(
    root: Path,
    settings: AdaptiveSettings,
    task: Task,
    effect: Effect,
    preset: str,
    change: Change,
    photos: list[Photo],
    splits: Mapping[str, list[Photo]],
    schedule: list[tuple[str, Photo, int]],
    out: TextIO,
) -> dict:
    """The loop of :func:`write_pairs` over ``schedule``, then ``task.json`` and the summary."""
    made: dict[str, list[str]] = {split: [] for split in SPLITS}
    shares: list[float] = []
    print(
        f"making {len(schedule)} pairs of {len(photos)} photos: {effect.name} {preset}, "
        f"{change.parameter} {preset_value(effect, preset, change.parameter):g} -> {change.inside:g} where {task.name} "
        f"({len(splits['train'])} training and {len(splits['test'])} test photos)",
        file=out,
        flush=True,
    )
    pending: tuple[str, str, str, float] | None = None
    # the pair being written: split, photo, pair name and region share
    left_out = 0

    def record(split: str, photo: str, name: str, share: float) -> None:
        made[split].append(photo)
        shares.append(share)

    with ctrl_c(out) as interruption:
        try:
            for split, photo, k in schedule:
                if interruption.received:
                    break
                pair, crop = _visible_pair(settings, effect, task, preset, change, photo, k)
                if pair is None:
                    left_out += 1
                    continue
                pending = (split, photo.name, pair_name(photo, k), float(regions.region_share(pair["soft"])[0]))
                _write_pair(root, split, pending[2], crop, pair, effect)
                record(*pending)
                pending = None
        except KeyboardInterrupt:
            # a pair is complete or absent (_write_pair); one complete but not yet recorded counts
            if pending is not None and all(path.is_file() for path in pair_paths(root, pending[0], pending[2])):
                record(*pending)
            print(f"interrupted: {len(shares)} of {len(schedule)} pairs written", file=out, flush=True)
        interruption.hold()
        description = task_description(settings, task, effect, preset, change, made)
        with atomic_path(root / TASK_FILE) as tmp:
            Path(tmp).write_text(json.dumps(description, indent=2) + "\n")
    summary = {
        **description,
        "pairs": {split: len(made[split]) for split in SPLITS},
        "mean_region": sum(shares) / len(shares) if shares else 0.0,
        "left_out": left_out,
        "interrupted": interruption.received,
    }
    print(
        f"{summary['pairs']['train']} training and {summary['pairs']['test']} test pairs in {root}; "
        f"mean region share {summary['mean_region']:.0%}; {left_out} left out where the change did not show",
        file=out,
        flush=True,
    )
    return summary
