"""Training examples made on the fly, the validation split and the losses."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from PIL import Image
from skimage import data

import wise
from wise.errors import WiseError
from wise.train.data import ExampleDataset, checked_photos, photo_files, read_photos, split_files
from wise.train.losses import prediction_loss


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("photos")
    (root / "nested").mkdir()
    Image.fromarray(data.astronaut()).resize((96, 80)).save(root / "a.png")
    Image.fromarray(data.rocket()).resize((90, 70)).save(root / "nested" / "b.jpg")
    Image.fromarray(data.camera()).resize((70, 70)).save(root / "c.png")
    (root / "broken.png").write_text("not an image")
    (root / "notes.txt").write_text("ignored")
    return root


def test_photos_are_found_recursively_and_unreadable_ones_skipped(folder: Path) -> None:
    files = photo_files(folder)
    assert [p.name for p in files] == ["a.png", "broken.png", "c.png", "b.jpg"]
    photos, skipped = read_photos(files, min_side=64)
    assert len(photos) == 3 and [p.name for p in skipped] == ["broken.png"]
    with pytest.raises(WiseError, match="not a directory"):
        photo_files(folder / "missing")
    with pytest.raises(
        WiseError, match="3 readable photos of at least 64 pixels a side \\(1 skipped\\); training needs at least 4"
    ):
        checked_photos(folder, files, 64)


def test_validation_photos_are_never_training_photos(folder: Path) -> None:
    files = photo_files(folder)
    train, validation = split_files(files, 0.25, seed=0)
    assert len(validation) == 1 and not set(train) & set(validation) and len(train) + 1 == len(files)


@pytest.mark.parametrize("sampling", ["uniform", "presets"])
def test_examples_are_reproducible_renders_of_random_crops(folder: Path, sampling: str) -> None:
    photos, _ = read_photos(photo_files(folder), min_side=64)
    dataset = ExampleDataset(photos, "xdog", size=48, length=6, sampling=sampling, seed=3)
    first, again, other = dataset[2], dataset[2], dataset[3]
    assert first["photo"].shape == first["example"].shape == (3, 48, 48)
    assert torch.equal(first["example"], again["example"]) and torch.equal(first["params"], again["params"])
    assert not torch.equal(first["params"], other["params"])
    assert float(first["params"].abs().max()) <= 0.5
    effect = wise.effects.create("xdog")
    with torch.no_grad():
        rendered = effect(first["photo"][None], first["params"][None])[0]
    assert float((rendered.clamp(0, 1) - first["example"]).abs().mean()) < 0.01
    with pytest.raises(IndexError):
        dataset[6]


def test_windows_are_tiles_of_a_larger_rendering_reduced(folder: Path) -> None:
    photos, _ = read_photos(photo_files(folder), min_side=64)
    dataset = ExampleDataset(photos, "xdog", size=48, length=4, render_size=192, window=12, seed=1)
    item = dataset[0]
    assert dataset.tile == 48 and item["photo"].shape == item["example"].shape == (3, 12, 12)
    generator = torch.Generator().manual_seed(1 * 1_000_003 + 0)
    photo = photos[int(torch.randint(0, len(photos), (), generator=generator))]
    tile, origin = dataset._tile(photo, generator)
    params = dataset._params(generator)  # the first draw: its example is not blank
    assert tile.shape[-2:] == (48, 48) and torch.equal(params, item["params"])
    effect = wise.effects.create("xdog")
    with torch.no_grad():
        as_part = dataset.reduced(effect(tile, params[None], scale=192 / 512, origin=origin).clamp(0, 1))[0]
        as_whole = dataset.reduced(effect(tile, params[None]).clamp(0, 1))[0]
    assert float((as_part - item["example"]).abs().max()) <= 1 / 255 + 1e-6
    assert float((as_whole - item["example"]).abs().mean()) > 0.01


def test_rendered_examples_are_cached_for_later_runs(folder: Path, tmp_path: Path) -> None:
    photos, _ = read_photos(photo_files(folder), min_side=64)
    first = ExampleDataset(photos, "cartoon", size=32, length=5, seed=4)
    rendered = [first[i] for i in (0, 3)]
    path = first.save_cache(tmp_path)
    again = ExampleDataset(photos, "cartoon", size=32, length=5, seed=4)
    assert again.load_cache(tmp_path) == 2 and again.cache_path(tmp_path) == path
    for index, item in zip((0, 3), rendered):
        assert all(torch.equal(item[k], again[index][k]) for k in ("photo", "example", "params"))
    other = ExampleDataset(photos, "cartoon", size=32, length=5, seed=5)
    assert other.load_cache(tmp_path) == 0 and other.cache_path(tmp_path) != path
    path.rename(other.cache_path(tmp_path))
    with pytest.raises(WiseError, match="an example cache of other settings"):
        other.load_cache(tmp_path)


def test_losses_in_parameter_and_image_space() -> None:
    effect = wise.effects.create("xdog")
    photo = torch.rand(2, 3, 32, 32)
    truth = torch.rand(2, len(effect.param_specs)) - 0.5
    with torch.no_grad():
        example = effect(photo, truth)
    assert float(prediction_loss("param-l1", truth, truth)) == 0.0
    assert float(prediction_loss("image-l2", truth, truth, effect, photo, example)) < 1e-10
    predicted = torch.zeros_like(truth, requires_grad=True)
    loss = prediction_loss("image-l1", predicted, truth, effect, photo, example)
    loss.backward()
    assert float(loss.detach()) > 0 and predicted.grad is not None and float(predicted.grad.abs().sum()) > 0
    with pytest.raises(WiseError, match="unknown loss"):
        prediction_loss("perceptual", truth, truth)
