"""Parameters predicted by a trained network (``wise predict``).

A global model (:class:`wise.ppn.predictor.Predictor`) predicts the global parameters that
re-create a stylized example of a photo in one forward pass; a short optimization within a
time budget refines them (:mod:`wise.optimize.refine`) unless asked not to. A local model
(:class:`wise.ppn.predictor.LocalPredictor`) paints the parameter masks from the photo alone.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import TextIO

import torch

from wise import effects, metrics
from wise.effects.base import Effect
from wise.io import atomic_path, read_image, write_image
from wise.optimize.refine import answers, refine
from wise.optimize.report import mask_sheet
from wise.optimize.run import match_target
from wise.optimize.settings import DEFAULT_BUDGET
from wise.paramfile import save_params
from wise.ppn.predictor import LocalPredictor, Predictor
from wise.render import render
from wise.threads import following_load

RESULT_FILES = ("params.safetensors", "result.png", "metrics.json")
MASKS_FILE = "masks.png"
"""A local model's masks, each as a heat map over its parameter's range."""
STAGE_FILE = "stage.png"
"""A translator's effect stage: the effect's output before its CNN."""
PREDICTED_FILE = "predicted.safetensors"
"""With refinement: the network's own prediction, which the refinement started from."""


def _scores(
    effect: Effect, content: torch.Tensor, target: torch.Tensor, params: torch.Tensor
) -> tuple[torch.Tensor, dict]:
    result = render(effect, content, params)
    scores = {
        "ssim": metrics.ssim(result, target),
        "psnr": metrics.psnr(result, target),
        "l1": metrics.l1(result, target),
    }
    return result, scores


@following_load()
def predict_files(
    effect_name: str,
    content_path: str,
    target_path: str,
    out_dir: str,
    model: str | None = None,
    refine_budget: float | None = DEFAULT_BUDGET,
    max_iterations: int | None = None,
    refine_mode: str = "global",
    device: torch.device | str = "cpu",
    out: TextIO = sys.stdout,
) -> dict:
    """Predict the parameters that re-create the target, refine them for ``refine_budget``
    seconds (:func:`wise.optimize.refine.refine`; None: the network alone), render the content
    with them at full resolution, and write :data:`RESULT_FILES` into ``out_dir``. The answer
    is whichever of the network alone and the refinement's answers
    (:func:`wise.optimize.refine.answers`) re-creates the target best (SSIM at full resolution,
    ties to the simpler); ``metrics.json`` names it. Returns the metrics: the result's, with the network's under
    ``network``."""
    effect = effects.create(effect_name)
    predictor = Predictor(model, effect_name, device)
    content = read_image(content_path)
    target = match_target(read_image(target_path), tuple(content.shape[-2:]), out, str(target_path), str(content_path))
    began = time.perf_counter()
    predicted = predictor(content, target)
    seconds = time.perf_counter() - began
    result, network_scores = _scores(effect, content, target, predicted)
    scores = {
        "effect": effect.name,
        "model": predictor.info.source,
        "architecture": predictor.info.architecture,
        "working_size": predictor.info.size,
        "seconds": round(seconds, 4),
        **network_scores,
        "params": effect.params_to_dict(predicted[0]),
        "network": {**network_scores, "seconds": round(seconds, 4)},
    }
    params, interrupted = predicted, False
    if refine_budget is not None and max_iterations != 0:
        outcome = refine(
            effect, content.to(device), target.to(device), predicted.to(device), refine_budget,
            mode=refine_mode, max_iterations=max_iterations,
        )  # fmt: skip
        interrupted = outcome.interrupted
        # every answer judged against the example at the size it was given, the network's too:
        # the answer is never worse than a simpler one
        judged = [("network", predicted, result, network_scores)]
        for name, answer in answers(outcome):
            if not torch.equal(answer.cpu(), predicted):
                judged.append((name, answer.cpu(), *_scores(effect, content, target, answer.cpu())))
        best = max(judged, key=lambda entry: entry[3]["ssim"])  # ties to the first, the simpler
        answer_name, params, result, refined_scores = best
        scores["refinement"] = {
            **refined_scores,
            "budget": refine_budget,
            "iterations": len(outcome.losses),
            "seconds": round(outcome.seconds, 2),
            "mode": refine_mode,
            "answer": answer_name,
            "why": "the highest SSIM against the example at its own size of the answers judged",
            "answers": {name: round(entry_scores["ssim"], 4) for name, _, _, entry_scores in judged},
            "left_out": list(outcome.left_out),
            "kept": answer_name != "network",
            "descent_kept": answer_name == "descent",
        }
        if answer_name != "network":
            scores.update(refined_scores)
            if params.dim() == 2:
                scores["params"] = effect.params_to_dict(params[0])
            else:
                scores.pop("params")
    scores["interrupted"] = interrupted
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    if "refinement" in scores:
        save_params(folder / PREDICTED_FILE, effect, predicted)
    save_params(folder / RESULT_FILES[0], effect, params)
    write_image(result, folder / RESULT_FILES[1])
    _write_json(folder / RESULT_FILES[2], scores)
    refined = scores.get("refinement")
    how = ""
    if refined is not None:
        verdict = f"answer: {refined['answer']}" if refined["kept"] else "the network alone scored highest"
        how = f", refined for {refined['seconds']:.1f} s ({refined['iterations']} iterations, {verdict})"
        if refined["left_out"]:
            how += f", {' and '.join(refined['left_out'])} left out to fit the budget at this machine's speed"
        if refined["iterations"] == 0:
            how += "; no descent: the readings took the budget (a larger --budget gives it time)"
    print(
        f"predicted in {seconds:.2f} s with {predictor.info.source}{how}: ssim {scores['ssim']:.4f}  "
        f"psnr {scores['psnr']:.2f} dB  l1 {scores['l1']:.4f}; result: {folder / 'result.png'}",
        file=out,
    )
    return scores


@following_load()
def predict_local_files(
    effect_name: str,
    content_path: str,
    out_dir: str,
    model: str,
    device: torch.device | str = "cpu",
    out: TextIO = sys.stdout,
) -> dict:
    """Paint the parameter masks of the content with a local model, render the content with
    them at full resolution, and write :data:`RESULT_FILES` and :data:`MASKS_FILE` into
    ``out_dir`` (the masks at the model's working size: ``wise apply --params`` and the
    editor enlarge them to any picture). Returns the metrics."""
    predictor = LocalPredictor(model, effect_name, device)
    if predictor.translates:
        return predict_translation_files(predictor, content_path, out_dir, out)
    effect = effects.create(effect_name)
    content = read_image(content_path)
    began = time.perf_counter()
    masks = predictor(content)
    seconds = time.perf_counter() - began
    result = render(effect, content, masks)
    real = effect.params_to_dict(masks.mean(dim=(2, 3))[0])
    scores = {
        "effect": effect.name,
        "model": predictor.info.source,
        "kind": "local",
        "architecture": predictor.info.architecture,
        "working_size": predictor.info.size,
        "masks_size": list(masks.shape[-2:]),
        "seconds": round(seconds, 4),
        "mean_params": real,
    }
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    save_params(folder / RESULT_FILES[0], effect, masks)
    write_image(result, folder / RESULT_FILES[1])
    with atomic_path(folder / MASKS_FILE) as tmp:
        mask_sheet(masks, effect.param_specs).save(tmp, format="PNG")
    _write_json(folder / RESULT_FILES[2], scores)
    print(
        f"masks painted in {seconds:.2f} s with {predictor.info.source}; result: {folder / RESULT_FILES[1]}; "
        f"masks: {folder / MASKS_FILE}",
        file=out,
    )
    return scores


def predict_translation_files(predictor: LocalPredictor, content_path: str, out_dir: str, out: TextIO) -> dict:
    """A translator's files (:mod:`wise.ppn.translation`), at its working size: ``result.png``
    (the final image), :data:`STAGE_FILE` (the effect stage) and, with an effect,
    ``params.safetensors`` (masks, or the preset it runs at) and :data:`MASKS_FILE` (painted
    masks); ``wise apply --model`` re-runs effect and CNN on edited masks."""
    content = read_image(content_path)
    began = time.perf_counter()
    made = predictor.stages(content)
    seconds = time.perf_counter() - began
    effect = predictor.effect
    scores = {
        "effect": predictor.info.effect,
        "model": predictor.info.source,
        "kind": "local",
        "architecture": predictor.info.architecture,
        "network": predictor.info.network,
        "working_size": predictor.info.size,
        "result_size": list(made.result.shape[-2:]),
        "seconds": round(seconds, 4),
    }
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    if effect is not None:
        save_params(folder / RESULT_FILES[0], effect, made.masks)
        write_image(made.stage.clamp(0.0, 1.0), folder / STAGE_FILE)
        if made.masks.dim() == 4:
            with atomic_path(folder / MASKS_FILE) as tmp:
                mask_sheet(made.masks, effect.param_specs).save(tmp, format="PNG")
    write_image(made.result, folder / RESULT_FILES[1])
    _write_json(folder / RESULT_FILES[2], scores)
    print(f"translated in {seconds:.2f} s with {predictor.info.source}; result: {folder / RESULT_FILES[1]}", file=out)
    return scores


def _write_json(path: Path, value: dict) -> None:
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(value, indent=2) + "\n")
