"""Local parameter prediction trained as a conditional GAN: the discriminator, the losses, a
tiny training run, and the model file of a local network."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import torch

from tests.images import xdog_pairs
from wise import effects
from wise.ppn.modelfile import load_model
from wise.train.discriminator import PatchDiscriminator, adversarial_loss
from wise.train.local import LocalGAN
from wise.train.local_run import train_local
from wise.train.local_settings import LocalSettings, prepare_local, start_params
from wise.train.losses import total_variation
from wise.train.pairs import PairDataset, pair_files


@pytest.fixture(scope="module")
def pairs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return xdog_pairs(tmp_path_factory.mktemp("pairs"), size=64)


def test_the_patch_discriminator_judges_patches_given_the_photo() -> None:
    torch.manual_seed(0)
    discriminator = PatchDiscriminator(8)
    photo, image = torch.rand(1, 3, 256, 256), torch.rand(1, 3, 256, 256)
    logits = discriminator(photo, image)
    assert logits.shape == (1, 1, 30, 30), "70x70 patches of a 256-pixel picture: 30x30 (pix2pix)"
    other_photo = discriminator(torch.rand(1, 3, 256, 256), image)
    assert not torch.allclose(logits, other_photo), "conditional: the photo changes the judgement"


def test_adversarial_losses_and_total_variation() -> None:
    logits = torch.tensor([[[[2.0, -1.0]]]])
    assert adversarial_loss("lsgan", logits, True) == pytest.approx(((2 - 1) ** 2 + (-1 - 1) ** 2) / 2)
    assert adversarial_loss("vanilla", logits, False) > adversarial_loss("vanilla", logits, True)
    flat = torch.full((1, 2, 8, 8), 0.3)
    assert float(total_variation(flat)) == 0.0
    step = flat.clone()
    step[..., 4:] = -0.2
    assert float(total_variation(step)) == pytest.approx(0.5 / 7)


def test_start_comes_from_the_task_preset(pairs: Path) -> None:
    xdog = effects.create("xdog")
    assert torch.equal(start_params(LocalSettings("xdog", str(pairs))), xdog.preset("portrait"))
    assert torch.equal(start_params(LocalSettings("xdog", str(pairs), start="sketch")), xdog.preset("sketch"))


def _l1(module: LocalGAN, dataset: PairDataset) -> float:
    losses = []
    with torch.no_grad():
        for index in range(len(dataset)):
            item = dataset[index]
            batch = {"photo": item["photo"][None], "scale": item["scale"], "origin": item["origin"][None]}
            made = module.generate(batch).result
            losses.append(float((made[0] - item["target"]).abs().mean()))
    return sum(losses) / len(losses)


def test_a_tiny_gan_run_lowers_the_l1_term_and_writes_a_local_model(pairs: Path, tmp_path: Path) -> None:
    settings = LocalSettings(
        "xdog", str(pairs), depth=3, width=8, max_width=16, discriminator_width=8, load_size=64, crop_size=64,
        steps=60, lr=5e-3, lr_schedule="constant", accelerator="cpu", checkpoint_every=1000,
    )  # fmt: skip
    train, test = prepare_local(settings, tmp_path / "run", resume=False)
    torch.manual_seed(0)
    dataset = PairDataset(train, None, None, flip=False)
    untrained = LocalGAN("xdog", start_params(settings).tolist(), {"depth": 3, "width": 8, "max_width": 16})
    summary = train_local(settings, str(tmp_path / "run"), out=open(os.devnull, "w"), pairs=(train, test))
    assert summary["steps"] == 60 and not summary["interrupted"]
    network, info = load_model(tmp_path / "run" / "model.safetensors", "xdog", "local")
    assert info.kind == "local" and info.network == {"depth": 3, "width": 8, "max_width": 16} and info.size == 64
    trained = LocalGAN("xdog", start_params(settings).tolist(), info.network)
    trained.generator.load_state_dict(network.state_dict())
    before, after = _l1(untrained, dataset), _l1(trained, dataset)
    assert after < 0.85 * before, (before, after)
    shading = trained.effect.param_names.index("shading")
    item = dataset[0]
    masks = network(item["photo"][None])[0, shading]
    dark = item["region"][0] > 0.5
    assert masks[dark].mean() > masks[~dark].mean() + 0.1, "more shading where the targets have it"
    report = (tmp_path / "run" / "report.html").read_text()
    assert "Test pairs: photo, predicted mask, result, target" in report and "shading" in report


def test_pairs_of_another_effect_are_refused(pairs: Path, tmp_path: Path) -> None:
    from wise.errors import WiseError

    with pytest.raises(WiseError, match="pairs of the 'xdog' effect"):
        prepare_local(LocalSettings("cartoon", str(pairs)), tmp_path / "run", resume=False)
    assert len(pair_files(pairs, "test")) == 2


def test_init_starts_from_a_local_model_of_the_same_network(pairs: Path, tmp_path: Path) -> None:
    from wise.errors import WiseError
    from wise.ppn.modelfile import ModelInfo, save_model
    from wise.train.local_run import _module

    network_options = {"depth": 3, "width": 8, "max_width": 16}
    xdog = effects.create("xdog")
    donor = LocalGAN("xdog", xdog.preset("sketch").tolist(), network_options).generator
    torch.manual_seed(1)
    with torch.no_grad():
        for weight in donor.parameters():
            weight.add_(0.1 * torch.randn_like(weight))
    info = ModelInfo("xdog", "unet", xdog.param_names, 64, 64, kind="local", network=network_options)
    save_model(tmp_path / "donor.safetensors", donor, info)
    settings = LocalSettings("xdog", str(pairs), init=str(tmp_path / "donor.safetensors"), **network_options)
    started = _module(settings).generator
    for name, value in donor.state_dict().items():
        assert torch.equal(started.state_dict()[name], value), name
    fresh = _module(LocalSettings("xdog", str(pairs), **network_options)).generator
    assert not torch.equal(fresh.head.bias, donor.head.bias), "without --init the network starts anew"
    tiny = {"load_size": 64, "crop_size": 64, "steps": 2, "accelerator": "cpu", "gan_weight": 0.0}
    run = LocalSettings("xdog", str(pairs), init=settings.init, **network_options, **tiny)
    train_local(run, str(tmp_path / "tuned"), out=open(os.devnull, "w"))
    recorded = load_model(tmp_path / "tuned" / "model.safetensors", "xdog", "local")[1].settings
    assert recorded["init"] == "donor.safetensors", "the model names its start, not this machine's folders"
    wider = LocalSettings("xdog", str(pairs), init=settings.init, depth=3, width=16, max_width=16)
    with pytest.raises(WiseError, match="depth 3, max width 16, width 8; give the same --depth"):
        prepare_local(wider, tmp_path / "run", resume=False)
    with pytest.raises(WiseError, match="a model for 'xdog', not 'cartoon'"):
        from wise.train.local_settings import init_model

        init_model(LocalSettings("cartoon", str(pairs), init=settings.init, **network_options))


def test_the_preset_weight_keeps_the_masks_at_the_start_preset(pairs: Path, tmp_path: Path) -> None:
    departures = []
    for weight in (0.0, 200.0):  # strong enough to show on every machine (20 left it to chance)
        settings = LocalSettings(
            "xdog", str(pairs), depth=3, width=8, max_width=16, load_size=64, crop_size=64, steps=30, lr=5e-3,
            lr_schedule="constant", gan_weight=0.0, tv_weight=0.0, preset_weight=weight, accelerator="cpu",
            checkpoint_every=1000,
        )  # fmt: skip
        folder = tmp_path / f"run-{weight:g}"
        train_local(settings, str(folder), out=open(os.devnull, "w"))
        network, _ = load_model(folder / "model.safetensors", "xdog", "local")
        photo = PairDataset(pair_files(pairs, "test"), None, None, flip=False)[0]["photo"][None]
        with torch.no_grad():
            masks = network(photo)
        departures.append(float((masks - start_params(settings).view(1, -1, 1, 1)).abs().mean()))
    assert departures[1] < 0.5 * departures[0], departures
