"""Parameter files: safetensors round trips, reordering and every refusal."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import save_file

from wise.effects.base import Effect
from wise.errors import WiseError
from wise.paramfile import describe, load_params, save_params
from wise.params import ParamSpec


class Tiny(Effect):
    """A three-parameter effect for file tests."""

    name = "tiny"
    param_specs = (
        ParamSpec("alpha", 0.0, 1.0, 0.5),
        ParamSpec("beta", -2.0, 2.0, 0.0),
        ParamSpec("gamma", 10.0, 20.0, 12.0),
    )
    presets = {"bright": {"alpha": 0.9}}

    def render(self, image: torch.Tensor, p: dict[str, torch.Tensor]) -> torch.Tensor:
        return image * p["alpha"]


class Other(Tiny):
    """Same parameters, another effect."""

    name = "other"


NAMES = ["alpha", "beta", "gamma"]


@pytest.fixture
def effect() -> Tiny:
    return Tiny()


def write_raw(path: Path, tensor: torch.Tensor, **overrides: str | None) -> Path:
    """A parameter file written by hand, with metadata fields replaced or removed (None)."""
    metadata: dict[str, str] = {
        "format": "wise-params",
        "version": "1",
        "effect": "tiny",
        "parameters": json.dumps(NAMES),
        "space": "normalized",
        "kind": "global" if tensor.dim() == 1 else "local",
    }
    for key, value in overrides.items():
        if value is None:
            metadata.pop(key, None)
        else:
            metadata[key] = value
    save_file({"params": tensor.contiguous()}, str(path), metadata=metadata)
    return path


@pytest.mark.parametrize("shape", [(3,), (1, 3)])
def test_global_round_trip(tmp_path: Path, effect: Tiny, shape: tuple[int, ...]) -> None:
    params = torch.tensor([-0.5, 0.1, 0.45]).view(shape)
    save_params(tmp_path / "p.safetensors", effect, params)
    loaded = load_params(tmp_path / "p.safetensors", effect)
    assert loaded.shape == (1, 3) and loaded.dtype == torch.float32
    assert torch.equal(loaded, params.view(1, 3))


@pytest.mark.parametrize("shape", [(3, 5, 7), (1, 3, 5, 7)])
def test_local_round_trip(tmp_path: Path, effect: Tiny, shape: tuple[int, ...]) -> None:
    params = torch.rand(shape) - 0.5
    save_params(tmp_path / "m.safetensors", effect, params)
    loaded = load_params(tmp_path / "m.safetensors", effect)
    assert loaded.shape == (1, 3, 5, 7)
    assert torch.equal(loaded, params.view(1, 3, 5, 7))
    assert describe(tmp_path / "m.safetensors")["kind"] == "local"


def test_metadata_and_real_space(tmp_path: Path, effect: Tiny) -> None:
    params = effect.params_from_dict({"alpha": 0.25, "beta": 1.0, "gamma": 15.0})
    path = tmp_path / "real.safetensors"
    save_params(path, effect, params, space="real")
    with safe_open(str(path), framework="pt") as f:
        meta = f.metadata()
        stored = f.get_tensor("params")
    assert meta["format"] == "wise-params" and meta["version"] == "1" and meta["effect"] == "tiny"
    assert json.loads(meta["parameters"]) == NAMES
    assert meta["space"] == "real" and meta["kind"] == "global"
    assert json.loads(meta["ranges"]) == [[0.0, 1.0], [-2.0, 2.0], [10.0, 20.0]]
    assert torch.allclose(stored, torch.tensor([0.25, 1.0, 15.0]))
    assert torch.allclose(load_params(path, effect), params.view(1, 3), atol=1e-6)


def test_reordered_names_are_accepted(tmp_path: Path, effect: Tiny) -> None:
    path = write_raw(
        tmp_path / "r.safetensors",
        torch.tensor([0.3, -0.2, 0.1]),
        parameters=json.dumps(["gamma", "alpha", "beta"]),
    )
    assert torch.equal(load_params(path, effect), torch.tensor([[-0.2, 0.1, 0.3]]))
    masks = torch.stack([torch.full((2, 2), v) for v in (0.4, 0.0, -0.4)])
    path = write_raw(tmp_path / "m.safetensors", masks, parameters=json.dumps(["beta", "gamma", "alpha"]), space="real")
    loaded = load_params(path, effect)
    assert torch.allclose(loaded[0, :, 0, 0], torch.tensor([-0.9, 0.1, -1.5]), atol=1e-6)


def refused(path: Path, effect: Effect, *words: str) -> str:
    with pytest.raises(WiseError) as info:
        load_params(path, effect)
    message = str(info.value)
    assert "\n" not in message and str(path) in message
    for word in words:
        assert word in message, message
    return message.split(".safetensors: ", 1)[-1]


def test_refuses_unreadable_files(tmp_path: Path, effect: Tiny) -> None:
    refused(tmp_path / "none.safetensors", effect, "no such file")
    refused(tmp_path, effect, "directory")
    (tmp_path / "text.safetensors").write_text("alpha = 0.5\n")
    refused(tmp_path / "text.safetensors", effect, "not a safetensors file")
    (tmp_path / "short.safetensors").write_bytes(b"\x01\x02")
    refused(tmp_path / "short.safetensors", effect, "not a safetensors file")


def test_refuses_foreign_safetensors(tmp_path: Path, effect: Tiny) -> None:
    save_file({"weight": torch.zeros(3)}, str(tmp_path / "model.safetensors"))
    refused(tmp_path / "model.safetensors", effect, "not a wise parameter file")
    write_raw(tmp_path / "v2.safetensors", torch.zeros(3), version="2")
    refused(tmp_path / "v2.safetensors", effect, "version")


def test_refuses_other_effect(tmp_path: Path, effect: Tiny) -> None:
    save_params(tmp_path / "o.safetensors", Other(), torch.zeros(3))
    refused(tmp_path / "o.safetensors", effect, "'other'", "'tiny'")


def test_refuses_missing_and_extra_parameters(tmp_path: Path, effect: Tiny) -> None:
    path = write_raw(tmp_path / "m.safetensors", torch.zeros(2), parameters=json.dumps(["alpha", "gamma"]))
    message = refused(path, effect, "missing parameter(s) beta")
    assert "unknown" not in message
    path = write_raw(tmp_path / "x.safetensors", torch.zeros(4), parameters=json.dumps(NAMES + ["delta"]))
    message = refused(path, effect, "unknown parameter(s) delta")
    assert "missing" not in message
    path = write_raw(tmp_path / "d.safetensors", torch.zeros(3), parameters=json.dumps(["alpha", "alpha", "gamma"]))
    refused(path, effect, "twice", "alpha")
    path = write_raw(tmp_path / "n.safetensors", torch.zeros(3), parameters="alpha,beta,gamma")
    refused(path, effect, "JSON list")


def test_refuses_wrong_shapes(tmp_path: Path, effect: Tiny) -> None:
    for i, shape in enumerate([(4,), (3, 2), (1, 3), (3, 0, 4), (2, 3, 4, 4)]):
        path = write_raw(tmp_path / f"s{i}.safetensors", torch.zeros(shape), kind=None)
        refused(path, effect, "wrong tensor shape")
    path = write_raw(tmp_path / "k.safetensors", torch.zeros(3, 2, 2), kind="global")
    refused(path, effect, "'global'")


def test_refuses_non_finite_values(tmp_path: Path, effect: Tiny) -> None:
    path = write_raw(tmp_path / "nan.safetensors", torch.tensor([0.0, float("nan"), 0.0]))
    refused(path, effect, "'beta'", "NaN or infinite")
    masks = torch.zeros(3, 2, 2)
    masks[2, 1, 1] = float("inf")
    path = write_raw(tmp_path / "inf.safetensors", masks)
    refused(path, effect, "'gamma'")


def test_refuses_bad_space_and_tensors(tmp_path: Path, effect: Tiny) -> None:
    refused(write_raw(tmp_path / "s.safetensors", torch.zeros(3), space="pixels"), effect, "space")
    path = tmp_path / "two.safetensors"
    save_file(
        {"params": torch.zeros(3), "extra": torch.zeros(1)},
        str(path),
        metadata={
            "format": "wise-params",
            "version": "1",
            "effect": "tiny",
            "parameters": json.dumps(NAMES),
            "space": "normalized",
        },
    )
    refused(path, effect, "exactly one tensor")
    refused(write_raw(tmp_path / "i.safetensors", torch.zeros(3, dtype=torch.int32)), effect, "floating point")


def test_save_refusals(tmp_path: Path, effect: Tiny) -> None:
    with pytest.raises(WiseError, match=r"shape \(3,\)"):
        save_params(tmp_path / "a.safetensors", effect, torch.zeros(4))
    with pytest.raises(WiseError, match="shape"):
        save_params(tmp_path / "a.safetensors", effect, torch.zeros(2, 3))
    with pytest.raises(WiseError, match="space"):
        save_params(tmp_path / "a.safetensors", effect, torch.zeros(3), space="pixels")
    with pytest.raises(WiseError, match="'gamma'"):
        save_params(tmp_path / "a.safetensors", effect, torch.tensor([0.0, 0.0, float("nan")]))
    with pytest.raises(WiseError, match="does not exist"):
        save_params(tmp_path / "missing" / "a.safetensors", effect, torch.zeros(3))
    assert list(tmp_path.iterdir()) == []


def test_failed_save_leaves_no_file(tmp_path: Path, effect: Tiny, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(self: Path, data: bytes) -> int:
        with open(self, "wb") as f:
            f.write(data[:10])
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "write_bytes", broken)
    with pytest.raises(WiseError, match="No space left"):
        save_params(tmp_path / "p.safetensors", effect, torch.zeros(3))
    assert list(tmp_path.iterdir()) == []
