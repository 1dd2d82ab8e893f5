"""How well a local model re-creates paired targets (``wise bench pairs``).

Every pair is taken whole: the model paints the photo's masks, the effect renders the photo
with them, and L1, PSNR and SSIM compare the result with the target; the same for the effect
at its preset, the baseline. For pairs of ``wise data adaptive`` (with ``regions/`` and a
``task.json``) the region where the predicted mask of the task's parameter departs from the
preset, by more than half the way to the value inside, is compared with the true region (IoU).
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import TextIO

import torch

from wise import effects, metrics
from wise.effects.base import Effect
from wise.interrupt import ctrl_c
from wise.io import atomic_path, read_image
from wise.ppn.predictor import LocalPredictor
from wise.train.local_settings import TASK_FILE, read_task
from wise.train.losses import total_variation
from wise.train.pairs import SPLITS, Pair, check_pairs, pairs_in

DEPARTURE_SHARE = 0.5
"""A mask departs from the preset where it has gone this share of the way to the task's value."""
REGION_THRESHOLD = 0.5


def bench_folder(folder: str | Path) -> Path:
    """The split folder to measure: ``folder`` itself when it holds the pairs, else its
    ``test/`` split."""
    path = Path(folder)
    if (path / "A").is_dir() or not any((path / split).is_dir() for split in SPLITS):
        return path
    return path / "test"


def pairs_task(folder: str | Path) -> dict:
    """The task of the pairs of :func:`bench_folder` (``task.json`` in the split folder or beside
    it; {} without one)."""
    split = bench_folder(folder)
    for place in (split, split.parent):
        if (place / TASK_FILE).is_file():
            return read_task(place)
    return {}


def read_pairs(folder: str | Path) -> tuple[list[Pair], dict]:
    """The checked pairs of :func:`bench_folder` and their task ({} without one)."""
    split = bench_folder(folder)
    pairs = pairs_in(split)
    check_pairs(pairs)
    return pairs, pairs_task(folder)


def baseline_params(effect: Effect, task: dict, settings: dict) -> tuple[torch.Tensor, str]:
    """The preset the baseline renders: the task's, else the one the model started from, else
    the defaults; and its name."""
    for name in (task.get("preset"), settings.get("start")):
        if isinstance(name, str) and name in effect.presets:
            return effect.preset(name), name
    return effect.default_params(), "defaults"


def _scores(result: torch.Tensor, target: torch.Tensor) -> dict[str, float]:
    return {
        "l1": metrics.l1(result, target),
        "psnr": metrics.psnr(result, target),
        "ssim": metrics.ssim(result, target),
    }


def region_iou(masks: torch.Tensor, region: torch.Tensor, effect: Effect, task: dict) -> float | None:
    """IoU of the true region and where the task's parameter departs from its preset value
    (None when the task does not say which parameter it changes, or both regions are empty)."""
    name, inside, outside = task.get("parameter"), task.get("inside"), task.get("preset_value")
    if name not in effect.param_names or not isinstance(inside, (int, float)) or not isinstance(outside, (int, float)):
        return None
    index = effect.param_names.index(name)
    spec = effect.param_specs[index]
    real = spec.min + (masks[:, index : index + 1] + 0.5) * (spec.max - spec.min)
    real = torch.nn.functional.interpolate(real, size=region.shape[-2:], mode="bilinear", align_corners=False)
    departed = (real - outside) * math.copysign(1.0, inside - outside) > DEPARTURE_SHARE * abs(inside - outside)
    truth = region > REGION_THRESHOLD
    union = (departed | truth).sum()
    if int(union) == 0:
        return None
    return float((departed & truth).sum() / union)


def _means(rows: list[dict], keys: tuple[str, ...], prefix: str = "") -> dict[str, float]:
    means = {}
    for key in keys:
        finite = [row[prefix + key] for row in rows if row.get(prefix + key) is not None]
        if finite:
            means[f"{prefix}mean_{key}"] = sum(finite) / len(finite)
    return means


def bench_pairs(
    model: str,
    effect_name: str,
    folder: str | Path,
    json_path: str | Path,
    device: torch.device | str = "cpu",
    out: TextIO = sys.stdout,
) -> dict:
    """Measure ``model`` on the pairs of ``folder`` and write the results to ``json_path``
    (atomically; Ctrl-C writes the pairs measured so far)."""
    effect = effects.create(effect_name)
    predictor = LocalPredictor(model, effect_name, device)
    pairs, task = read_pairs(folder)
    preset, preset_name = baseline_params(effect, task, predictor.info.settings)
    rows: list[dict] = []
    with ctrl_c(out) as interruption:
        for pair in pairs:
            if interruption.received:
                break
            photo, target = read_image(pair.photo), read_image(pair.target)
            with torch.no_grad():
                masks = predictor(photo)
                result = effect(photo, masks)
                baseline = effect(photo, preset[None])
            row = {"name": pair.name, **_scores(result, target)}
            row.update({f"baseline_{k}": v for k, v in _scores(baseline, target).items()})
            row["tv"] = float(total_variation(masks))
            if pair.region is not None:
                region = read_image(pair.region)[:, :1]
                row["iou"] = region_iou(masks, region, effect, task)
            rows.append(row)
    summary = {
        "model": predictor.info.source,
        "effect": effect.name,
        "pairs": str(folder),
        "task": task.get("task"),
        "baseline": preset_name,
        "count": len(rows),
        "interrupted": interruption.received,
        **_means(rows, ("l1", "psnr", "ssim", "tv", "iou")),
        **_means(rows, ("l1", "psnr", "ssim"), prefix="baseline_"),
        "rows": rows,
    }
    with atomic_path(json_path) as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2) + "\n")
    mean = {key: summary.get(key, math.nan) for key in ("mean_l1", "baseline_mean_l1", "mean_psnr", "mean_ssim")}
    line = (
        f"{len(rows)} pairs: L1 {mean['mean_l1']:.4f} (preset {mean['baseline_mean_l1']:.4f}), "
        f"PSNR {mean['mean_psnr']:.2f} dB, SSIM {mean['mean_ssim']:.4f}"
    )
    if "mean_iou" in summary:
        line += f", region IoU {summary['mean_iou']:.3f}"
    print(line + f"; {json_path}", file=out, flush=True)
    return summary
