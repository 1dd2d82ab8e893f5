"""Model files: weights and metadata round-trip; anything else is refused with one clear line."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import save_file

import wise
from wise import ppn
from wise.errors import WiseError
from wise.ppn.modelfile import ModelInfo, builtin_model_path, load_model, model_info, save_model
from wise.ppn.predictor import Predictor

EFFECTS = ("xdog", "cartoon", "watercolor", "oilpaint")


def _metadata_of(path: Path) -> dict[str, str]:
    with safe_open(str(path), "pt") as f:
        return dict(f.metadata())


def _info(effect: str, architecture: str = "simple") -> ModelInfo:
    names = wise.effects.create(effect).param_names
    return ModelInfo(effect, architecture, names, size=64, render_size=256, settings={"lr": 0.001})


@pytest.mark.parametrize("half", [False, True])
def test_weights_and_metadata_round_trip(tmp_path: Path, half: bool) -> None:
    torch.manual_seed(0)
    network = ppn.create("simple", len(wise.effects.create("cartoon").param_specs))
    save_model(tmp_path / "m.safetensors", network, _info("cartoon"), half=half)
    loaded, info = load_model(tmp_path / "m.safetensors", "cartoon")
    assert (info.effect, info.architecture, info.size, info.render_size) == ("cartoon", "simple", 64, 256)
    assert info.settings == {"lr": 0.001} and info.wise_version == wise.__version__
    photo, example = torch.rand(2, 3, 40, 48), torch.rand(2, 3, 40, 48)
    with torch.no_grad():
        expected, found = network(photo, example), loaded(photo, example)
    assert torch.allclose(expected, found, atol=2e-3 if half else 1e-6)


def test_models_of_another_effect_or_format_are_refused(tmp_path: Path) -> None:
    network = ppn.create("simple", len(wise.effects.create("xdog").param_specs))
    save_model(tmp_path / "xdog.safetensors", network, _info("xdog"))
    with pytest.raises(WiseError, match="a model for 'xdog', not 'cartoon'"):
        model_info(tmp_path / "xdog.safetensors", "cartoon")
    save_file({"w": torch.zeros(2)}, tmp_path / "plain.safetensors")
    with pytest.raises(WiseError, match="not a wise model file \\(no wise metadata"):
        load_model(tmp_path / "plain.safetensors")
    (tmp_path / "model.pth").write_bytes(b"\x80\x04pickle")
    with pytest.raises(WiseError, match="must be a .safetensors file"):
        load_model(tmp_path / "model.pth")
    raw = (tmp_path / "xdog.safetensors").read_bytes()
    (tmp_path / "cut.safetensors").write_bytes(raw[: len(raw) // 2])
    with pytest.raises(WiseError, match="not a safetensors file"):
        load_model(tmp_path / "cut.safetensors")


def test_weights_that_do_not_fit_the_architecture_are_refused(tmp_path: Path) -> None:
    count = len(wise.effects.create("xdog").param_specs)
    wrong = ppn.create("simple", count + 1)
    save_model(tmp_path / "wide.safetensors", wrong, _info("xdog"))
    with pytest.raises(WiseError, match="linear.weight has the shape"):
        load_model(tmp_path / "wide.safetensors", "xdog")
    network = ppn.create("simple", count)
    state = {name: value.clone() for name, value in network.state_dict().items()}
    state["linear.bias"][0] = float("nan")
    save_model(tmp_path / "good.safetensors", network, _info("xdog"))
    header = _metadata_of(tmp_path / "good.safetensors")
    save_file(state, tmp_path / "nan.safetensors", metadata=header)
    with pytest.raises(WiseError, match="non-finite"):
        load_model(tmp_path / "nan.safetensors", "xdog")
    del state["linear.bias"]
    save_file(state, tmp_path / "missing.safetensors", metadata=header)
    with pytest.raises(WiseError, match="missing: linear.bias"):
        load_model(tmp_path / "missing.safetensors", "xdog")


def test_metadata_names_the_parameters_in_output_order(tmp_path: Path) -> None:
    network = ppn.create("simple", len(wise.effects.create("watercolor").param_specs))
    save_model(tmp_path / "w.safetensors", network, _info("watercolor"))
    header = _metadata_of(tmp_path / "w.safetensors")
    assert json.loads(header["parameters"]) == wise.effects.create("watercolor").param_names
    assert header["format"] == "wise-ppn" and header["kind"] == "global" and header["architecture"] == "simple"


@pytest.mark.parametrize("effect", EFFECTS)
def test_every_effect_ships_a_small_model_that_loads(effect: str) -> None:
    path = builtin_model_path(effect)
    assert path.stat().st_size < 8 * 1000**2
    network, info = load_model(path, effect)
    assert info.effect == effect and info.parameters == wise.effects.create(effect).param_names
    with torch.no_grad():
        predicted = network(torch.rand(1, 3, info.size, info.size), torch.rand(1, 3, info.size, info.size))
    assert predicted.shape == (1, len(info.parameters)) and float(predicted.abs().max()) <= 0.5


def test_a_global_model_made_before_a_parameter_was_added_predicts_it_at_its_default(tmp_path: Path) -> None:
    effect = wise.effects.create("watercolor")
    assert "accents" in effect.added_params
    older = [name for name in effect.param_names if name != "accents"]
    torch.manual_seed(0)
    network = ppn.create("simple", len(older))
    info = ModelInfo("watercolor", "simple", older, size=64, render_size=256, settings={})
    save_model(tmp_path / "old.safetensors", network, info)
    photo, example = torch.rand(1, 3, 64, 80), torch.rand(1, 3, 64, 80)
    predicted = Predictor(tmp_path / "old.safetensors", "watercolor")(photo, example)
    with torch.no_grad():
        own = network(photo, example)
    accents = effect.param_names.index("accents")
    assert predicted.shape == (1, len(effect.param_names))
    assert float(predicted[0, accents]) == float(effect.default_params()[accents])
    assert torch.allclose(predicted[:, [effect.param_names.index(n) for n in older]], own)
    # a model that lacks a parameter the effect always had is refused
    save_model(
        tmp_path / "bad.safetensors",
        ppn.create("simple", len(older)),
        replace(info, parameters=older[1:] + ["accents"]),
    )
    with pytest.raises(WiseError, match="other parameters"):
        Predictor(tmp_path / "bad.safetensors", "watercolor")
