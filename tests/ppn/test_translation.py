"""The image-to-image generator N(O(I, P_L(I))) and its ablation variants."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from wise import effects
from wise.errors import WiseError
from wise.ppn.modelfile import ModelInfo, load_model, save_model
from wise.ppn.translation import Translator, build_translator, translator_options

PPN = {"depth": 3, "width": 4, "max_width": 8}
VARIANTS = {
    "cnn only (resnet)": ("none", translator_options("local", "resnet", 4)),
    "cnn only (unet)": ("none", translator_options("local", "unet", 4)),
    "preset + xdog + resnet": ("xdog", translator_options("preset", "resnet", 4, **PPN)),
    "ppn + xdog + resnet": ("xdog", translator_options("local", "resnet", 4, **PPN)),
    "ppn + xdog + unet, dropout": ("xdog", translator_options("local", "unet", 4, True, **PPN)),
}


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_every_variant_translates_a_photo_and_survives_its_model_file(variant: str, tmp_path: Path) -> None:
    effect_name, options = VARIANTS[variant]
    torch.manual_seed(0)
    start = effects.create("xdog").preset("portrait") if effect_name == "xdog" else None
    network = build_translator(effect_name, options, start).eval()
    photo = torch.rand(1, 3, 48, 64)
    masks, stage, result = network.stages(photo)
    assert result.shape == photo.shape and stage.shape == photo.shape
    assert float(result.detach().min()) >= 0.0 and float(result.detach().max()) <= 1.0
    if effect_name == "none":
        assert masks is None and torch.equal(stage, photo)
    elif options["ppn"] == "local":
        assert masks.shape == (1, 8, 48, 64)
    else:
        assert torch.allclose(masks, start.expand(1, -1))
    parameters = [] if effect_name == "none" else effects.create("xdog").param_names
    info = ModelInfo(effect_name, "translator", parameters, 48, 48, kind="local", network=options)
    save_model(tmp_path / "m.safetensors", network, info)
    loaded, read = load_model(tmp_path / "m.safetensors", effect_name, "local")
    assert read.network == options and read.effect == effect_name
    assert torch.allclose(loaded.stages(photo).result, result, atol=1e-6)
    if effect_name == "xdog":
        assert torch.equal(loaded.start, network.start), "the preset travels with the weights"


def test_parts_that_cannot_form_a_generator_are_refused() -> None:
    xdog = effects.create("xdog")
    with pytest.raises(WiseError, match="CNN alone"):
        Translator(None, None, None)
    with pytest.raises(WiseError, match="nothing to learn"):
        Translator(xdog, None, None, xdog.preset("portrait"))
    with pytest.raises(WiseError, match="unknown PPN kind 'global'"):
        build_translator("xdog", translator_options("global", "resnet"))


def test_edited_masks_change_the_effect_stage_where_painted_and_only_there(astronaut_small: torch.Tensor) -> None:
    torch.manual_seed(0)
    xdog = effects.create("xdog")
    network = build_translator("xdog", translator_options("local", "unet", 4, **PPN), xdog.preset("portrait"))
    network.eval()
    with torch.no_grad():
        masks = network.masks(astronaut_small)
        before = network.finish(astronaut_small, masks)
        edited = masks.clone()
        edited[:, xdog.param_names.index("shading"), 16:48, 16:48] = 0.45
        after = network.finish(astronaut_small, edited)
    stage_change = (after.stage - before.stage).abs().mean(dim=1)[0]
    inside, outside = stage_change[16:48, 16:48], stage_change.clone()
    outside[8:56, 8:56] = 0.0
    assert float(inside.mean()) > 0.02
    assert float(outside.max()) == 0.0, "the effect stage changes only near the painted square"
    assert not torch.equal(after.result, before.result), "and the CNN's drawing follows"
