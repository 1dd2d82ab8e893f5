"""The functional benchmark of the WISE supplement: can optimization recover random parameters?

Seeded random global parameters render a reference from a photo; optimization starts from the
effect's defaults (or from the parameters a trained model predicts, ``init="ppn"``) and tries
to match it: half the iterations coarse to fine on reduced copies, then a grid search at full
size of the parameters the effect names as out of the gradient's reach
(:mod:`wise.optimize.search`), then the other half on random crops at full resolution, where
details too fine for a reduced copy (brush texture, thin lines) can be matched, kept where the
whole image is closer for them; SSIM and PSNR measure how close it gets.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable, TextIO

import torch

from wise import effects, metrics
from wise.effects.base import Effect
from wise.errors import WiseError
from wise.optimize.inversion import inversion_between_levels, read_starts
from wise.optimize.parametric import (
    CROP_SIZE,
    Outcome,
    Settings,
    closest,
    describe_levels,
    optimize_coarse_to_fine,
    optimize_on_crops,
    pyramid,
)
from wise.optimize.search import coordinate_search
from wise.optimize.settings import INIT_DEFAULTS, INIT_PPN, RECOVER_ITERATIONS, parse_init
from wise.optimize.trials import PSNR_CAP, Column, mean_of, random_reference, run_trials
from wise.ppn.predictor import Predictor

LEVELS = ((8, 0.5, 1.0), (4, 0.25, 0.5), (2, 0.15, 0.25), (1, 0.1, 0.25))
"""Coarse-to-fine schedule of the first :data:`COARSE_SHARE` of the iterations: (reduction, share,
factor on the learning rate). Global parameters carry over between resolutions, so these run
mostly on small copies (64 px short side at the default 512 px)."""
COARSE_SHARE = 0.5
CROP_LR = 0.3
"""Factor on the learning rate for the iterations on full-resolution crops: a refinement."""


def schedule(
    iterations: int, lr: float, loss: str, anneal: float = 0.0
) -> tuple[tuple[tuple[int, Settings], ...], Settings | None]:
    """The levels of :data:`LEVELS` and the settings of the crop iterations (None when there are
    too few iterations for both) for ``iterations`` in all; ``anneal`` is the step temperature
    at the start of the coarsest level."""
    coarse = max(1, round(iterations * COARSE_SHARE))
    levels = pyramid(Settings(mode="global", iterations=coarse, lr=lr, loss=loss, anneal=anneal), LEVELS)
    if coarse == iterations:
        return levels, None
    return levels, Settings(mode="global", iterations=iterations - coarse, lr=lr * CROP_LR, loss=loss)


def describe_schedule(levels: tuple[tuple[int, Settings], ...], crops: Settings | None) -> list[dict[str, float]]:
    """JSON-ready rows of :func:`schedule`: the levels, then the crops (with their size)."""
    rows = describe_levels(levels)
    if crops is not None:
        rows.append({"reduction": 1, "iterations": crops.iterations, "lr": crops.lr, "crop": CROP_SIZE})
    return rows


def _trial(
    effect: Effect,
    content: torch.Tensor,
    generator: torch.Generator,
    levels: tuple[tuple[int, Settings], ...],
    crops: Settings | None,
    crop_seed: int,
    predictor: Callable[[torch.Tensor, torch.Tensor], torch.Tensor] | None = None,
) -> tuple[torch.Tensor, torch.Tensor, Outcome]:
    """One trial: random parameters, their reference, and the optimization's outcome: from each
    start that the reading leaves (:func:`wise.optimize.inversion.read_starts`), the one that ends
    closest, its time that of all starts."""
    truth, reference = random_reference(effect, content, generator, at_reference=False)
    start = effect.default_params() if predictor is None else predictor(content, reference)
    began = time.perf_counter()
    starts, held = read_starts(effect, content, reference, start.reshape(1, -1))
    levels = tuple((reduction, replace(settings, held=held)) for reduction, settings in levels)
    crops = None if crops is None else replace(crops, held=held)
    outcomes = []
    for params in starts:
        outcomes.append(_descend(effect, content, reference, params, levels, crops, crop_seed))
        if outcomes[-1].interrupted:
            return truth, reference, outcomes[-1]
    loss = levels[-1][1].loss
    # descent can end further from the reference than a reading it started from (the coarse
    # levels' reduced looks pull it away): the starts are answers too, as in wise predict
    best = closest(effect, content, reference, [*(outcome.params for outcome in outcomes), *starts], loss)
    if any(best is start for start in starts):
        with torch.no_grad():
            outcome = replace(outcomes[0], params=best, result=effect(content, best))
    else:
        outcome = next(outcome for outcome in outcomes if outcome.params is best)
    outcome.seconds = time.perf_counter() - began  # the reading and every start included
    return truth, reference, outcome


def _descend(
    effect: Effect,
    content: torch.Tensor,
    reference: torch.Tensor,
    start: torch.Tensor,
    levels: tuple[tuple[int, Settings], ...],
    crops: Settings | None,
    crop_seed: int,
) -> Outcome:
    """Coarse to fine from ``start`` (the steps read again between the levels), the grid search of
    the effect's searched parameters, then the crops, kept where the whole image is closer."""
    between = inversion_between_levels(effect, content, reference)
    outcome = optimize_coarse_to_fine(effect, content, reference, start, levels, between_levels=between)
    if between is not None and not outcome.interrupted:
        outcome.params = between(outcome.params)
        with torch.no_grad():
            outcome.result = effect(content, outcome.params)
    if effect.searched_params and not outcome.interrupted:
        outcome.params, _ = coordinate_search(effect, content, reference, outcome.params)
        with torch.no_grad():
            outcome.result = effect(content, outcome.params)
    if crops is not None and not outcome.interrupted:
        coarse = outcome
        crop_generator = torch.Generator().manual_seed(crop_seed)
        outcome = optimize_on_crops(effect, content, reference, coarse.params, crops, crop_generator)
        outcome.losses = coarse.losses + outcome.losses
        if not outcome.interrupted:
            # a cartoon's hard steps move with every crop: they can leave the whole image worse
            outcome.params = closest(effect, content, reference, [coarse.params, outcome.params], crops.loss)
            with torch.no_grad():
                outcome.result = effect(content, outcome.params)
    return outcome


def recover(
    effect_name: str,
    images_dir: str,
    trials: int = 10,
    size: int = 512,
    seed: int = 0,
    iterations: int = RECOVER_ITERATIONS,
    lr: float = 0.1,
    loss: str = "l2",
    json_path: str | None = None,
    out: TextIO = sys.stdout,
    init: str = INIT_DEFAULTS,
    anneal: float = 0.0,
) -> dict:
    """Run the benchmark; prints a table and returns (and optionally writes) the results.

    The photos of the trials are read before the first one starts. Ctrl-C ends the run: the
    trial in progress is dropped, and the results of the finished ones are written with
    ``"interrupted": true``. ``anneal`` smooths the look's steps at the start of the coarse
    levels (:mod:`wise.filters.smoothing`).
    """
    if trials < 1:
        raise WiseError(f"--trials must be at least 1, got {trials}")
    effect = effects.create(effect_name)
    init_kind, model = parse_init(init)
    predictor = Predictor(model, effect_name) if init_kind == INIT_PPN else None
    levels, crops = schedule(iterations, lr, loss, anneal)

    def trial(number: int, path: Path, content: torch.Tensor, generator: torch.Generator) -> dict:
        crop_seed = seed * 1_000_003 + number
        truth, reference, outcome = _trial(effect, content, generator, levels, crops, crop_seed, predictor)
        if outcome.interrupted:
            raise KeyboardInterrupt
        assert outcome.result is not None
        return {
            "ssim": metrics.ssim(outcome.result, reference),
            "psnr": min(PSNR_CAP, metrics.psnr(outcome.result, reference)),
            "true_params": effect.params_to_dict(truth[0]),
            "found_params": effect.params_to_dict(outcome.params[0]),
            "seconds": round(outcome.seconds, 2),
            "losses": [round(value, 6) for value in outcome.losses],
        }

    def summarize(rows: list[dict], interrupted: bool) -> dict:
        summary = {
            "effect": effect_name,
            "size": size,
            "iterations": iterations,
            "loss": loss,
            "anneal": anneal,
            "seed": seed,
            "init": init if predictor is None else f"{INIT_PPN}:{predictor.info.source}",
            "trials_finished": len(rows),
            "mean_ssim": mean_of(rows, "ssim"),
            "mean_psnr": mean_of(rows, "psnr"),
            "psnr_cap": PSNR_CAP,
            "levels": describe_schedule(levels, crops),
            "trials": rows,
        }
        if rows:
            print(f"mean SSIM {summary['mean_ssim']:.4f}, mean PSNR {summary['mean_psnr']:.2f} dB", file=out)
        return summary

    columns = (Column("SSIM", "ssim"), Column("PSNR", "psnr", ".2f"))
    return run_trials(images_dir, trials, size, seed, trial, columns, summarize, json_path, out)
