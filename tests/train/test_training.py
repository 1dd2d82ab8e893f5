"""Training runs: the loss falls, DDP equals one process with the same global batch, Ctrl-C
saves a checkpoint that resumes, and the run folder holds a loadable model."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from PIL import Image
from safetensors.torch import load_file
from skimage import data

import wise
from wise.ppn.modelfile import load_model
from wise.train.report import read_curves
from wise.train.run import train_global
from wise.train.settings import CHECKPOINT, TrainSettings

SRC = Path(wise.__file__).resolve().parent.parent
TINY = ["--size", "32", "--render-size", "48", "--examples", "32", "--batch", "4", "--accelerator", "cpu"]


@pytest.fixture(scope="module")
def photos(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("training-photos")
    for name in ("astronaut", "rocket", "immunohistochemistry", "hubble_deep_field", "coffee", "retina"):
        Image.fromarray(getattr(data, name)()).resize((96, 80)).save(root / f"{name}.png")
    return root


def _wise(argv: list[str], cwd: Path) -> list[str]:
    """The command line of ``wise`` run with this interpreter."""
    return [sys.executable, "-m", "wise", *argv]


def _env() -> dict[str, str]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")]))
    return env


def test_a_tiny_run_lowers_the_loss(photos: Path, tmp_path: Path) -> None:
    settings = TrainSettings(
        effect="cartoon", images=str(photos), size=32, render_size=32, batch=8, steps=120, examples=16, loss="param-l1",
        lr=3e-3, accelerator="cpu", checkpoint_every=1000,
    )  # fmt: skip
    summary = train_global(settings, str(tmp_path / "run"), out=open(os.devnull, "w"))
    assert summary["steps"] == 120 and not summary["interrupted"]
    losses = read_curves(sorted((tmp_path / "run" / "logs").glob("*/metrics.csv")))["train_loss"]
    first, last = sum(losses[:3]) / 3, sum(losses[-3:]) / 3
    assert last < 0.6 * first, (first, last)
    network, info = load_model(tmp_path / "run" / "model.safetensors", "cartoon")
    assert info.architecture == "simple" and info.size == 32 and info.settings["steps_done"] == 120
    assert info.settings["images"] == photos.name
    report = (tmp_path / "run" / "report.html").read_text()
    assert "<svg" in report and report.count("<img") == 3 * 6 and report.rstrip().endswith("</html>")


def test_two_ddp_processes_equal_one_with_the_same_global_batch(photos: Path, tmp_path: Path) -> None:
    # A parameter-space loss: with Adam, float rounding of tiny gradients through XDoG's thresholds
    # (other batch shapes, the all-reduce) would show as well, and this is about the batches.
    common = ["train", "global", "xdog", "--images", str(photos), "--steps", "4", *TINY, "--loss", "param-l1"]
    from wise.cli import main

    assert main([*common, "-o", str(tmp_path / "one"), "--batch", "8"]) == 0  # one process: this one
    two = subprocess.run(
        _wise([*common, "-o", str(tmp_path / "two"), "--batch", "4", "--devices", "2"], tmp_path),
        capture_output=True, text=True, env=_env(), timeout=300,
    )  # fmt: skip
    assert two.returncode == 0, two.stderr[-2000:]
    single, double = (
        load_file(tmp_path / "one" / "model.safetensors"),
        load_file(tmp_path / "two" / "model.safetensors"),
    )
    assert single.keys() == double.keys()
    for name in single:
        assert torch.allclose(single[name], double[name], atol=2e-5, rtol=1e-4), name
    steps = [json.loads((tmp_path / run / "settings.json").read_text())["steps"] for run in ("one", "two")]
    assert steps == [4, 4]
    processes = [load_model(tmp_path / run / "model.safetensors")[1].settings["processes"] for run in ("one", "two")]
    assert processes == [1, 2]


def test_ctrl_c_saves_a_checkpoint_and_the_run_resumes(
    photos: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    argv = ["train", "global", "oilpaint", "--images", str(photos), "-o", str(run), *TINY, "--checkpoint-every", "2"]
    process = subprocess.Popen(
        _wise([*argv, "--steps", "100000"], tmp_path), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, env=_env(),
    )  # fmt: skip
    deadline = time.monotonic() + 240
    while not (run / CHECKPOINT).exists() and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.2)
    assert (run / CHECKPOINT).exists(), process.communicate()[1][-2000:]
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr[-2000:]
    assert stderr.strip().splitlines()[-1] == "wise: interrupted"
    stopped_at = torch.load(run / CHECKPOINT, weights_only=True)["global_step"]
    assert 2 <= stopped_at < 100000
    assert load_model(run / "model.safetensors", "oilpaint")[1].settings["steps_done"] == stopped_at
    assert (run / "report.html").read_text().rstrip().endswith("</html>")

    from wise.cli import main

    target = stopped_at + 6
    assert main([*argv, "--steps", str(target), "--resume"]) == 0  # resumed in this process
    assert torch.load(run / CHECKPOINT, weights_only=True)["global_step"] == target
    assert load_model(run / "model.safetensors")[1].settings["steps_done"] == target
    assert sorted(p.parent.name for p in (run / "logs").glob("*/metrics.csv")) == ["0", "1"]
    assert json.loads((run / "settings.json").read_text())["steps"] == target

    capsys.readouterr()
    assert main(argv) == 2 and "pass --resume" in capsys.readouterr().err  # refused, in this process


def test_the_cosine_schedule_falls_to_its_floor_at_the_last_step() -> None:
    from types import SimpleNamespace

    from wise.train.module import GlobalPPN
    from wise.train.schedules import COSINE_FLOOR

    module = GlobalPPN("xdog", "simple", "image-l1", 1e-3, 32, lr_schedule="cosine")
    module._trainer = SimpleNamespace(estimated_stepping_batches=100)  # type: ignore[assignment]
    configured = module.configure_optimizers()
    optimizer, schedule = configured["optimizer"], configured["lr_scheduler"]["scheduler"]
    rates = []
    for _ in range(100):
        rates.append(optimizer.param_groups[0]["lr"])
        optimizer.step()
        schedule.step()
    assert rates[0] == 1e-3 and rates[50] == pytest.approx(1e-3 * (1 + COSINE_FLOOR) / 2, rel=0.02)
    assert optimizer.param_groups[0]["lr"] == pytest.approx(1e-3 * COSINE_FLOOR)
    assert all(a >= b for a, b in zip(rates, rates[1:]))
    constant = GlobalPPN("xdog", "simple", "image-l1", 1e-3, 32)
    assert isinstance(constant.configure_optimizers(), torch.optim.Adam)


def test_the_parameter_weight_adds_the_parameter_error_to_the_image_loss() -> None:
    from wise.train.module import GlobalPPN

    torch.manual_seed(0)
    plain = GlobalPPN("xdog", "tone", "image-l1", 1e-3, 32)
    weighted = GlobalPPN("xdog", "tone", "image-l1", 1e-3, 32, param_weight=0.5)
    weighted.network.load_state_dict(plain.network.state_dict())
    photo = torch.rand(2, 3, 32, 32)
    truth = torch.rand(2, len(plain.effect.param_specs)) - 0.5
    with torch.no_grad():
        target = plain.effect(photo, truth)
    batch = {"photo": photo, "example": target, "target": target, "params": truth}
    (image_loss, param_l1), (total, same_l1) = plain._losses(batch), weighted._losses(batch)
    assert float(param_l1) > 0.05 and same_l1 == param_l1
    assert float(total.detach()) == pytest.approx(float(image_loss.detach()) + 0.5 * float(param_l1), rel=1e-5)
