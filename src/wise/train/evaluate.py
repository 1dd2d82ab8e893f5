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
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np
import torch

from wise import effects, metrics
from wise.effects.base import Effect, window_scale
from wise.fidelity.fid import frechet_distance
from wise.interrupt import ctrl_c
from wise.io import atomic_path, read_image
from wise.ppn.predictor import LocalPredictor
from wise.ppn.translation import NO_EFFECT, Stages
from wise.train.choices import TASK_FILE
from wise.train.local_settings import read_task
from wise.train.losses import total_variation
from wise.train.pairs import SPLITS, Pair, check_pairs, dataset_root, pairs_in
from wise.train.pairs_page import PAGE_PAIRS, write_pairs_page

DEPARTURE_SHARE = 0.5
"""A mask departs from the preset where it has gone this share of the way to the task's value."""
REGION_THRESHOLD = 0.5


def bench_folder(folder: str | Path) -> Path:
    """The split folder to measure: ``folder`` itself when it holds the pairs, else its
    ``test/`` split."""
    path = dataset_root(folder)
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


def translator_baseline(effect: Effect, start: torch.Tensor) -> tuple[torch.Tensor, str]:
    """A translator's baseline: the effect at the preset it starts from (or runs at), named
    when it is one of the effect's presets."""
    for name in effect.presets:
        if torch.allclose(effect.preset(name), start, atol=1e-3):
            return start, name
    if torch.allclose(effect.default_params(), start, atol=1e-3):
        return start, "defaults"
    return start, "the model's start values"


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


@dataclass
class PerceptualMetrics:
    """The networks of the optional metrics: FID's Inception (:func:`wise.fidelity.load_inception`)
    and LPIPS (:func:`wise.fidelity.load_lpips`), each None when not asked for. Load them
    before the work starts, so that missing weight files are refused at once."""

    inception: torch.nn.Module | None = None
    lpips: torch.nn.Module | None = None
    result_features: list[np.ndarray] = field(default_factory=list)
    target_features: list[np.ndarray] = field(default_factory=list)

    def add(self, result: torch.Tensor, target: torch.Tensor, row: dict) -> None:
        """Measure one pair: its LPIPS into ``row``, its Inception features kept for FID."""
        with torch.no_grad():
            if self.lpips is not None:
                row["lpips"] = float(self.lpips(result.clamp(0.0, 1.0), target)[0])
            if self.inception is not None:
                self.result_features.append(self.inception(result.clamp(0.0, 1.0)).double().numpy())
                self.target_features.append(self.inception(target).double().numpy())

    def fid(self) -> float | None:
        """FID between the results and the targets measured (None without Inception or with
        fewer than two pairs)."""
        if self.inception is None or len(self.result_features) < 2:
            return None
        moments = []
        for features in (np.concatenate(self.result_features), np.concatenate(self.target_features)):
            moments += [features.mean(axis=0), np.cov(features, rowvar=False)]
        return frechet_distance(*moments)


def _measure(
    predictor: LocalPredictor,
    effect: Effect | None,
    preset: torch.Tensor | None,
    pair: Pair,
    task: dict,
    perceptual: PerceptualMetrics | None = None,
) -> tuple[dict, Stages]:
    """The row of one pair and its stages (masks, effect stage, result)."""
    photo, target = read_image(pair.photo), read_image(pair.target)
    with torch.no_grad():
        if predictor.translates:
            made = predictor.stages(photo)
            made = Stages(made.masks, _at(made.stage, target), _at(made.result, target))
        else:
            masks = predictor(photo)
            result = effect(photo, masks, scale=window_scale(*photo.shape[-2:]))
            made = Stages(masks, result, result)
        row = {"name": pair.name, **_scores(made.result, target)}
        if perceptual is not None:
            perceptual.add(made.result, target, row)
        if predictor.translates and effect is not None and predictor.network.post is not None:
            row.update({f"stage_{k}": v for k, v in _scores(made.stage.clamp(0.0, 1.0), target).items()})
        if effect is not None and preset is not None:
            baseline = effect(photo, preset[None], scale=window_scale(*photo.shape[-2:]))
            row.update({f"baseline_{k}": v for k, v in _scores(baseline, target).items()})
    if made.masks is not None and made.masks.dim() == 4:
        row["tv"] = float(total_variation(made.masks))
        if pair.region is not None:
            region = read_image(pair.region)[:, :1]
            row["iou"] = region_iou(made.masks, region, effect, task)
    return row, made


def _at(image: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """``image`` at the size of ``target`` (a translator works at its model's size)."""
    if image.shape[-2:] == target.shape[-2:]:
        return image
    return torch.nn.functional.interpolate(image, size=target.shape[-2:], mode="bilinear", align_corners=False)


def bench_pairs(
    model: str,
    effect_name: str,
    folder: str | Path,
    json_path: str | Path,
    device: torch.device | str = "cpu",
    out: TextIO = sys.stdout,
    html_path: str | Path | None = None,
    perceptual: PerceptualMetrics | None = None,
) -> dict:
    """Measure ``model`` on the pairs of ``folder`` and write the results to ``json_path``
    (atomically; Ctrl-C writes the pairs measured so far); with ``html_path``, a results
    page of the first pairs (:func:`wise.train.pairs_page.write_pairs_page`)."""
    effect = None if effect_name == NO_EFFECT else effects.create(effect_name)
    predictor = LocalPredictor(model, effect_name, device)
    pairs, task = read_pairs(folder)
    preset, preset_name = (None, None) if effect is None else baseline_params(effect, task, predictor.info.settings)
    if effect is not None and predictor.translates:
        preset, preset_name = translator_baseline(effect, predictor.network.start.float().cpu())
    rows: list[dict] = []
    shown: list[tuple[Pair, Stages]] = []
    with ctrl_c(out) as interruption:
        for pair in pairs:
            if interruption.received:
                break
            row, made = _measure(predictor, effect, preset, pair, task, perceptual)
            rows.append(row)
            if html_path is not None and len(shown) < PAGE_PAIRS:
                shown.append((pair, made))
    summary = {
        "model": predictor.info.source,
        "effect": effect_name,
        "pairs": str(folder),
        "task": task.get("task"),
        "baseline": preset_name,
        "count": len(rows),
        "interrupted": interruption.received,
        **_means(rows, ("l1", "psnr", "ssim", "lpips", "tv", "iou")),
        **_means(rows, ("l1", "psnr", "ssim"), prefix="stage_"),
        **_means(rows, ("l1", "psnr", "ssim"), prefix="baseline_"),
        "rows": rows,
    }
    fid = perceptual.fid() if perceptual is not None else None
    if fid is not None:
        summary["fid"] = fid
    with atomic_path(json_path) as tmp:
        Path(tmp).write_text(json.dumps(summary, indent=2) + "\n")
    if html_path is not None:
        write_pairs_page(html_path, summary, shown, effect)
    print(summary_line(summary) + f"; {json_path}", file=out, flush=True)
    return summary


def summary_line(summary: dict) -> str:
    """One line of the means of :func:`bench_pairs`."""
    mean = {key: summary.get(key, math.nan) for key in ("mean_l1", "baseline_mean_l1", "mean_psnr", "mean_ssim")}
    line = f"{summary['count']} pairs: L1 {mean['mean_l1']:.4f}"
    if "baseline_mean_l1" in summary:
        line += f" (preset {mean['baseline_mean_l1']:.4f})"
    line += f", PSNR {mean['mean_psnr']:.2f} dB, SSIM {mean['mean_ssim']:.4f}"
    if "mean_lpips" in summary:
        line += f", LPIPS {summary['mean_lpips']:.4f}"
    if "fid" in summary:
        line += f", FID {summary['fid']:.2f}"
    if "stage_mean_l1" in summary:
        line += f"; effect stage L1 {summary['stage_mean_l1']:.4f}"
    if "mean_iou" in summary:
        line += f", region IoU {summary['mean_iou']:.3f}"
    return line
