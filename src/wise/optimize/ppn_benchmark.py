"""The parameter prediction benchmark of the WISE supplement (``wise bench ppn``).

Seeded random global parameters render an example from a photo (redrawn while the example is
nearly blank, as in :mod:`wise.optimize.benchmark`); the model predicts the parameters from
photo and example; the effect re-renders the photo with them. Scores: SSIM and PSNR of the
re-rendering against the example, and the mean absolute error of the normalized parameters.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path
from typing import TextIO

import torch

from wise import effects, metrics
from wise.effects.base import Effect
from wise.interrupt import ctrl_c
from wise.io import atomic_path, read_image
from wise.optimize.benchmark import PSNR_CAP, content_at, photos_in, random_reference
from wise.predict import Predictor


def bench_ppn(
    effect_name: str,
    images_dir: str,
    model: str | None = None,
    trials: int = 20,
    size: int = 512,
    seed: int = 0,
    json_path: str | None = None,
    device: torch.device | str = "cpu",
    out: TextIO = sys.stdout,
) -> dict:
    """Run the benchmark; prints a table, returns (and optionally writes) the results. Ctrl-C
    ends it after the trial in progress; the finished trials are written with ``"interrupted": true``."""
    effect = effects.create(effect_name)
    predictor = Predictor(model, effect_name, device)
    photos = photos_in(images_dir)
    contents = {path: content_at(read_image(path), size) for path in photos[:trials]}
    generator = torch.Generator().manual_seed(seed)
    rows: list[dict] = []
    print("| trial | image | SSIM | PSNR | param L1 |\n| --- | --- | --- | --- | --- |", file=out)
    with ctrl_c(out) as interruption:
        try:
            for trial in range(trials):
                path = photos[trial % len(photos)]
                rows.append(_trial(effect, predictor, contents[path], path, trial, generator))
                row = rows[-1]
                print(
                    f"| {trial} | {path.name} | {row['ssim']:.4f} | {row['psnr']:.2f} | {row['param_l1']:.4f} |",
                    file=out,
                    flush=True,
                )
        except KeyboardInterrupt:
            print(f"interrupted: {len(rows)} of {trials} trials finished", file=out, flush=True)
        interruption.hold()
        result = _summary(effect_name, predictor, size, seed, rows, interruption.received)
        if rows:
            print(
                f"mean SSIM {result['mean_ssim']:.4f}, mean PSNR {result['mean_psnr']:.2f} dB, "
                f"mean parameter L1 {result['mean_param_l1']:.4f}, "
                f"{result['seconds_per_prediction']:.3f} s per prediction",
                file=out,
            )
        if json_path is not None:
            with atomic_path(json_path) as tmp:
                Path(tmp).write_text(json.dumps(result, indent=2) + "\n")
    return result


def _trial(
    effect: Effect,
    predictor: Predictor,
    content: torch.Tensor,
    path: Path,
    trial: int,
    generator: torch.Generator,
) -> dict:
    truth, example = random_reference(effect, content, generator)
    began = time.perf_counter()
    predicted = predictor(content, example)
    seconds = time.perf_counter() - began
    with torch.no_grad():
        rendered = effect(content, predicted).clamp(0.0, 1.0)
    return {
        "trial": trial,
        "image": path.name,
        "ssim": metrics.ssim(rendered, example),
        "psnr": min(PSNR_CAP, metrics.psnr(rendered, example)),
        "param_l1": float((predicted - truth).abs().mean()),
        "seconds": round(seconds, 4),
        "true_params": effect.params_to_dict(truth[0]),
        "predicted_params": effect.params_to_dict(predicted[0]),
    }


def _summary(effect_name: str, predictor: Predictor, size: int, seed: int, rows: list[dict], interrupted: bool) -> dict:
    def mean(key: str) -> float | None:
        return statistics.fmean(row[key] for row in rows) if rows else None

    return {
        "effect": effect_name,
        "model": predictor.info.source,
        "architecture": predictor.info.architecture,
        "working_size": predictor.info.size,
        "size": size,
        "seed": seed,
        "interrupted": interrupted,
        "trials_finished": len(rows),
        "mean_ssim": mean("ssim"),
        "mean_psnr": mean("psnr"),
        "mean_param_l1": mean("param_l1"),
        "seconds_per_prediction": mean("seconds"),
        "psnr_cap": PSNR_CAP,
        "trials": rows,
    }
