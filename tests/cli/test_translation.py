"""Image-to-image translation on the command line: ``wise data drawing``, ``wise predict`` and
``wise apply --model`` with a translator, ``wise bench pairs`` with its effect stage, FID, LPIPS
and results page."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image
from safetensors.torch import save_file

from tests.cli.helpers import run_in_process
from tests.images import astronaut_png, drawing_pairs
from wise import effects
from wise.editor.server import initial_session
from wise.fidelity.inception import expected_shapes as inception_shapes
from wise.fidelity.lpips import alexnet_shapes, linear_shapes
from wise.ppn.modelfile import ModelInfo, save_model
from wise.ppn.translation import build_translator, translator_options

PPN = {"depth": 3, "width": 4, "max_width": 8}


def _random_weights(shapes: dict[str, tuple[int, ...]]) -> dict[str, torch.Tensor]:
    weights = {}
    for name, shape in shapes.items():
        if name.endswith("running_var"):
            weights[name] = torch.ones(shape)
        elif name.endswith(("running_mean", "bias")):
            weights[name] = torch.zeros(shape)
        elif len(shape) > 1:
            weights[name] = torch.randn(shape) * (2.0 / float(np.prod(shape[1:]))) ** 0.5
        else:
            weights[name] = torch.ones(shape)
    return weights


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("translation")
    torch.manual_seed(0)
    xdog = effects.create("xdog")
    for name, effect, options in (
        ("full", "xdog", translator_options("local", "resnet", 4, **PPN)),
        ("cnn", "none", translator_options("local", "unet", 4)),
    ):
        network = build_translator(effect, options, xdog.preset("portrait") if effect == "xdog" else None)
        if network.ppn is not None:
            with torch.no_grad():
                network.ppn.head.weight.normal_(0.0, 0.5)  # masks that vary over the photo
        names = xdog.param_names if effect == "xdog" else []
        info = ModelInfo(effect, "translator", names, size=64, render_size=64, kind="local", network=options)
        save_model(root / f"{name}.safetensors", network, info)
    save_file(_random_weights(inception_shapes()), root / "inception.safetensors")
    linear = {name: torch.rand(shape) for name, shape in linear_shapes().items()}  # LPIPS' weights are >= 0
    save_file({**_random_weights(alexnet_shapes()), **linear}, root / "lpips.safetensors")
    return {
        "root": root,
        "photo": astronaut_png(root / "photo.png", 150, 100),
        "pairs": drawing_pairs(root / "pairs", size=64),
    }


def test_predict_then_apply_with_the_model_reproduces_the_drawing(world: dict[str, Path]) -> None:
    out = world["root"] / "predicted"
    model = str(world["root"] / "full.safetensors")
    code, printed = run_in_process(
        ["predict", "xdog", "--content", str(world["photo"]), "-o", str(out), "--model", model]
    )
    assert code == 0 and "translated" in printed
    assert sorted(p.name for p in out.iterdir()) == [
        "masks.png", "metrics.json", "params.safetensors", "result.png", "stage.png",
    ]  # fmt: skip
    scores = json.loads((out / "metrics.json").read_text())
    assert scores["architecture"] == "translator" and scores["result_size"] == [64, 96], "the model's working size"
    result = np.asarray(Image.open(out / "result.png"))
    stage = np.asarray(Image.open(out / "stage.png"))
    assert result.shape == stage.shape == (64, 96, 3) and not np.array_equal(result, stage)
    applied = world["root"] / "applied.png"
    code, _ = run_in_process(
        ["apply", "xdog", str(world["photo"]), "-o", str(applied), "--params", str(out / "params.safetensors"),
         "--model", str(world["root"] / "full.safetensors")]
    )  # fmt: skip
    assert code == 0
    assert np.array_equal(result, np.asarray(Image.open(applied)))
    edited = world["root"] / "edited.png"
    code, _ = run_in_process(
        ["apply", "xdog", str(world["photo"]), "-o", str(edited), "--params", str(out / "params.safetensors"),
         "--model", str(world["root"] / "full.safetensors"), "--set", "contour=3"]
    )  # fmt: skip
    assert code == 0 and not np.array_equal(result, np.asarray(Image.open(edited))), "edits reach the drawing"
    session = initial_session(
        str(world["photo"]), str(out / "params.safetensors"), model=str(world["root"] / "full.safetensors")
    )
    in_editor = np.asarray(Image.open(io.BytesIO(session.render_full(session.snapshot()))).convert("RGB"))
    assert np.array_equal(result, in_editor), "the editor draws with the model's CNN too"
    preview = Image.open(io.BytesIO(session.render_preview(session.snapshot())))
    assert preview.size[0] > 0


def test_a_cnn_alone_predicts_only_its_drawing(world: dict[str, Path]) -> None:
    out = world["root"] / "cnn"
    model = str(world["root"] / "cnn.safetensors")
    code, _ = run_in_process(["predict", "none", "--content", str(world["photo"]), "-o", str(out), "--model", model])
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "result.png"]


def test_bench_pairs_reports_the_effect_stage_fid_lpips_and_a_page(world: dict[str, Path]) -> None:
    report, page = world["root"] / "bench.json", world["root"] / "bench.html"
    weights = world["root"] / "lpips.safetensors"
    code, printed = run_in_process(
        ["bench", "pairs", "--model", str(world["root"] / "full.safetensors"), "--pairs", str(world["pairs"]),
         "--json", str(report), "--html", str(page), "--fid", "--inception-weights",
         str(world["root"] / "inception.safetensors"), "--lpips", "--lpips-weights", str(weights)]
    )  # fmt: skip
    assert code == 0 and "FID" in printed and "LPIPS" in printed and "effect stage" in printed
    result = json.loads(report.read_text())
    for key in ("mean_l1", "mean_psnr", "mean_ssim", "stage_mean_l1", "stage_mean_ssim", "mean_lpips", "fid"):
        assert np.isfinite(result[key]), key
    assert result["baseline"] == "portrait" and result["count"] == 2
    assert result["fid"] > 0.0 and all(row["lpips"] > 0.0 for row in result["rows"])
    text = page.read_text()
    for label in ("photo", "effect stage", "result", "ground truth"):
        assert f"<figcaption>{label}</figcaption>" in text, label
    names = effects.create("xdog").param_names
    masks_shown = sum(text.count(f"<figcaption>{name} [") for name in names)
    assert masks_shown == 2 * 3, "the three masks that vary most, for both pairs"
    assert text.count("<img") >= 2 * 5, "photo, stage, result, ground truth and masks of both pairs"


def test_data_drawing_writes_a_set_that_trains_as_pairs(world: dict[str, Path], tmp_path: Path) -> None:
    photos = tmp_path / "photos"
    photos.mkdir()
    for index in range(2):
        astronaut_png(photos / f"p{index}.png", 90 + 10 * index, 80)
    code, printed = run_in_process(
        ["data", "drawing", "--images", str(photos), "-o", str(tmp_path / "drawings"), "--count", "4", "--size", "32"]
    )
    assert code == 0 and "2 training and 2 test pairs" in printed
    description = json.loads((tmp_path / "drawings" / "drawing.json").read_text())
    assert description["pairs"] == {"train": 2, "test": 2}
