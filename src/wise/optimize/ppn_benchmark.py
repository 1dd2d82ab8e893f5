"""The parameter prediction benchmark of the WISE supplement (``wise bench ppn``).

Two sets of examples: seeded random global parameters render an example from a photo (redrawn
while the example is nearly blank, as in :mod:`wise.optimize.benchmark`), and examples as users
make them, the effect's presets in turn with one to three parameters moved far
(:func:`~wise.optimize.trials.preset_reference`). The model predicts the parameters from photo
and example; the effect re-renders the photo with them, as ``wise apply`` renders. Scores: SSIM and PSNR of the
re-rendering against the example, and the mean absolute error of the normalized parameters.
With a refinement budget, each trial also refines the prediction as ``wise predict`` does
(:func:`wise.optimize.refine.refine`) and scores the refined parameters and the whole time.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import TextIO

import torch

from wise import effects, metrics
from wise.io import atomic_path
from wise.optimize.inversion import invert_steps, invertible
from wise.optimize.refine import answers, refine
from wise.optimize.trials import PSNR_CAP, Column, mean_of, preset_reference, random_reference, run_trials, worst_of
from wise.ppn.predictor import Predictor
from wise.render import render

EXAMPLES = ("random", "presets", "both")
"""The sets of examples ``bench_ppn`` can run."""


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
    refine_budget: float | None = None,
    examples: str = "both",
) -> dict:
    """Run the benchmark on the ``examples`` set (:data:`EXAMPLES`); prints a table per set,
    returns (and optionally writes) the results: the random set's summary with the presets'
    under ``presets`` (or the one set run). Ctrl-C ends it after the trial in progress; the
    finished trials are written with ``"interrupted": true``."""
    if examples not in EXAMPLES:
        raise ValueError(f"examples must be one of {EXAMPLES}, got {examples!r}")
    effect = effects.create(effect_name)
    predictor = Predictor(model, effect_name, device)
    made_from_presets = False

    def score(content: torch.Tensor, example: torch.Tensor, params: torch.Tensor) -> tuple[float, float]:
        rendered = render(effect, content, params).clamp(0.0, 1.0)
        return metrics.ssim(rendered, example), min(PSNR_CAP, metrics.psnr(rendered, example))

    def trial(number: int, path: Path, content: torch.Tensor, generator: torch.Generator) -> dict:
        made: dict = {}
        if made_from_presets:
            truth, example, made = preset_reference(effect, content, generator, number)
        else:
            truth, example = random_reference(effect, content, generator)
        began = time.perf_counter()
        predicted = predictor(content, example)
        seconds = time.perf_counter() - began
        ssim, psnr = score(content, example, predicted)
        row = {
            **made,
            "ssim": ssim,
            "psnr": psnr,
            "param_l1": float((predicted - truth).abs().mean()),
            "seconds": round(seconds, 4),
            "true_params": effect.params_to_dict(truth[0]),
            "predicted_params": effect.params_to_dict(predicted[0]),
        }
        if invertible(effect):
            # the network's answer with the staircase parameters read off the example instead
            read = invert_steps(effect, content, example, predicted)
            row["read_ssim"], row["read_psnr"] = score(content, example, read)
            row["read_param_l1"] = float((read - truth).abs().mean())
            row["read_params"] = effect.params_to_dict(read[0])
        if refine_budget is not None:
            outcome = refine(effect, content, example, predicted, refine_budget)
            if outcome.interrupted:
                raise KeyboardInterrupt
            # as wise predict: the best of the network alone and the refinement's answers
            judged = [("network", predicted, ssim, psnr)]
            judged += [(name, answer, *score(content, example, answer)) for name, answer in answers(outcome)]
            name, final, refined_ssim, refined_psnr = max(judged, key=lambda entry: entry[2])
            row["refined"] = {
                "ssim": refined_ssim,
                "psnr": refined_psnr,
                "param_l1": float((final - truth).abs().mean()),
                "kept": name != "network",
                "iterations": len(outcome.losses),
                "seconds": round(seconds + outcome.seconds, 2),
                "params": effect.params_to_dict(final[0]),
                "descent_kept": name == "descent",
                "answer": name,
            }
            row.update({f"refined_{key}": row["refined"][key] for key in ("ssim", "psnr", "seconds")})
        return row

    def summarize(rows: list[dict], interrupted: bool) -> dict:
        summary = {
            "effect": effect_name,
            "examples": "presets" if made_from_presets else "random",
            "model": predictor.info.source,
            "architecture": predictor.info.architecture,
            "working_size": predictor.info.size,
            "size": size,
            "seed": seed,
            "trials_finished": len(rows),
            "mean_ssim": mean_of(rows, "ssim"),
            "worst_ssim": worst_of(rows, "ssim"),
            "mean_psnr": mean_of(rows, "psnr"),
            "mean_param_l1": mean_of(rows, "param_l1"),
            "seconds_per_prediction": mean_of(rows, "seconds"),
            "refine_budget": refine_budget,
            "psnr_cap": PSNR_CAP,
            "trials": rows,
        }
        if invertible(effect):
            summary["read"] = {
                "mean_ssim": mean_of(rows, "read_ssim"),
                "mean_psnr": mean_of(rows, "read_psnr"),
                "mean_param_l1": mean_of(rows, "read_param_l1"),
            }
        if refine_budget is not None:
            summary["refined"] = {
                "mean_ssim": mean_of(rows, "refined_ssim"),
                "worst_ssim": worst_of(rows, "refined_ssim"),
                "mean_psnr": mean_of(rows, "refined_psnr"),
                "mean_seconds": mean_of(rows, "refined_seconds"),
            }
        if rows:
            print(
                f"mean SSIM {summary['mean_ssim']:.4f} (worst {summary['worst_ssim']:.4f}), "
                f"mean PSNR {summary['mean_psnr']:.2f} dB, "
                f"mean parameter L1 {summary['mean_param_l1']:.4f}, "
                f"{summary['seconds_per_prediction']:.3f} s per prediction",
                file=out,
            )
            if "read" in summary:
                read = summary["read"]
                print(
                    f"with the staircase read off the example: mean SSIM {read['mean_ssim']:.4f}, "
                    f"mean PSNR {read['mean_psnr']:.2f} dB, mean parameter L1 {read['mean_param_l1']:.4f}",
                    file=out,
                )
            if refine_budget is not None:
                refined = summary["refined"]
                print(
                    f"refined: mean SSIM {refined['mean_ssim']:.4f} (worst {refined['worst_ssim']:.4f}), "
                    f"mean PSNR {refined['mean_psnr']:.2f} dB, "
                    f"{refined['mean_seconds']:.1f} s per trial",
                    file=out,
                )
        return summary

    columns = [Column("SSIM", "ssim"), Column("PSNR", "psnr", ".2f"), Column("param L1", "param_l1")]
    if invertible(effect):
        columns += [Column("read SSIM", "read_ssim"), Column("read param L1", "read_param_l1")]
    if refine_budget is not None:
        columns += [Column("refined SSIM", "refined_ssim"), Column("refined PSNR", "refined_psnr", ".2f")]
    result: dict | None = None
    if examples in ("random", "both"):
        print("examples with random parameters:", file=out, flush=True)
        result = run_trials(images_dir, trials, size, seed, trial, columns, summarize, None, out)
    if examples in ("presets", "both") and not (result is not None and result["interrupted"]):
        made_from_presets = True
        print("examples made from presets, one to three parameters moved far:", file=out, flush=True)
        presets = run_trials(
            images_dir, trials, size, seed, trial, [Column("preset", "preset", "s"), *columns], summarize, None, out
        )
        if result is None:
            result = presets
        else:
            result["presets"] = presets
            result["interrupted"] = presets["interrupted"]
    assert result is not None
    if json_path is not None:
        with atomic_path(json_path) as tmp:
            Path(tmp).write_text(json.dumps(result, indent=2) + "\n")
    return result
