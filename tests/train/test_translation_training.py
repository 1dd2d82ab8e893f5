"""Image-to-image translation trained through the effect (WISE Sec. 5.2): a tiny run of every
variant of the paper's ablation, the data layouts it reads, and editing a trained model's masks."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from tests.images import drawing_pairs
from wise.errors import WiseError
from wise.ppn.predictor import LocalPredictor
from wise.train.local import LocalGAN
from wise.train.local_run import train_local
from wise.train.local_settings import LocalSettings, prepare_local, start_params
from wise.train.pairs import PairDataset, pair_files

SIZE = 48
TINY = {"depth": 3, "width": 4, "max_width": 8, "post_width": 8, "discriminator_width": 8}
VARIANTS = {
    "cnn only (resnet)": {"effect": "none", "post": "resnet"},
    "cnn only (unet)": {"effect": "none", "post": "unet", "dropout": True},
    "preset + xdog + resnet": {"effect": "xdog", "post": "resnet", "ppn": "preset"},
    "ppn + xdog + resnet": {"effect": "xdog", "post": "resnet"},
    "ppn + xdog": {"effect": "xdog"},
}


@pytest.fixture(scope="module")
def pairs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return drawing_pairs(tmp_path_factory.mktemp("drawings"), size=SIZE)


def _settings(pairs: Path, variant: dict, **extra: object) -> LocalSettings:
    options = {
        "pairs": str(pairs), "load_size": SIZE, "crop_size": SIZE, "steps": 40, "lr": 2e-3, "lr_schedule": "constant",
        "gan_weight": 0.0, "accelerator": "cpu", "checkpoint_every": 1000, "batch": 2, **TINY,
    }  # fmt: skip
    return LocalSettings(**{**options, **variant, **extra})


def _l1(predictor: LocalPredictor, pairs: list) -> float:
    from wise.io import read_image

    losses = [float((predictor.stages(read_image(p.photo)).result - read_image(p.target)).abs().mean()) for p in pairs]
    return sum(losses) / len(losses)


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_a_tiny_run_of_every_variant_learns_and_writes_its_model(pairs: Path, tmp_path: Path, variant: str) -> None:
    settings = _settings(pairs, VARIANTS[variant])
    train, test = prepare_local(settings, tmp_path / "run", resume=False)
    torch.manual_seed(0)
    untrained = LocalGAN(
        settings.effect, start_params(settings).tolist(), {"depth": 3, "width": 4, "max_width": 8},
        post=settings.post, post_width=8, ppn_kind=settings.ppn, dropout=settings.dropout,
    )  # fmt: skip
    summary = train_local(settings, str(tmp_path / "run"), out=open(os.devnull, "w"), pairs=(train, test))
    assert summary["steps"] == 40 and not summary["interrupted"]
    predictor = LocalPredictor(tmp_path / "run" / "model.safetensors", settings.effect)
    expected = "unet" if settings.post == "none" else "translator"
    assert predictor.info.architecture == expected and predictor.info.kind == "local"
    dataset = PairDataset(train, None, None, flip=False)
    with torch.no_grad():
        before = sum(
            float((untrained.generate({**_batch(dataset[i])}).result[0] - dataset[i]["target"]).abs().mean())
            for i in range(len(dataset))
        ) / len(dataset)
    after = _l1(predictor, train)
    assert after < before, (variant, before, after)
    report = (tmp_path / "run" / "report.html").read_text()
    assert ("effect stage" in report) == (settings.post != "none" and settings.effect != "none")


def _batch(item: dict) -> dict:
    return {"photo": item["photo"][None], "scale": item["scale"], "origin": item["origin"][None]}


def test_the_apdrawing_layout_is_read_as_distributed(tmp_path: Path) -> None:
    root = drawing_pairs(tmp_path / "APDrawingDB", size=32, layout="apdrawing")
    train = pair_files(root, "train")
    test = pair_files(root, "test", direction="AtoB")
    assert [p.name for p in train] == ["astronaut", "chelsea", "coffee", "rocket"]
    assert len(test) == 2 and test[0].target is None, "one side-by-side image per pair"
    item = PairDataset(train, None, None, flip=False)[0]
    assert item["photo"].shape == item["target"].shape == (3, 32, 32)
    assert float(item["target"].std(dim=0).max()) == 0.0, "the right half is the grey drawing"
    swapped = PairDataset(pair_files(root / "data", "train", "BtoA"), None, None, flip=False, direction="BtoA")[0]
    assert torch.equal(swapped["photo"], item["target"]) and torch.equal(swapped["target"], item["photo"])


def test_variants_that_cannot_learn_are_refused_before_any_work(pairs: Path, tmp_path: Path) -> None:
    cases = {
        "the effect 'none' trains a CNN alone": {"effect": "none"},
        "--ppn preset with --post none has nothing to learn": {"effect": "xdog", "ppn": "preset"},
        "unknown post-processing network 'vgg'": {"effect": "xdog", "post": "vgg"},
        "--init starts the PPN from a local model": {"effect": "none", "post": "unet", "init": "m.safetensors"},
    }
    for message, variant in cases.items():
        with pytest.raises(WiseError, match=message):
            prepare_local(_settings(pairs, variant), tmp_path / "run", resume=False)
    assert not (tmp_path / "run").exists()


def test_painting_a_trained_models_masks_changes_its_drawing_where_painted_and_only_there(
    pairs: Path, tmp_path: Path
) -> None:
    settings = _settings(pairs, VARIANTS["ppn + xdog + resnet"], steps=60)
    train_local(settings, str(tmp_path / "run"), out=open(os.devnull, "w"))
    predictor = LocalPredictor(tmp_path / "run" / "model.safetensors", "xdog")
    from wise.io import read_image

    photo = read_image(pair_files(pairs, "test")[0].photo)
    made = predictor.stages(photo)
    edited = made.masks.clone()
    shading = predictor.effect.param_names.index("shading")
    edited[:, shading, 8:24, 8:24] = 0.45
    repainted = predictor.finish(photo, edited)
    change = (repainted.result - made.result).abs().mean(dim=1)[0]
    far = change.clone()
    far[:36, :36] = 0.0
    assert float(change[8:24, 8:24].mean()) > 0.02, "the painted square shows in the final drawing"
    assert float(far.mean()) < 0.1 * float(change[8:24, 8:24].mean()), "and little changes far from it"
