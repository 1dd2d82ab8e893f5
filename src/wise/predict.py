"""Global parameters predicted from a photo and a stylized example of it (``wise predict``).

A :class:`Predictor` holds a trained network (:mod:`wise.ppn.modelfile`) and resizes both
images to the model's working size before its one forward pass.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path
from typing import TextIO

import torch
import torch.nn.functional as F

from wise import effects, metrics
from wise.effects.base import Effect
from wise.io import atomic_path, read_image, write_image
from wise.paramfile import save_params
from wise.ppn.modelfile import ModelInfo, load_model, resolve_model
from wise.render import render

RESULT_FILES = ("params.safetensors", "result.png", "metrics.json")
PREDICTED_FILE = "predicted.safetensors"
"""With ``--refine``: the prediction the optimization started from."""


def at_short_side(image: torch.Tensor, short_side: int) -> torch.Tensor:
    """``image`` resized so that its short side is ``short_side`` (area filter when reducing)."""
    height, width = image.shape[-2:]
    factor = short_side / min(height, width)
    if factor == 1.0:
        return image
    shape = (max(1, round(height * factor)), max(1, round(width * factor)))
    return F.interpolate(image, size=shape, mode="area" if factor < 1 else "bilinear").clamp(0.0, 1.0)


class Predictor:
    """A loaded model: ``predictor(photo, example)`` -> normalized global parameters ``(B, P)``."""

    def __init__(self, model: str | os.PathLike[str] | None, effect: str, device: torch.device | str = "cpu") -> None:
        path = resolve_model(model, effect)
        self.network, self.info = load_model(path, effect)
        self.network.to(device)
        self.device = torch.device(device)
        if model is None:
            self.info.source = f"builtin:{effect}"

    @torch.no_grad()
    def __call__(self, photo: torch.Tensor, example: torch.Tensor) -> torch.Tensor:
        size = self.info.size
        small_photo = at_short_side(photo, size).to(self.device)
        small_example = at_short_side(example, size).to(self.device)
        return self.network(small_photo, small_example).float().cpu()


def predict_files(
    effect_name: str,
    content_path: str,
    target_path: str,
    out_dir: str,
    model: str | None = None,
    refine: int = 0,
    refine_mode: str = "global",
    device: torch.device | str = "cpu",
    out: TextIO = sys.stdout,
) -> dict:
    """Predict the parameters that re-create the target, render the content with them at full
    resolution, and write :data:`RESULT_FILES` into ``out_dir``; ``refine`` iterations of
    :func:`wise.optimize.run.run` follow when positive. Returns the metrics."""
    from wise.optimize.run import match_target

    effect = effects.create(effect_name)
    predictor = Predictor(model, effect_name, device)
    content = read_image(content_path)
    target = match_target(read_image(target_path), tuple(content.shape[-2:]), out, str(target_path), str(content_path))
    began = time.perf_counter()
    params = predictor(content, target)
    seconds = time.perf_counter() - began
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    scores = _write_prediction(folder, effect, content, target, params, predictor.info, seconds)
    if refine > 0:
        scores = _refine(folder, effect_name, content_path, target_path, refine, refine_mode, scores, device, out)
    print(
        f"predicted in {seconds:.2f} s with {predictor.info.source}: ssim {scores['ssim']:.4f}  "
        f"psnr {scores['psnr']:.2f} dB  l1 {scores['l1']:.4f}; result: {folder / 'result.png'}",
        file=out,
    )
    return scores


def _write_prediction(
    folder: Path,
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    params: torch.Tensor,
    info: ModelInfo,
    seconds: float,
) -> dict:
    result = render(effect, content, params)
    scores = {
        "effect": effect.name,
        "model": info.source,
        "architecture": info.architecture,
        "working_size": info.size,
        "seconds": round(seconds, 4),
        "ssim": metrics.ssim(result, target),
        "psnr": metrics.psnr(result, target),
        "l1": metrics.l1(result, target),
        "params": effect.params_to_dict(params[0]),
    }
    save_params(folder / RESULT_FILES[0], effect, params)
    write_image(result, folder / RESULT_FILES[1])
    _write_json(folder / RESULT_FILES[2], scores)
    return scores


def _write_json(path: Path, value: dict) -> None:
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(value, indent=2) + "\n")


def _refine(
    folder: Path,
    effect_name: str,
    content_path: str,
    target_path: str,
    iterations: int,
    mode: str,
    predicted: dict,
    device: torch.device | str,
    out: TextIO,
) -> dict:
    """Optimize from the prediction; the optimization's files replace the prediction's, and
    its metrics keep the prediction's under ``prediction``."""
    from wise.optimize.parametric import Settings
    from wise.optimize.run import run

    start = folder / PREDICTED_FILE
    (folder / RESULT_FILES[0]).replace(start)
    settings = Settings(mode=mode, iterations=iterations, loss="l1")
    outcome = run(
        effect_name, content_path, target_path, str(folder), settings, init=str(start), device=device, out=out
    )
    scores = json.loads((folder / RESULT_FILES[2]).read_text())
    scores["prediction"] = {key: predicted[key] for key in ("model", "seconds", "ssim", "psnr", "l1")}
    scores["model"], scores["optimization_seconds"] = predicted["model"], scores["seconds"]
    scores["seconds"] = predicted["seconds"]
    scores["interrupted"] = outcome.interrupted
    _write_json(folder / RESULT_FILES[2], scores)
    return scores
