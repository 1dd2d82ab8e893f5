"""The parameter prediction benchmark of the WISE supplement (``wise bench ppn``).

Seeded random global parameters render an example from a photo (redrawn while the example is
nearly blank, as in :mod:`wise.optimize.benchmark`); the model predicts the parameters from
photo and example; the effect re-renders the photo with them. Scores: SSIM and PSNR of the
re-rendering against the example, and the mean absolute error of the normalized parameters.
With a refinement budget, each trial also refines the prediction as ``wise predict`` does
(:func:`wise.optimize.refine.refine`) and scores the refined parameters and the whole time.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import TextIO

import torch

from wise import effects, metrics
from wise.optimize.inversion import invert_steps, invertible
from wise.optimize.parametric import Outcome
from wise.optimize.refine import answers, refine
from wise.optimize.trials import PSNR_CAP, Column, mean_of, random_reference, run_trials
from wise.ppn.predictor import Predictor


def _answer_kind(outcome: Outcome, final: torch.Tensor) -> str:
    """Which of the refinement's answers ``final`` is: ``descent``, ``after descent`` or ``read``."""
    if final is outcome.params:
        return "descent"
    return "after descent" if any(final is answer for answer in outcome.settled) else "read"


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
) -> dict:
    """Run the benchmark; prints a table, returns (and optionally writes) the results. Ctrl-C
    ends it after the trial in progress; the finished trials are written with ``"interrupted": true``."""
    effect = effects.create(effect_name)
    predictor = Predictor(model, effect_name, device)

    def score(content: torch.Tensor, example: torch.Tensor, params: torch.Tensor) -> tuple[float, float]:
        with torch.no_grad():
            rendered = effect(content, params).clamp(0.0, 1.0)
        return metrics.ssim(rendered, example), min(PSNR_CAP, metrics.psnr(rendered, example))

    def trial(number: int, path: Path, content: torch.Tensor, generator: torch.Generator) -> dict:
        truth, example = random_reference(effect, content, generator)
        began = time.perf_counter()
        predicted = predictor(content, example)
        seconds = time.perf_counter() - began
        ssim, psnr = score(content, example, predicted)
        row = {
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
            scored = [(answer, *score(content, example, answer)) for answer in answers(outcome)]
            final, refined_ssim, refined_psnr = max(scored, key=lambda s: s[1])  # as wise predict
            kept = refined_ssim >= ssim
            row["refined"] = {
                "ssim": refined_ssim if kept else ssim,
                "psnr": refined_psnr if kept else psnr,
                "param_l1": float(((final if kept else predicted) - truth).abs().mean()),
                "kept": kept,
                "iterations": len(outcome.losses),
                "seconds": round(seconds + outcome.seconds, 2),
                "params": effect.params_to_dict((final if kept else predicted)[0]),
                "descent_kept": final is outcome.params,
                "answer": _answer_kind(outcome, final),
            }
            row.update({f"refined_{key}": row["refined"][key] for key in ("ssim", "psnr", "seconds")})
        return row

    def summarize(rows: list[dict], interrupted: bool) -> dict:
        summary = {
            "effect": effect_name,
            "model": predictor.info.source,
            "architecture": predictor.info.architecture,
            "working_size": predictor.info.size,
            "size": size,
            "seed": seed,
            "trials_finished": len(rows),
            "mean_ssim": mean_of(rows, "ssim"),
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
                "mean_psnr": mean_of(rows, "refined_psnr"),
                "mean_seconds": mean_of(rows, "refined_seconds"),
            }
        if rows:
            print(
                f"mean SSIM {summary['mean_ssim']:.4f}, mean PSNR {summary['mean_psnr']:.2f} dB, "
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
                    f"refined: mean SSIM {refined['mean_ssim']:.4f}, mean PSNR {refined['mean_psnr']:.2f} dB, "
                    f"{refined['mean_seconds']:.1f} s per trial",
                    file=out,
                )
        return summary

    columns = [Column("SSIM", "ssim"), Column("PSNR", "psnr", ".2f"), Column("param L1", "param_l1")]
    if invertible(effect):
        columns += [Column("read SSIM", "read_ssim"), Column("read param L1", "read_param_l1")]
    if refine_budget is not None:
        columns += [Column("refined SSIM", "refined_ssim"), Column("refined PSNR", "refined_psnr", ".2f")]
    return run_trials(images_dir, trials, size, seed, trial, columns, summarize, json_path, out)
