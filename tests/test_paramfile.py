"""Parameter files: safetensors round trips, reordering and every refusal."""

from __future__ import annotations

import json
import os
import struct
import time
import warnings
from pathlib import Path

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import save_file

from tests.effects.reference_xdog import REFERENCE_SKETCH
from wise import effects
from wise.effects.base import Effect
from wise.errors import WiseError, WiseWarning
from wise.paramfile import RANGE_TOLERANCE, describe, effect_of, load_params, save_params
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
    masks = torch.stack([torch.full((2, 2), v) for v in (0.4, 15.0, 0.25)])
    path = write_raw(tmp_path / "m.safetensors", masks, parameters=json.dumps(["beta", "gamma", "alpha"]), space="real")
    loaded = load_params(path, effect)
    assert torch.allclose(loaded[0, :, 0, 0], torch.tensor([-0.25, 0.1, 0.0]), atol=1e-6)


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


NO_METADATA = (
    "not a wise parameter file (no wise metadata); "
    "make one with wise optimize, the editor's Save params or wise.paramfile.save_params"
)


def test_refuses_foreign_safetensors(tmp_path: Path, effect: Tiny) -> None:
    save_file({"weight": torch.zeros(3)}, str(tmp_path / "model.safetensors"))
    assert refused(tmp_path / "model.safetensors", effect) == NO_METADATA
    save_file({"params": torch.zeros(3)}, str(tmp_path / "other.safetensors"), metadata={"format": "gguf"})
    refused(tmp_path / "other.safetensors", effect, "not a wise parameter file", "'gguf'", "wise optimize")
    write_raw(tmp_path / "v2.safetensors", torch.zeros(3), version="2")
    refused(tmp_path / "v2.safetensors", effect, "version")
    write_raw(tmp_path / "e.safetensors", torch.zeros(3), effect=None)
    refused(tmp_path / "e.safetensors", effect, "no effect in its metadata", "wise optimize")


def test_effect_of(tmp_path: Path, effect: Tiny) -> None:
    save_params(tmp_path / "o.safetensors", Other(), torch.zeros(3))
    assert effect_of(tmp_path / "o.safetensors") == "other"
    save_file({"weight": torch.zeros(3)}, str(tmp_path / "model.safetensors"))
    with pytest.raises(WiseError) as info:
        effect_of(tmp_path / "model.safetensors")
    assert str(info.value) == f"{tmp_path / 'model.safetensors'}: {NO_METADATA}"
    write_raw(tmp_path / "e.safetensors", torch.zeros(3), effect="")
    with pytest.raises(WiseError, match="no effect in its metadata"):
        effect_of(tmp_path / "e.safetensors")
    write_raw(tmp_path / "v2.safetensors", torch.zeros(3), version="2")
    with pytest.raises(WiseError, match="version"):
        effect_of(tmp_path / "v2.safetensors")


def test_special_files_and_huge_headers_are_refused_fast(tmp_path: Path, effect: Tiny) -> None:
    fifo = tmp_path / "fifo.safetensors"
    os.mkfifo(fifo)
    huge = tmp_path / "huge.safetensors"
    huge.write_bytes(struct.pack("<Q", 2**63) + b"{}")
    for path, words in ((Path("/dev/zero"), "character device"), (fifo, "named pipe"), (huge, "header length")):
        for read in (lambda p: load_params(p, effect), effect_of, describe):
            start = time.perf_counter()
            with pytest.raises(WiseError, match=words):
                read(path)
            assert time.perf_counter() - start < 1.0


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


def test_out_of_range_values_are_clamped_with_a_note(tmp_path: Path, effect: Tiny) -> None:
    masks = torch.zeros(3, 2, 2)
    masks[0, 0] = 0.7  # two values of alpha above the range
    masks[0, 1, 0] = -0.6
    masks[2, 1, 1] = -40.0
    masks[1] = 0.5 + RANGE_TOLERANCE / 2  # rounding: clamped without a note
    path = write_raw(tmp_path / "m.safetensors", masks)
    notes: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        loaded = load_params(path, effect, notes=notes)
    assert caught == []
    assert notes == [
        f"{path}: 3 values of alpha outside [0, 1] and 1 value of gamma outside [10, 20] clamped to their ranges"
    ]
    assert float(loaded.min()) == -0.5 and float(loaded.max()) == 0.5
    expected = masks.clamp(-0.5, 0.5)
    assert torch.equal(loaded[0], expected)


def test_out_of_range_values_warn_without_notes(tmp_path: Path, effect: Tiny) -> None:
    path = write_raw(tmp_path / "real.safetensors", torch.tensor([1e30, 0.0, 15.0]), space="real")
    with pytest.warns(WiseWarning) as caught:
        loaded = load_params(path, effect)
    assert [str(w.message) for w in caught] == [f"{path}: 1 value of alpha outside [0, 1] clamped to the range"]
    assert caught[0].filename == __file__  # points at the caller
    assert torch.equal(loaded, torch.tensor([[0.5, 0.0, 0.0]]))
    notes: list[str] = []
    in_range = write_raw(tmp_path / "ok.safetensors", torch.tensor([0.5, -0.5, 0.0]))
    assert torch.equal(load_params(in_range, effect, notes=notes), torch.tensor([[0.5, -0.5, 0.0]])) and notes == []


def test_a_preset_outside_its_range_loads_as_authored_and_bounds_the_span(tmp_path: Path) -> None:
    class ReferenceXDoG(type(effects.create("xdog"))):
        presets = {"reference_sketch": REFERENCE_SKETCH}

    xdog = ReferenceXDoG()
    path = tmp_path / "sketch.safetensors"
    save_params(path, xdog, xdog.preset("reference_sketch"))
    notes: list[str] = []
    assert torch.equal(load_params(path, xdog, notes=notes)[0], xdog.preset("reference_sketch")) and notes == []
    index = xdog.param_names.index("stroke_width")
    below = xdog.preset("reference_sketch").clone()
    below[index] -= 0.1
    save_params(path, xdog, below)
    loaded = load_params(path, xdog, notes=notes)
    authored = REFERENCE_SKETCH["stroke_width"]
    spec = xdog.spec("stroke_width")
    assert notes == [f"{path}: 1 value of stroke_width outside [{authored:g}, {spec.max:g}] clamped to the range"]
    assert float(loaded[0, index]) == pytest.approx(float(xdog.preset("reference_sketch")[index]))


def test_masks_fitted_beyond_the_range_within_their_reach_load_as_saved(tmp_path: Path) -> None:
    oilpaint = effects.create("oilpaint")
    index = oilpaint.param_names.index("brightness")
    masks = oilpaint.default_params()[:, None, None].expand(-1, 2, 2).clone()
    masks[index, 0, 0] = oilpaint.spec("brightness").to_normalized(-0.9)  # a white wall painted dark
    path = tmp_path / "masks.safetensors"
    save_params(path, oilpaint, masks)
    notes: list[str] = []
    assert torch.allclose(load_params(path, oilpaint, notes=notes)[0], masks) and notes == []
    masks[index, 0, 0] = oilpaint.spec("brightness").to_normalized(-1.5)  # beyond the reach: clamped to it
    save_params(path, oilpaint, masks)
    loaded = load_params(path, oilpaint, notes=notes)
    assert notes == [f"{path}: 1 value of brightness outside [-1, 1] clamped to the range"]
    assert oilpaint.spec("brightness").to_real(float(loaded[0, index, 0, 0])) == pytest.approx(-1.0)


class Grown(Tiny):
    """Tiny after a release that added ``delta``."""

    name = "tiny"
    param_specs = (*Tiny.param_specs, ParamSpec("delta", 0.0, 4.0, 3.0))
    added_params = ("delta",)


@pytest.mark.parametrize("space", ["normalized", "real"])
def test_a_file_made_before_a_parameter_was_added_loads_with_its_default(tmp_path: Path, space: str) -> None:
    masks = torch.rand(3, 4, 5) - 0.5 if space == "normalized" else torch.tensor([0.2, 1.0, 15.0])[:, None, None]
    path = write_raw(tmp_path / "old.safetensors", masks.expand(3, 4, 5).clone(), space=space)
    notes: list[str] = []
    loaded = load_params(path, Grown(), notes)
    assert loaded.shape == (1, 4, 4, 5)
    assert torch.allclose(loaded[0, :3], masks if space == "normalized" else load_params(path, Tiny())[0])
    assert torch.allclose(loaded[0, 3], torch.tensor(0.25))  # 3.0 of [0, 4]
    assert len(notes) == 1 and "delta" in notes[0] and "default" in notes[0]
    # a parameter that was there from the start is still missing, not defaulted
    path = write_raw(tmp_path / "m.safetensors", torch.zeros(2), parameters=json.dumps(["alpha", "gamma"]))
    refused(path, Grown(), "missing parameter(s) beta")
