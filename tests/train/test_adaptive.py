"""Synthetic content-adaptive pairs: the region rules find what they claim, and the pairs written."""

from __future__ import annotations

import io
import json
import math
import re
import signal
from pathlib import Path

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from PIL import Image
from skimage import data, measure

from wise import effects
from wise.effects.base import window_scale
from wise.errors import WiseError
from wise.filters import gaussian_blur
from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.io import read_image
from wise.paramfile import load_params
from wise.train import adaptive, regions
from wise.train.adaptive import REACHABLE, AdaptiveSettings, pair_counts, write_pairs
from wise.train.pairs import check_pairs, pair_files
from wise.train.tasks import TASKS

SIDE = 128
"""Side of the synthetic pictures: the rules' windows are a few pixels wide at this size."""
BAND = 16
"""Pixels on either side of a synthetic picture's boundary where a region may go either way
(the rules' windows and the feather reach this far at :data:`SIDE`)."""
RULES = {name: task.rule for name, task in TASKS.items()}
TASK_KEYS = {
    "task", "effect", "preset", "parameter", "inside", "preset_value", "size", "scale", "count", "seed", "test_share",
    "min_change", "rule", "train_photos", "test_photos",
}  # fmt: skip
PAIR_SIZE = 64
CHANGE_BAND = 12
"""Pixels beyond the region's feathered border where a target may still differ from the preset's
rendering (the effect's filters reach across the border)."""
PAIR_COUNT = 8


def _generator(seed: int = 0) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def _columns(profile: torch.Tensor) -> torch.Tensor:
    """A grey ``(1, 3, SIDE, SIDE)`` picture whose columns follow ``profile`` ``(SIDE,)``."""
    return profile.view(1, 1, 1, SIDE).expand(1, 3, SIDE, SIDE).clone()


def _halves(soft: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The left and right halves of ``soft``, without the band around the middle."""
    return soft[..., : SIDE // 2 - BAND], soft[..., SIDE // 2 + BAND :]


def _photo(name: str, side: int = 128) -> torch.Tensor:
    picture = getattr(data, name)()
    if picture.ndim == 2:
        picture = np.stack([picture] * 3, axis=-1)
    tensor = torch.from_numpy(picture[..., :3].copy()).permute(2, 0, 1)[None].float() / 255.0
    return F.interpolate(tensor, size=(side, side), mode="area")


def test_contours_region_covers_the_side_of_weak_edges() -> None:
    x = torch.arange(SIDE, dtype=torch.float32)
    square_wave = torch.sign(torch.sin(2.0 * math.pi * x / 12.0))
    strong, weak = 0.5 + 0.4 * square_wave, 0.5 + 0.05 * square_wave
    soft = regions.low_contrast_region(_columns(torch.where(x < SIDE // 2, strong, weak)))
    left, right = _halves(soft)
    assert float(right.mean()) > 0.95 and float(left.max()) == 0.0


def test_details_region_covers_the_textured_half() -> None:
    texture = 0.5 + 0.25 * (2.0 * torch.rand(1, 1, SIDE, SIDE, generator=_generator()) - 1.0)
    flat = torch.full_like(texture, 0.5)
    picture = torch.where(torch.arange(SIDE).view(1, 1, 1, SIDE) < SIDE // 2, flat, texture).expand(1, 3, -1, -1)
    left, right = _halves(regions.fine_texture_region(picture.contiguous()))
    assert float(right.mean()) > 0.95 and float(left.max()) == 0.0


def test_details_region_is_empty_without_fine_texture() -> None:
    smooth = gaussian_blur(torch.rand(1, 3, SIDE, SIDE, generator=_generator(1)), 40.0)
    assert float(regions.fine_texture_region(smooth).max()) == 0.0


def test_background_region_excludes_a_sharp_distinct_disk() -> None:
    generator = _generator(2)
    blurred = gaussian_blur(0.3 + 0.4 * torch.rand(1, 3, SIDE, SIDE, generator=generator), 24.0)
    background = blurred * torch.tensor([0.6, 0.8, 0.6]).view(1, 3, 1, 1)
    red = torch.tensor([0.85, 0.15, 0.1]).view(1, 3, 1, 1)
    disk_texture = red + 0.15 * (2.0 * torch.rand(1, 1, SIDE, SIDE, generator=generator) - 1.0)
    ys, xs = torch.meshgrid(torch.arange(SIDE).float(), torch.arange(SIDE).float(), indexing="ij")
    distance = ((ys - SIDE / 2) ** 2 + (xs - SIDE / 2) ** 2).sqrt().view(1, 1, SIDE, SIDE)
    radius = 0.3 * SIDE
    soft = regions.background_region(torch.where(distance < radius, disk_texture, background).clamp(0.0, 1.0))
    assert float(soft[distance < radius - BAND / 2].max()) == 0.0
    assert float(soft[distance > radius + BAND / 2].mean()) > 0.9


@pytest.mark.parametrize("task", sorted(TASKS))
@pytest.mark.parametrize("name", ["astronaut", "coffee"])
def test_regions_are_smooth_soft_maps_without_speckle(task: str, name: str) -> None:
    soft = RULES[task](_photo(name))
    assert soft.shape == (1, 1, SIDE, SIDE) and float(soft.min()) >= 0.0 and float(soft.max()) <= 1.0
    # feathered: no jumps between neighbours, and exactly 0 or 1 away from the border
    step = max(float(soft.diff(dim=-1).abs().max()), float(soft.diff(dim=-2).abs().max()))
    assert step < 0.5
    assert float(((soft == 0.0) | (soft == 1.0)).float().mean()) > 0.5
    # no speckle: every part of the true region and every hole in it is a sizeable blob
    inside = regions.true_region(soft)[0, 0].numpy()
    scale = SIDE / REFERENCE_SHORT_SIDE
    smallest = 0.5 * (regions.SMALLEST_PART * scale) ** 2
    for mask in (inside, ~inside):
        areas = [part.area for part in measure.regionprops(measure.label(mask, connectivity=1))]
        assert all(area >= smallest for area in areas), (task, name, sorted(areas)[:3])


@pytest.mark.parametrize("task", sorted(TASKS))
def test_rules_are_functions_of_each_picture_alone(task: str) -> None:
    one, other = _photo("chelsea", 96), _photo("rocket", 96)
    together = RULES[task](torch.cat([one, other]))
    assert torch.equal(together[:1], RULES[task](one)) and torch.equal(together[1:], RULES[task](other))
    assert torch.equal(RULES[task](one), RULES[task](one.clone()))


def test_rules_find_the_same_region_at_any_size() -> None:
    small, large = _photo("astronaut", 128), _photo("astronaut", 384)
    for task, rule in RULES.items():
        reduced = F.interpolate(rule(large), size=(128, 128), mode="area")
        agree = float((regions.true_region(reduced) == regions.true_region(rule(small))).float().mean())
        assert agree > 0.9, task


def test_otsu_threshold_separates_two_modes() -> None:
    low, high = torch.full((300,), 0.2), torch.full((100,), 0.9)
    values = torch.cat([low, high]) + 0.01 * torch.randn(400, generator=_generator())
    threshold = regions.otsu_threshold(values.view(1, 1, 20, 20)).flatten()
    assert torch.equal(values > threshold, torch.arange(400) >= 300)


def test_task_values_are_in_range_reachable_and_far_from_the_presets() -> None:
    for task in TASKS.values():
        assert len(task.description.split(". ")) == 1 and task.changes
        for effect_name, change in task.changes.items():
            effect = effects.create(effect_name)
            spec = effect.spec(change.parameter)
            normalized = spec.to_normalized(change.inside)
            assert spec.in_range(change.inside) and abs(normalized) <= REACHABLE
            preset = adaptive.task_preset(task, effect)
            assert preset in effect.presets
            moved = abs(change.inside - adaptive.preset_value(effect, preset, change.parameter)) / spec.span
            assert moved > 0.1, (task.name, effect_name)


def test_settings_refuse_what_a_task_cannot_do() -> None:
    with pytest.raises(WiseError, match="no parameter for the effect 'oilpaint'; supported effects: cartoon, xdog"):
        AdaptiveSettings("background", effect="oilpaint").resolve()
    with pytest.raises(WiseError, match="unknown task 'edges'; tasks: contours, details, background"):
        AdaptiveSettings("edges").resolve()
    with pytest.raises(WiseError, match="has no preset 'nope'"):
        AdaptiveSettings("details", preset="nope").resolve()
    assert AdaptiveSettings("contours").resolve()[2] == "portrait"
    assert AdaptiveSettings("details").resolve()[2] == "pencil"  # the task's own: half-toned
    assert AdaptiveSettings("details", preset="lines").resolve()[2] == "lines"
    assert AdaptiveSettings("details", effect="cartoon").resolve()[2] == "classic"


def test_pairs_are_shared_by_the_splits_and_spread_over_the_photos() -> None:
    splits = {"train": list("abcd"), "test": ["e"]}
    assert pair_counts(splits, 11) == {"train": [3, 2, 2, 2], "test": [2]}  # type: ignore[arg-type]
    assert pair_counts(splits, 2) == {"train": [1, 0, 0, 0], "test": [1]}  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def photos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Five readable photos (two with the stem ``astronaut``), an unreadable one and a small one."""
    root = tmp_path_factory.mktemp("photos")
    (root / "more").mkdir()
    for name in ("astronaut", "coffee", "chelsea", "rocket"):
        Image.fromarray(getattr(data, name)()).resize((72, 64)).save(root / f"{name}.png")
    Image.fromarray(data.camera()).resize((64, 80)).save(root / "more" / "astronaut.jpg")
    Image.fromarray(data.coffee()).resize((32, 32)).save(root / "more" / "tiny.png")
    (root / "notes.png").write_text("not an image")
    return root


def _make(
    folder: Path,
    photos: Path,
    seed: int = 1,
    count: int = PAIR_COUNT,
    task: str = "background",
    min_change: float = 0.0,
) -> dict:
    settings = AdaptiveSettings(task, count=count, size=PAIR_SIZE, seed=seed, min_change=min_change)
    with pytest.warns(UserWarning, match="skipped 2 unreadable or too small files"):
        return write_pairs(folder, settings, images=photos, out=io.StringIO())


@pytest.fixture(scope="module")
def pairs(tmp_path_factory: pytest.TempPathFactory, photos: Path) -> tuple[Path, dict]:
    folder = tmp_path_factory.mktemp("sets") / "pairs"
    return folder, _make(folder, photos)


def _names(folder: Path, split: str, sub: str) -> list[str]:
    return sorted(path.stem for path in (folder / split / sub).iterdir())


def test_layout_task_file_and_split_by_photo(pairs: tuple[Path, dict]) -> None:
    folder, summary = pairs
    task = json.loads((folder / "task.json").read_text())
    assert set(task) == TASK_KEYS
    assert task["task"] == "background" and task["effect"] == "xdog" and task["preset"] == "sketch"
    sketch_brightness = effects.create("xdog").presets["sketch"]["brightness"]
    assert (task["parameter"], task["inside"], task["preset_value"]) == ("brightness", 0.45, sketch_brightness)
    assert task["count"] == PAIR_COUNT and task["rule"] == TASKS["background"].description
    assert (task["size"], task["seed"], task["test_share"]) == (PAIR_SIZE, 1, 0.2)
    photos = {"astronaut.png", "coffee.png", "chelsea.png", "rocket.png", "more/astronaut.jpg"}
    train, test = set(task["train_photos"]), set(task["test_photos"])
    assert train | test == photos and not train & test and len(test) == 1
    assert summary["pairs"] == {"train": PAIR_COUNT - 2, "test": 2} and 0.0 < summary["mean_region"] < 1.0
    stems = {"train": set(), "test": set()}
    for split in ("train", "test"):
        names = _names(folder, split, "A")
        assert all(_names(folder, split, sub) == names for sub in ("B", "regions", "params"))
        assert all(re.fullmatch(r".+_\d{3}", name) for name in names)
        stems[split] = {name.rsplit("_", 1)[0] for name in names}
        listed = pair_files(folder, split)
        check_pairs(listed)
        for pair in listed:
            assert read_image(pair.photo).shape == (1, 3, PAIR_SIZE, PAIR_SIZE)
            region = np.asarray(Image.open(pair.region))
            assert region.ndim == 2 and set(np.unique(region)) <= {0, 255}
            assert load_params(pair.params, effects.create("xdog")).shape == (1, 8, PAIR_SIZE, PAIR_SIZE)
    assert not stems["train"] & stems["test"]
    # the two photos named astronaut are told apart
    assert len({stem for stem in stems["train"] | stems["test"] if stem.startswith("astronaut")}) == 2


def test_same_seed_same_pairs_other_seed_other_crops(pairs: tuple[Path, dict], photos: Path, tmp_path: Path) -> None:
    folder, _ = pairs
    again = tmp_path / "again"
    _make(again, photos)
    files = sorted(path.relative_to(folder) for path in folder.rglob("*") if path.is_file())
    assert files == sorted(path.relative_to(again) for path in again.rglob("*") if path.is_file())
    xdog = effects.create("xdog")
    for path in files:
        if path.suffix == ".safetensors":  # the metadata's order varies; the masks do not
            assert torch.equal(load_params(folder / path, xdog), load_params(again / path, xdog))
        else:
            assert (folder / path).read_bytes() == (again / path).read_bytes(), path
    other = tmp_path / "other"
    _make(other, photos, seed=2)
    crops = {path.name: path.read_bytes() for path in folder.glob("*/A/*.png")}
    others = {path.name: path.read_bytes() for path in other.glob("*/A/*.png")}
    common = set(crops) & set(others)
    assert common and all(crops[name] != others[name] for name in common)


def test_targets_differ_from_the_preset_only_in_the_region(pairs: tuple[Path, dict]) -> None:
    folder, _ = pairs
    effect = effects.create("xdog").eval()
    index = effect.param_names.index("brightness")
    preset = effect.preset("sketch")
    inside = effect.spec("brightness").to_normalized(TASKS["background"].change("xdog").inside)
    changed_inside = 0
    for pair in pair_files(folder, "train") + pair_files(folder, "test"):
        photo, target = read_image(pair.photo), read_image(pair.target)
        masks = load_params(pair.params, effect)
        departed = (masks[:, index : index + 1] - preset[index]).abs() > 1e-6
        others = torch.cat([masks[:, :index], masks[:, index + 1 :]], dim=1)
        assert torch.equal(others, torch.cat([preset[:index], preset[index + 1 :]]).view(1, -1, 1, 1).expand_as(others))
        soft = (masks[:, index : index + 1] - preset[index]) / (inside - preset[index])
        region = read_image(pair.region)[:, :1] > 0.5
        clear = (soft - regions.INSIDE).abs() > 1e-4
        assert torch.equal(region[clear], (soft > regions.INSIDE)[clear])
        with torch.no_grad():
            plain = effect(
                photo, preset.view(1, -1, 1, 1).expand_as(masks).contiguous(), scale=window_scale(*photo.shape[-2:])
            )
        plain = (plain.clamp(0.0, 1.0) * 255.0).round() / 255.0
        near = F.max_pool2d(departed.float(), 2 * CHANGE_BAND + 1, stride=1, padding=CHANGE_BAND) > 0
        difference = (target - plain).abs().amax(dim=1, keepdim=True)
        assert float(torch.where(near, 0.0, difference).max()) <= 1.0 / 255.0 + 1e-6
        changed_inside += int((difference[region] > 0.05).sum())
    assert changed_inside > 0


def test_ctrl_c_keeps_the_complete_pairs(photos: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    written = []
    save = adaptive.save_params

    def interrupted_on_the_third(path, *args, **kwargs):  # noqa: ANN001, ANN202 (stands in for save_params)
        written.append(path)
        if len(written) == 3:
            signal.raise_signal(signal.SIGINT)
        return save(path, *args, **kwargs)

    monkeypatch.setattr(adaptive, "save_params", interrupted_on_the_third)
    folder = tmp_path / "stopped"
    summary = _make(folder, photos)
    assert summary["interrupted"] and summary["count"] == 2
    task = json.loads((folder / "task.json").read_text())
    assert task["count"] == 2 and len(task["train_photos"]) + len(task["test_photos"]) == 2
    names = {split: _names(folder, split, "A") for split in ("train", "test")}
    assert sum(len(n) for n in names.values()) == 2
    for split, listed in names.items():
        assert all(_names(folder, split, sub) == listed for sub in ("B", "regions", "params"))
    assert not list(folder.rglob(".*.tmp"))


def test_too_few_photos_are_refused(photos: Path, tmp_path: Path) -> None:
    lonely = tmp_path / "lonely"
    lonely.mkdir()
    (lonely / "a.png").write_bytes((photos / "coffee.png").read_bytes())
    with pytest.raises(WiseError, match=f"1 readable photos of at least {PAIR_SIZE} pixels a side .* at least 2"):
        write_pairs(tmp_path / "out", AdaptiveSettings("details", size=PAIR_SIZE), images=lonely)
    assert not (tmp_path / "out").exists()


def test_pairs_whose_change_does_not_show_are_left_out(photos: Path, tmp_path: Path) -> None:
    everything = _make(tmp_path / "all", photos, min_change=1.0 - 1e-9)
    assert everything["pairs"] == {"train": 0, "test": 0} and everything["left_out"] == PAIR_COUNT
    visible = _make(tmp_path / "visible", photos, min_change=0.01)
    kept = visible["pairs"]["train"] + visible["pairs"]["test"]
    assert kept + visible["left_out"] == PAIR_COUNT and kept > 0
    xdog = effects.create("xdog")
    for photo in (tmp_path / "visible" / "train" / "A").iterdir():
        target = read_image(photo.parent.parent / "B" / photo.name)
        at_preset = xdog(read_image(photo), xdog.preset("sketch")[None], scale=1.0)
        assert float((target - at_preset).abs().mean()) >= 0.01 - 2 / 255
