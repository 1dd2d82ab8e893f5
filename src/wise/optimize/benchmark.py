"""The functional benchmark of the WISE supplement: can optimization recover random parameters?

Seeded random global parameters render a reference from a photo; optimization starts from the
effect's defaults (or from the parameters a trained model predicts, ``init="ppn"``) and tries
to match it: half the iterations coarse to fine on reduced copies,
the other half on random crops at full resolution, where details too fine for a reduced copy
(brush texture, thin lines) can be matched; SSIM and PSNR measure how close it gets.
"""

from __future__ import annotations

import json
import statistics
import sys
from pathlib import Path
from typing import Callable, TextIO

import torch
import torch.nn.functional as F

from wise import effects, metrics
from wise.effects.base import Effect
from wise.errors import WiseError
from wise.interrupt import ctrl_c
from wise.io import READ_FORMATS, atomic_path, read_image
from wise.optimize.parametric import (
    CROP_SIZE,
    Outcome,
    Settings,
    describe_levels,
    optimize_coarse_to_fine,
    optimize_on_crops,
    pyramid,
)

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".webp", ".tif", ".tiff"}
PSNR_CAP = 60.0
"""PSNR counted for a recovered image identical to the reference (beyond 8-bit precision)."""
MIN_REFERENCE_CONTRAST = 0.05
"""Random parameters whose reference has a smaller standard deviation (a nearly blank image,
which any parameters near the edge of a range reproduce) are drawn again."""
MAX_DRAWS = 20
LEVELS = ((8, 0.5, 1.0), (4, 0.25, 0.5), (2, 0.15, 0.25), (1, 0.1, 0.25))
"""Coarse-to-fine schedule of the first :data:`COARSE_SHARE` of the iterations: (reduction, share,
factor on the learning rate). Global parameters carry over between resolutions, so these run
mostly on small copies (64 px short side at the default 512 px)."""
COARSE_SHARE = 0.5
CROP_LR = 0.3
"""Factor on the learning rate for the iterations on full-resolution crops: a refinement."""


def schedule(iterations: int, lr: float, loss: str) -> tuple[tuple[tuple[int, Settings], ...], Settings | None]:
    """The levels of :data:`LEVELS` and the settings of the crop iterations (None when there are
    too few iterations for both) for ``iterations`` in all."""
    coarse = max(1, round(iterations * COARSE_SHARE))
    levels = pyramid(Settings(mode="global", iterations=coarse, lr=lr, loss=loss), LEVELS)
    if coarse == iterations:
        return levels, None
    return levels, Settings(mode="global", iterations=iterations - coarse, lr=lr * CROP_LR, loss=loss)


def describe_schedule(levels: tuple[tuple[int, Settings], ...], crops: Settings | None) -> list[dict[str, float]]:
    """JSON-ready rows of :func:`schedule`: the levels, then the crops (with their size)."""
    rows = describe_levels(levels)
    if crops is not None:
        rows.append({"reduction": 1, "iterations": crops.iterations, "lr": crops.lr, "crop": CROP_SIZE})
    return rows


def random_reference(
    effect: Effect, content: torch.Tensor, generator: torch.Generator
) -> tuple[torch.Tensor, torch.Tensor]:
    """Random normalized global parameters (1, P) and the reference they render, redrawn while
    the reference is nearly blank."""
    for _ in range(MAX_DRAWS):
        truth = torch.rand(1, len(effect.param_specs), generator=generator) - 0.5
        with torch.no_grad():
            reference = effect(content, truth)
        if float(reference.std()) >= MIN_REFERENCE_CONTRAST:
            break
    return truth, reference


def photos_in(folder: str) -> list[Path]:
    """The images of a folder, sorted by name."""
    path = Path(folder)
    if not path.is_dir():
        raise WiseError(f"{path}: not a directory of images")
    found = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not found:
        raise WiseError(f"{path}: no images ({', '.join(READ_FORMATS.values())}) found")
    return found


def content_at(photo: torch.Tensor, size: int) -> torch.Tensor:
    """The photo with its short side at ``size``."""
    factor = size / min(photo.shape[-2:])
    shape = (max(8, round(photo.shape[-2] * factor)), max(8, round(photo.shape[-1] * factor)))
    return F.interpolate(photo, size=shape, mode="area" if factor < 1 else "bilinear")


INIT_DEFAULTS = "defaults"
INIT_PPN = "ppn"


def parse_init(init: str) -> tuple[str, str | None]:
    """``defaults``, ``ppn`` (the built-in model) or ``ppn:MODEL`` -> (kind, model file or None)."""
    kind, _, model = init.partition(":")
    if kind == INIT_DEFAULTS and not model:
        return kind, None
    if kind == INIT_PPN:
        return kind, model or None
    raise WiseError(f"--init {init!r}: use {INIT_DEFAULTS}, {INIT_PPN} or {INIT_PPN}:MODEL")


def _trial(
    effect: Effect,
    content: torch.Tensor,
    generator: torch.Generator,
    levels: tuple[tuple[int, Settings], ...],
    crops: Settings | None,
    crop_seed: int,
    predictor: Callable[[torch.Tensor, torch.Tensor], torch.Tensor] | None = None,
) -> tuple[torch.Tensor, torch.Tensor, Outcome]:
    """One trial: random parameters, their reference, and the optimization's outcome."""
    truth, reference = random_reference(effect, content, generator)
    start = effect.default_params() if predictor is None else predictor(content, reference)
    outcome = optimize_coarse_to_fine(effect, content, reference, start, levels)
    if crops is not None and not outcome.interrupted:
        coarse_seconds = outcome.seconds
        crop_generator = torch.Generator().manual_seed(crop_seed)
        outcome = optimize_on_crops(effect, content, reference, outcome.params, crops, crop_generator)
        outcome.seconds += coarse_seconds
    return truth, reference, outcome


def recover(
    effect_name: str,
    images_dir: str,
    trials: int = 10,
    size: int = 512,
    seed: int = 0,
    iterations: int = 300,
    lr: float = 0.1,
    loss: str = "l2",
    json_path: str | None = None,
    out: TextIO = sys.stdout,
    init: str = INIT_DEFAULTS,
) -> dict:
    """Run the benchmark; prints a table and returns (and optionally writes) the results.

    The photos of the trials are read before the first one starts. Ctrl-C ends the run: the
    trial in progress is dropped, and the results of the finished ones are written with
    ``"interrupted": true``.
    """
    if trials < 1:
        raise WiseError(f"--trials must be at least 1, got {trials}")
    effect = effects.create(effect_name)
    init_kind, model = parse_init(init)
    predictor = None
    if init_kind == INIT_PPN:
        from wise.predict import Predictor

        predictor = Predictor(model, effect_name)
    photos = photos_in(images_dir)[:trials]
    contents = {path: content_at(read_image(path), size) for path in photos}
    generator = torch.Generator().manual_seed(seed)
    levels, crops = schedule(iterations, lr, loss)
    rows: list[dict] = []
    print("| trial | image | SSIM | PSNR |\n| --- | --- | --- | --- |", file=out)
    with ctrl_c(out) as interruption:
        try:
            for trial in range(trials):
                photo_path = photos[trial % len(photos)]
                truth, reference, outcome = _trial(
                    effect, contents[photo_path], generator, levels, crops, seed * 1_000_003 + trial, predictor
                )
                if outcome.interrupted:
                    raise KeyboardInterrupt
                rows.append(_row(effect, trial, photo_path, truth, reference, outcome))
                print(_table_row(rows[-1]), file=out, flush=True)
        except KeyboardInterrupt:
            print(f"interrupted: {len(rows)} of {trials} trials finished", file=out, flush=True)
        interruption.hold()
        result = _summary(effect_name, size, iterations, loss, seed, levels, crops, rows, interruption.received)
        result["init"] = init if predictor is None else f"{INIT_PPN}:{predictor.info.source}"
        if rows:
            print(f"mean SSIM {result['mean_ssim']:.4f}, mean PSNR {result['mean_psnr']:.2f} dB", file=out)
        if json_path is not None:
            with atomic_path(json_path) as path:
                Path(path).write_text(json.dumps(result, indent=2) + "\n")
    result["interrupted"] = interruption.received
    return result


def _row(
    effect: Effect, trial: int, photo: Path, truth: torch.Tensor, reference: torch.Tensor, outcome: Outcome
) -> dict:
    assert outcome.result is not None
    return {
        "trial": trial,
        "image": photo.name,
        "ssim": metrics.ssim(outcome.result, reference),
        "psnr": min(PSNR_CAP, metrics.psnr(outcome.result, reference)),
        "true_params": effect.params_to_dict(truth[0]),
        "found_params": effect.params_to_dict(outcome.params[0]),
        "seconds": round(outcome.seconds, 2),
    }


def _table_row(row: dict) -> str:
    return f"| {row['trial']} | {row['image']} | {row['ssim']:.4f} | {row['psnr']:.2f} |"


def _summary(
    effect_name: str,
    size: int,
    iterations: int,
    loss: str,
    seed: int,
    levels: tuple[tuple[int, Settings], ...],
    crops: Settings | None,
    rows: list[dict],
    interrupted: bool,
) -> dict:
    """The JSON-ready results; the means are None when no trial finished."""
    return {
        "effect": effect_name,
        "size": size,
        "iterations": iterations,
        "loss": loss,
        "seed": seed,
        "interrupted": interrupted,
        "trials_finished": len(rows),
        "mean_ssim": statistics.fmean(r["ssim"] for r in rows) if rows else None,
        "mean_psnr": statistics.fmean(r["psnr"] for r in rows) if rows else None,
        "psnr_cap": PSNR_CAP,
        "levels": describe_schedule(levels, crops),
        "trials": rows,
    }
