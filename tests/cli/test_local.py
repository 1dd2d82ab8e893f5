"""``wise train local``, ``wise predict`` with a local model and ``wise bench pairs``."""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from tests.cli.helpers import run_in_process
from tests.images import astronaut_png, xdog_pairs
from wise import effects, ppn
from wise.editor.server import initial_session
from wise.ppn.modelfile import ModelInfo, load_model, save_model
from wise.train.evaluate import region_iou

NETWORK = {"depth": 3, "width": 8, "max_width": 16}


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("local")
    xdog = effects.create("xdog")
    torch.manual_seed(0)
    network = ppn.create_local("unet", len(xdog.param_specs), **NETWORK, start=xdog.preset("portrait"))
    with torch.no_grad():
        network.head.weight.normal_(0.0, 0.5)  # masks that vary over the photo
    info = ModelInfo("xdog", "unet", xdog.param_names, size=64, render_size=64, kind="local", network=NETWORK)
    save_model(root / "local.safetensors", network, info)
    return {
        "root": root,
        "photo": astronaut_png(root / "photo.png", 150, 100),
        "model": root / "local.safetensors",
        "pairs": xdog_pairs(root / "pairs", size=64),
    }


def test_predict_paints_masks_that_apply_and_the_editor_render_to_the_same_pixels(world: dict[str, Path]) -> None:
    out = world["root"] / "painted"
    code, printed = run_in_process(
        ["predict", "xdog", "--content", str(world["photo"]), "-o", str(out), "--model", str(world["model"])]
    )
    assert code == 0 and "masks painted" in printed
    assert sorted(p.name for p in out.iterdir()) == ["masks.png", "metrics.json", "params.safetensors", "result.png"]
    scores = json.loads((out / "metrics.json").read_text())
    assert scores["kind"] == "local" and scores["masks_size"] == [64, 96]
    result = np.asarray(Image.open(out / "result.png"))
    assert result.shape == (100, 150, 3)
    sheet = Image.open(out / "masks.png")
    assert sheet.width > 4 * 64 and sheet.mode == "RGB"
    code, _ = run_in_process(
        ["apply", "xdog", str(world["photo"]), "-o", str(world["root"] / "applied.png"),
         "--params", str(out / "params.safetensors")]
    )  # fmt: skip
    assert code == 0
    assert np.array_equal(result, np.asarray(Image.open(world["root"] / "applied.png")))
    session = initial_session(str(world["photo"]), str(out / "params.safetensors"))
    assert session.masks_from_file and tuple(session.masks.shape) == (1, 8, 64, 96)
    assert session.masks.std(dim=(2, 3)).max() > 0.01, "masks, not one value"
    edited = np.asarray(Image.open(io.BytesIO(session.render_full(session.snapshot()))).convert("RGB"))
    assert np.array_equal(result, edited)


def test_bench_pairs_measures_the_model_against_the_preset(world: dict[str, Path]) -> None:
    report = world["root"] / "pairs.json"
    code, printed = run_in_process(["bench", "pairs", "--model", str(world["model"]), "--pairs", str(world["pairs"]),
                          "--json", str(report)])  # fmt: skip
    assert code == 0 and "2 pairs" in printed and "region IoU" in printed
    result = json.loads(report.read_text())
    assert result["count"] == 2 and result["baseline"] == "portrait" and result["task"] == "dark"
    keys = {"mean_l1", "mean_psnr", "mean_ssim", "baseline_mean_l1", "baseline_mean_psnr", "baseline_mean_ssim"}
    assert keys <= result.keys() and "mean_iou" in result and "mean_tv" in result
    assert [row["name"] for row in result["rows"]] == ["camera", "immunohistochemistry"], "the test split"
    assert result["baseline_mean_l1"] > 0.01, "the targets depart from the preset"


def test_region_iou_compares_where_the_mask_departs_with_the_true_region() -> None:
    xdog = effects.create("xdog")
    spec = xdog.spec("contour")
    task = {"parameter": "contour", "inside": 3.0, "preset_value": 1.0}
    masks = xdog.preset("portrait").view(1, -1, 1, 1).repeat(1, 1, 8, 8)
    index = xdog.param_names.index("contour")
    masks[:, index, :, :4] = (2.5 - spec.min) / (spec.max - spec.min) - 0.5
    region = torch.zeros(1, 1, 8, 8)
    region[..., :4] = 1.0
    assert region_iou(masks, region, xdog, task) == pytest.approx(1.0)
    region[..., :2, :] = 1.0
    assert region_iou(masks, region, xdog, task) == pytest.approx(32 / 40)
    masks[:, index] = (1.5 - spec.min) / (spec.max - spec.min) - 0.5
    assert region_iou(masks, region, xdog, task) == 0.0, "not half the way to the task's value"
    assert region_iou(masks, region, xdog, {}) is None


def test_train_local_runs_resumes_and_writes_itsrun_in_process(world: dict[str, Path], tmp_path: Path) -> None:
    run = tmp_path / "run"
    common = ["train", "local", "xdog", "--pairs", str(world["pairs"]), "-o", str(run), "--depth", "3", "--width",
              "8", "--max-width", "16", "--discriminator-width", "8", "--load-size", "64", "--crop-size", "48",
              "--accelerator", "cpu", "--checkpoint-every", "2"]  # fmt: skip
    code, printed = run_in_process([*common, "--steps", "3"])
    assert code == 0 and "3 steps" in printed
    assert {"model.safetensors", "report.html", "settings.json"} <= {p.name for p in run.iterdir()}
    code, printed = run_in_process([*common, "--steps", "5", "--resume"])
    assert code == 0, printed
    _, info = load_model(run / "model.safetensors", "xdog", "local")
    assert info.settings["steps_done"] == 5 and info.settings["task"] == "dark" and info.size == 64
    assert sorted(p.name for p in (run / "logs").iterdir()) == ["0", "1"]


def test_train_local_runs_on_two_ddp_processes(world: dict[str, Path], tmp_path: Path) -> None:
    import os
    import subprocess
    import sys

    import wise

    source = Path(wise.__file__).resolve().parent.parent
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(source), os.environ.get("PYTHONPATH")]))}
    argv = ["train", "local", "xdog", "--pairs", str(world["pairs"]), "-o", str(tmp_path / "run"), "--depth", "3",
            "--width", "8", "--max-width", "16", "--discriminator-width", "8", "--load-size", "64", "--crop-size",
            "48", "--accelerator", "cpu", "--devices", "2", "--steps", "2", "--checkpoint-every", "1"]  # fmt: skip
    done = subprocess.run(
        [sys.executable, "-m", "wise", *argv], capture_output=True, text=True, env=env, timeout=300, cwd=tmp_path
    )
    assert done.returncode == 0, done.stderr[-2000:]
    _, info = load_model(tmp_path / "run" / "model.safetensors", "xdog", "local")
    assert info.settings["processes"] == 2 and info.settings["steps_done"] == 2


def test_the_built_in_contours_model_paints_without_a_download(world: dict[str, Path]) -> None:
    out = world["root"] / "builtin"
    code, printed = run_in_process(
        ["predict", "xdog", "--model", "builtin:contours", "--content", str(world["photo"]), "-o", str(out)]
    )
    assert code == 0 and "builtin:contours" in printed
    scores = json.loads((out / "metrics.json").read_text())
    assert scores["model"] == "builtin:contours" and scores["kind"] == "local"
    code, _ = run_in_process(
        ["predict", "xdog", "--model", "builtin:chin", "--content", str(world["photo"]), "-o", str(out)]
    )
    assert code == 2
