"""Training examples made on the fly, the validation split and the losses."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from PIL import Image
from skimage import data

import wise
from wise.effects.base import window_scale
from wise.errors import WiseError
from wise.optimize.trials import MIN_REFERENCE_CONTRAST
from wise.train.data import ExampleDataset, checked_photos, photo_files, read_photos, split_files
from wise.train.losses import prediction_loss
from wise.train.sampler import GlobalBatchSampler


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
    assert dataset.tile == 48 and item["photo"].shape == item["example"].shape == item["target"].shape == (3, 12, 12)
    generator = torch.Generator().manual_seed(1 * 1_000_003 + 0)
    tile = dataset._picture(dataset._source(generator), generator)
    params = dataset._params(generator)  # the first draw: its example is not blank
    assert tile.shape[-2:] == (48, 48) and torch.equal(params, item["params"])
    effect = wise.effects.create("xdog")
    with torch.no_grad():
        as_part = dataset.reduced(effect(tile, params[None], scale=192 / 512).clamp(0, 1))[0]
        as_whole = dataset.reduced(effect(tile, params[None]).clamp(0, 1))[0]
        # at the reference scale: the network's 48 pixels are below the reference size
        at_network_size = effect(item["photo"][None], params[None], scale=window_scale(48, 48)).clamp(0, 1)[0]
    assert float((as_part - item["example"]).abs().max()) <= 1 / 255 + 1e-6
    assert float((as_whole - item["example"]).abs().mean()) > 0.01
    # the image-space loss's reference: the true parameters at the network's size, from the photo it sees
    assert float((at_network_size - item["target"]).abs().max()) <= 1 / 255 + 1e-6
    assert float((item["target"] - item["example"]).abs().mean()) > 0.01


def test_the_target_is_the_example_when_rendered_at_the_network_size(folder: Path) -> None:
    photos, _ = read_photos(photo_files(folder), min_side=64)
    item = ExampleDataset(photos, "watercolor", size=40, length=2, seed=2)[1]
    assert torch.equal(item["target"], item["example"])


def test_a_batch_is_rendered_together_and_equals_its_examples_one_by_one(folder: Path) -> None:
    photos, _ = read_photos(photo_files(folder), min_side=64)
    batch = ExampleDataset(photos, "oilpaint", size=32, length=8, seed=5).__getitems__([6, 1, 4])
    single = ExampleDataset(photos, "oilpaint", size=32, length=8, seed=5)
    for index, item in zip((6, 1, 4), batch):
        alone = single[index]
        assert torch.equal(item["params"], alone["params"]) and torch.equal(item["photo"], alone["photo"])
        assert float((item["example"] - alone["example"]).abs().max()) <= 1 / 255 + 1e-6


def test_the_fresh_stream_is_reproducible_from_its_seed_and_new_every_epoch(folder: Path) -> None:
    photos, _ = read_photos(photo_files(folder), min_side=64)
    settings = {"size": 32, "length": 8, "fresh": True, "procedural": 0.5, "augmentation": True, "sampling": "mixture"}
    first = ExampleDataset(photos, "cartoon", seed=9, **settings)
    again = ExampleDataset(photos, "cartoon", seed=9, **settings)
    other_seed = ExampleDataset(photos, "cartoon", seed=10, **settings)
    sampler = GlobalBatchSampler(8, 4, seed=9, fresh=True)
    epochs = []
    for epoch in (0, 1):
        sampler.set_epoch(epoch)
        epochs.append([index for batch in sampler for index in batch])
    assert sorted(epochs[0]) == list(range(8)) and sorted(epochs[1]) == list(range(8, 16))
    for index in (3, 12):
        a, b, c = first[index], again[index], other_seed[index]
        assert all(torch.equal(a[k], b[k]) for k in ("photo", "example", "target", "params"))
        assert not torch.equal(a["params"], c["params"])
    assert not torch.equal(first[3]["photo"], first[11]["photo"])
    assert not first._kept, "a fresh stream keeps no examples"
    fixed = ExampleDataset(photos, "cartoon", seed=9, size=32, length=8)
    with pytest.raises(IndexError):
        fixed[8]


def test_examples_on_dead_leaves_pictures_need_no_photos() -> None:
    dataset = ExampleDataset([], "xdog", size=32, length=4, seed=0, procedural=1.0, augmentation=True)
    item = dataset[2]
    assert item["photo"].shape == (3, 32, 32) and float(item["example"].std()) >= MIN_REFERENCE_CONTRAST
    assert len(dataset._pictures) == 1 and float(item["photo"].std()) > 0.02
    with pytest.raises(WiseError, match="no photos"):
        ExampleDataset([], "xdog", size=32, length=4, procedural=0.5)
    with pytest.raises(WiseError, match="procedural share"):
        ExampleDataset([], "xdog", size=32, length=4, procedural=1.5)


def test_mixture_sampling_draws_both_uniform_and_near_preset_parameters(folder: Path) -> None:
    photos, _ = read_photos(photo_files(folder), min_side=64)
    dataset = ExampleDataset(photos, "xdog", size=32, length=200, sampling="mixture", seed=0)
    presets = torch.stack([dataset._effect.preset(name) for name in dataset._effect.presets])
    draws = torch.stack([dataset._params(torch.Generator().manual_seed(i)) for i in range(200)])
    nearest = torch.cdist(draws, presets).min(dim=1).values
    near_share = float((nearest < 0.6).float().mean())
    assert 0.2 < near_share < 0.6, near_share  # uniform draws are rarely this close to a preset in 8 dimensions


def test_rendered_examples_are_cached_for_later_runs(folder: Path, tmp_path: Path) -> None:
    photos, _ = read_photos(photo_files(folder), min_side=64)
    first = ExampleDataset(photos, "cartoon", size=32, length=5, seed=4)
    rendered = [first[i] for i in (0, 3)]
    path = first.save_cache(tmp_path)
    again = ExampleDataset(photos, "cartoon", size=32, length=5, seed=4)
    assert again.load_cache(tmp_path) == 2 and again.cache_path(tmp_path) == path
    for index, item in zip((0, 3), rendered):
        assert all(torch.equal(item[k], again[index][k]) for k in ("photo", "example", "target", "params"))
    other = ExampleDataset(photos, "cartoon", size=32, length=5, seed=5)
    assert other.load_cache(tmp_path) == 0 and other.cache_path(tmp_path) != path
    assert path is not None
    path.rename(other.cache_path(tmp_path))
    with pytest.raises(WiseError, match="an example cache of other settings"):
        other.load_cache(tmp_path)
    assert ExampleDataset(photos, "cartoon", size=32, length=5, seed=4, fresh=True).save_cache(tmp_path) is None


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


def test_worker_processes_render_the_same_fresh_batches(folder: Path) -> None:
    from wise.train.module import ExampleData

    photos, _ = read_photos(photo_files(folder), min_side=64)
    train = ExampleDataset(photos, "xdog", size=32, length=8, seed=2, fresh=True, procedural=0.5)
    validation = ExampleDataset(photos, "xdog", size=32, length=4, seed=3)
    here = next(iter(ExampleData(train, validation, batch=4, seed=2).train_dataloader()))
    elsewhere = next(iter(ExampleData(train, validation, batch=4, seed=2, workers=1).train_dataloader()))
    assert all(torch.equal(here[key], elsewhere[key]) for key in ("photo", "example", "target", "params"))
