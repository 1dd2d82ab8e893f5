"""Parametric style transfer: optimize an effect's parameters so that its output matches a target.

Follows WISE Sec. 5.1: Adam on global parameters or per-pixel parameter masks with an image
loss, the learning rate multiplied by 0.98 every 5 iterations from iteration 50, and the masks
smoothed by a Gaussian at iterations 10, 25, 50, 100, 250 and 500 against fragmented masks;
optionally a total-variation penalty on the masks. By default the iterations run coarse to
fine on an image pyramid (:data:`PYRAMIDS`): the effects are resolution-independent, so masks
found on a reduced copy carry over, and the early, large Adam steps are taken where they are
cheap and where a step of one mask pixel covers a larger region of the image.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import torch

from wise.effects.base import Effect
from wise.errors import WiseError
from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.filters.clamp import inward_gradients
from wise.filters.color import rgb_to_lab
from wise.filters.gaussian import gaussian_blur
from wise.filters.smoothing import annealed_temperature, smoothed_steps, softened_gradients
from wise.optimize.adam import Adam
from wise.optimize.settings import PYRAMIDS, Settings
from wise.params import NORMALIZED_MAX, NORMALIZED_MIN, check_params, clamp_masks, resize_masks
from wise.render import Look
from wise.threads import follow_load
from wise.vgg import StyleLoss, load_vgg19

LAB_WEIGHT = 0.5
"""Weight of the CIE Lab term of the ``l1-lab`` loss (Lab divided by 100) beside L1 in RGB."""
DECAY = 0.98
DECAY_EVERY = 5
DECAY_FROM = 50
SMOOTH_AT = (10, 25, 50, 100, 250, 500)
MASK_SMOOTHING_SIGMA = 1.0
"""Sigma (mask pixels) of the Gaussian applied to the masks at ``SMOOTH_AT``."""
CROP_SIZE = 128
"""Side of the random crop compared per iteration by :func:`optimize_on_crops` (pixels)."""
CROP_CONTEXT = 24
"""Pixels rendered around a crop so that its filters see their neighbourhood; the loss
ignores them."""
MASK_CROP_SIZE = 256
"""Side of the crops of :func:`optimize_masks_on_crops` (pixels of the reference-size picture)."""
MASK_CROP_RATE = 2.0
"""Factor on the learning rate of a last level fitted on crops: a mask pixel steps only in the
iterations whose crop covers it (about a third of them at 512 pixels), and the lines it must
take away were never seen by the reduced levels before it. On the demo's watercolor the dashes
left went from 0.48 % of the pixels to 0.07 %; at 5 times the cartoon's masks turned to noise."""


@dataclass
class Outcome:
    """The state reached: normalized ``params`` ((1, P) or (1, P, h, w)), the loss per
    iteration, the effect's output at the working resolution and the wall time."""

    params: torch.Tensor
    losses: list[float] = field(default_factory=list)
    result: torch.Tensor | None = None
    seconds: float = 0.0
    interrupted: bool = False
    read: torch.Tensor | None = None
    """Where descent started when that was not the given start: the steps read off the target
    first (:func:`wise.optimize.refine.refine`). Descent on an image loss can leave a reading that
    fitted better, so the callers compare the two."""
    settled: tuple[torch.Tensor, ...] = ()
    """Answers read off the target once descent ended, from where it ended (the refinement's
    :func:`~wise.optimize.inversion.read_after_descent`): steps and ink that descent cannot move
    across their staircases, which the callers judge beside ``params``."""
    left_out: tuple[str, ...] = ()
    """Steps of a time-bounded refinement left out because the budget, at the speed the machine
    showed, had no room for them (e.g. ``"the colour fit"``)."""


def image_distance(kind: str, output: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The mean distance of ``output`` from ``target`` (both ``(B, 3, H, W)`` RGB): ``l1``, ``l2``,
    or ``l1-lab``, L1 in RGB plus :data:`LAB_WEIGHT` times L1 in CIE Lab (divided by 100). In
    RGB alone a pixel whose tone the effect cannot reach (on a quantization plateau) gets closer
    with a saturated colour that makes up the difference channel by channel; in Lab a colour
    cannot stand in for a tone. (``nst`` is scored as ``l2`` here.)"""
    if kind == "l1-lab":
        return _l1_lab(output, target, rgb_to_lab(target.clamp(0.0, 1.0)))
    difference = output - target
    return difference.abs().mean() if kind == "l1" else difference.square().mean()


def _l1_lab(output: torch.Tensor, target: torch.Tensor, target_lab: torch.Tensor) -> torch.Tensor:
    lab = (rgb_to_lab(output.clamp(0.0, 1.0)) - target_lab) / 100.0
    return (output - target).abs().mean() + LAB_WEIGHT * lab.abs().mean()


def _image_loss(kind: str, content: torch.Tensor, target: torch.Tensor, vgg_weights: str | None):
    """The loss as a function of the output: :func:`image_distance` from the target, or Gatys'
    content + style loss (``nst``) with the content photo's features and the target's Gram matrices."""
    if kind == "nst":
        return StyleLoss(load_vgg19(vgg_weights).to(content.device), content, target)
    if kind == "l1-lab":  # the target's Lab once, not every iteration
        target_lab = rgb_to_lab(target.clamp(0.0, 1.0))
        return lambda output: _l1_lab(output, target, target_lab)
    return lambda output: image_distance(kind, output, target)


def closest(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    candidates: Sequence[torch.Tensor],
    loss: str = "l2",
    at_reference: bool = False,
) -> torch.Tensor:
    """The candidate parameters whose render of ``content`` is closest to ``target`` by ``loss``
    (:func:`image_distance`, the first of equals); a single candidate is returned without rendering.
    ``at_reference``: rendered as :class:`wise.render.Look` draws the picture (default: at its own scale)."""
    if len(candidates) == 1:
        return candidates[0]
    look = Look(effect, content, at_reference)
    with torch.no_grad():
        losses = [float(image_distance(loss, look(c).clamp(0.0, 1.0), target)) for c in candidates]
    return candidates[losses.index(min(losses))]


def total_variation(masks: torch.Tensor) -> torch.Tensor:
    """Mean absolute difference of neighbouring mask values (Johnson et al. 2016)."""
    return (masks[..., 1:, :] - masks[..., :-1, :]).abs().mean() + (masks[..., 1:] - masks[..., :-1]).abs().mean()


def initial_params(effect: Effect, init: torch.Tensor, mode: str, size: tuple[int, int]) -> torch.Tensor:
    """Start values: global (1, P), or masks (1, P, H, W) at the working size from ``init``."""
    params = check_params(init, effect.param_specs, 1).detach().clone()
    if mode == "global":
        return params if params.dim() == 2 else params.mean(dim=(2, 3))
    if params.dim() == 2:
        return params[:, :, None, None].expand(-1, -1, *size).clone()
    return torch.nn.functional.interpolate(params, size=size, mode="bilinear", align_corners=False)


def _hold(params: torch.Tensor, effect: Effect, held: tuple[str, ...]) -> None:
    """No step for the ``held`` parameters: their gradient (global or per pixel) set to zero."""
    if held and params.grad is not None:
        params.grad[:, [effect.param_names.index(name) for name in held]] = 0.0


def _decay_learning_rate(optimizer: Adam, iteration: int) -> None:
    """The paper's schedule: x 0.98 every 5 iterations from iteration 50."""
    if iteration >= DECAY_FROM and iteration % DECAY_EVERY == 0:
        for group in optimizer.param_groups:
            group["lr"] *= DECAY


def _schedule_learning_rate(optimizer: Adam, settings: Settings, iteration: int, start: float) -> None:
    """After ``iteration``: the paper's decay, or with ``settings.final_lr`` the learning rate
    lowered along a half cosine over the progress to that share of ``settings.lr`` at the end."""
    if settings.final_lr is None:
        _decay_learning_rate(optimizer, iteration)
        return
    progress = min(1.0, _progress(settings, iteration + 1, start))
    factor = settings.final_lr + (1.0 - settings.final_lr) * 0.5 * (1.0 + math.cos(math.pi * progress))
    for group in optimizer.param_groups:
        group["lr"] = settings.lr * factor


RECENT_ITERATIONS = 3
"""Iterations whose longest duration predicts the next one's (the longest rather than the average:
on a busy machine one step can take twice as long as the one before; only recent ones, so that
the slow first step of a process does not end the loop early)."""


def _next_would_overrun(time_limit: float, start: float, iterations: deque[float], renders: deque[float]) -> bool:
    """Whether another iteration and the final render, each as long as the longest recent one,
    could end after ``time_limit``."""
    elapsed = time.perf_counter() - start
    return elapsed + max(iterations) + max(renders) > time_limit


def _progress(settings: Settings, iteration: int, start: float) -> float:
    """How far along the optimization is (0 to 1), by iterations and, with a time limit, by time."""
    done = (iteration - 1) / settings.iterations
    if settings.time_limit is None:
        return done
    return max(done, (time.perf_counter() - start) / settings.time_limit)


def _finished(outcome: Outcome, look: Look, start: float) -> Outcome:
    """The outcome with its wall time and the effect's output for the parameters reached."""
    outcome.seconds = time.perf_counter() - start
    with torch.no_grad():
        outcome.result = look(outcome.params)
    return outcome


def optimize(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    init: torch.Tensor,
    settings: Settings,
    on_step: Callable[[int, float, torch.Tensor], None] | None = None,
) -> Outcome:
    """Optimize ``effect``'s parameters so that ``effect(content)`` matches ``target``.

    Args:
        content, target: ``(1, 3, H, W)`` in [0, 1] at the working resolution.
        init: normalized start parameters, (P,), (1, P) or (1, P, h, w).
        on_step: called after every iteration with (iteration, loss, output).

    Ctrl-C (KeyboardInterrupt) ends the loop early; the state reached is returned with
    ``interrupted`` set.
    """
    if content.shape != target.shape:
        raise WiseError(f"content {tuple(content.shape)} and target {tuple(target.shape)} differ in size")
    image_loss = _image_loss(settings.loss, content, target, settings.vgg_weights)
    look = Look(effect, content, settings.at_reference)
    params = initial_params(effect, init.to(content), settings.mode, tuple(content.shape[-2:])).requires_grad_()
    optimizer = Adam([params], lr=settings.lr)
    outcome = Outcome(params=params.detach())
    start = time.perf_counter()
    output = None
    iterations: deque[float] = deque(maxlen=RECENT_ITERATIONS)
    renders: deque[float] = deque(maxlen=RECENT_ITERATIONS)
    try:
        for iteration in range(1, settings.iterations + 1):
            follow_load()
            began = time.perf_counter()
            optimizer.zero_grad(set_to_none=True)
            temperature = annealed_temperature(settings.anneal, _progress(settings, iteration, start))
            with (
                inward_gradients(params.dim() == 4),
                smoothed_steps(temperature),
                softened_gradients(settings.soft_gradients),
            ):
                output = look(params)
            renders.append(time.perf_counter() - began)
            loss = image_loss(output)
            if settings.tv_weight > 0 and params.dim() == 4:
                loss = loss + settings.tv_weight * total_variation(params)
            loss.backward()
            _hold(params, effect, settings.held)
            optimizer.step()
            with torch.no_grad():
                if params.dim() == 4 and iteration in SMOOTH_AT and iteration < settings.iterations:
                    params.copy_(gaussian_blur(params, MASK_SMOOTHING_SIGMA, scale=1.0))
                if params.dim() == 4:
                    clamp_masks(params, effect.param_specs)
                else:
                    params.clamp_(NORMALIZED_MIN, NORMALIZED_MAX)
            _schedule_learning_rate(optimizer, settings, iteration, start)
            value = float(loss.detach())
            outcome.losses.append(value)
            outcome.params = params.detach().clone()
            if on_step is not None:
                on_step(iteration, value, output.detach())
            iterations.append(time.perf_counter() - began)
            if settings.time_limit is not None and _next_would_overrun(settings.time_limit, start, iterations, renders):
                break
    except KeyboardInterrupt:
        outcome.interrupted = True
    return _finished(outcome, look, start)


def pyramid(
    settings: Settings, schedule: Sequence[tuple[int, float, float]] | None = None
) -> tuple[tuple[int, Settings], ...]:
    """The levels for :func:`optimize_coarse_to_fine`: ``settings.iterations`` split over
    ``schedule`` (default ``PYRAMIDS[settings.levels]``), each level a copy of ``settings``
    with its share of the iterations and its learning rate. The ``nst`` loss runs at the
    working size only: its VGG features lose their meaning on small reduced copies."""
    if schedule is None:
        schedule = PYRAMIDS[1 if settings.loss == "nst" else settings.levels]
    levels, left = [], settings.iterations
    for index, (reduction, share, rate) in enumerate(schedule):
        last = index == len(schedule) - 1
        count = left if last else min(left - 1, max(1, round(settings.iterations * share)))
        left -= count
        if count > 0:
            anneal = settings.anneal if not levels else 0.0  # smoothing belongs to the first, coarsest level
            level = replace(settings, iterations=count, lr=settings.lr * rate, levels=1, anneal=anneal)
            levels.append((reduction, level))
    return tuple(levels)


def describe_levels(levels: Sequence[tuple[int, Settings]]) -> list[dict[str, float]]:
    """The levels of :func:`pyramid` as JSON-ready rows: reduction, iterations, learning rate."""
    return [{"reduction": reduction, "iterations": level.iterations, "lr": level.lr} for reduction, level in levels]


def optimize_coarse_to_fine(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    init: torch.Tensor,
    levels: tuple[tuple[int, Settings], ...],
    on_step: Callable[[int, float, torch.Tensor], None] | None = None,
    between_levels: Callable[[torch.Tensor], torch.Tensor] | None = None,
    finest: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> Outcome:
    """:func:`optimize` on an image pyramid: each ``(reduction, settings)`` level works on the
    images reduced by that factor and starts from the previous level's parameters
    (``between_levels`` may change global ones before the next level starts, e.g.
    :func:`wise.optimize.inversion.invert_steps` once descent has moved the rest). With
    ``finest`` (content and target at the size the result is rendered at), the last level of
    parameter masks fits them on crops of those instead (:func:`optimize_masks_on_crops`).

    The effects are resolution-independent, so the parameters found on a small copy carry
    over; most iterations then cost a fraction of a full-resolution one. The last level
    should have a reduction of 1. Each level runs :func:`optimize` afresh, so the mask
    smoothing and learning-rate decay schedules restart per level. ``on_step`` sees the
    iterations counted over all levels and outputs at the level's size. Returns the last
    level's outcome with the losses and time of all levels.
    """
    params, losses, seconds = init, [], 0.0
    outcome, mode = None, "global"
    for index, (reduction, settings) in enumerate(levels):
        mode = settings.mode
        if index > 0 and between_levels is not None and params.dim() == 2:
            params = between_levels(params.detach())
        if reduction > 1:
            settings = replace(settings, at_reference=False)  # a coarse copy: cheap iterations
            size = (max(8, content.shape[-2] // reduction), max(8, content.shape[-1] // reduction))
            level_content = torch.nn.functional.interpolate(content, size=size, mode="area")
            level_target = torch.nn.functional.interpolate(target, size=size, mode="area")
        else:
            level_content, level_target = content, target
        done = len(losses)
        level_step = None if on_step is None else lambda i, loss, output: on_step(done + i, loss, output)
        if finest is not None and index == len(levels) - 1 and mode == "local":
            canvas = None if outcome is None else outcome.result
            masks = initial_params(effect, params, "local", tuple(level_content.shape[-2:]))
            on_crops = replace(settings, lr=settings.lr * MASK_CROP_RATE)
            outcome = optimize_masks_on_crops(effect, *finest, masks, on_crops, on_step=level_step, canvas=canvas)
        else:
            outcome = optimize(effect, level_content, level_target, params, settings, level_step)
        params, seconds = outcome.params, seconds + outcome.seconds
        losses.extend(outcome.losses)
        if outcome.interrupted:
            break
    assert outcome is not None, "levels must not be empty"
    if outcome.result is not None and outcome.result.shape[-2:] != content.shape[-2:]:
        with torch.no_grad():
            outcome.params = initial_params(effect, outcome.params, mode, tuple(content.shape[-2:]))
            outcome.result = Look(effect, content, levels[-1][1].at_reference)(outcome.params)
    outcome.losses, outcome.seconds = losses, seconds
    return outcome


def _covering_windows(
    size: tuple[int, int], crop: int, context: int, passes: int, generator: torch.Generator
) -> list[tuple[tuple[int, int, int], tuple[int, int, int]]]:
    """Crops that cover a picture of ``size`` in one pass, in random order: per side, the first
    pixel of each crop and the rendered span around it (``context`` each side, shifted inward at
    the picture's edges). Every crop and span has the same size, so the kernels compile once. The
    crops are spread evenly, one more per side on odd ``passes`` so that their borders move;
    each pixel is fitted at least once per pass (random crops would reach the outermost pixels
    once in ``length - crop`` draws)."""

    def spans(length: int) -> list[tuple[int, int, int]]:
        count = math.ceil(length / crop) + passes % 2
        starts = sorted({round(index * (length - crop) / max(1, count - 1)) for index in range(count)})
        span = min(length, crop + 2 * context)
        firsts = [min(max(start - context, 0), length - span) for start in starts]
        return [(start, first, first + span) for start, first in zip(starts, firsts)]

    windows = [(rows, columns) for rows in spans(size[0]) for columns in spans(size[1])]
    order = torch.randperm(len(windows), generator=generator).tolist()
    return [windows[index] for index in order]


def _random_box(size: tuple[int, int], crop: int, generator: torch.Generator) -> tuple[int, int]:
    height, width = size
    top = int(torch.randint(0, height - crop + 1, (1,), generator=generator))
    left = int(torch.randint(0, width - crop + 1, (1,), generator=generator))
    return top, left


def _check_crops(settings: Settings, content: torch.Tensor, target: torch.Tensor) -> None:
    """Refuses what optimization on crops cannot do: the ``nst`` loss, a target of another size."""
    if settings.loss == "nst":
        raise WiseError("optimization on crops takes the l1, l1-lab or l2 loss, not 'nst'")
    if content.shape != target.shape:
        raise WiseError(f"content {tuple(content.shape)} and target {tuple(target.shape)} differ in size")


def optimize_on_crops(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    init: torch.Tensor,
    settings: Settings,
    generator: torch.Generator | None = None,
    crop: int = CROP_SIZE,
    context: int = CROP_CONTEXT,
    render: bool = True,
) -> Outcome:
    """Global parameters optimized at the working resolution, one random crop per iteration.

    Each iteration renders a ``crop`` x ``crop`` region with ``context`` pixels around it,
    at the scale and position of the whole image as :class:`wise.render.Look` draws it (so
    textures and filter sizes are those of the full render; both sizes count pixels of that
    render, of which an enlarged small picture shows fewer of its own), and takes an Adam step
    on the loss over the region. Details finer than a reduced copy can show (brush texture,
    thin lines) are then fitted where they exist, at a fraction of the cost of full-size
    iterations. The learning rate decays as in :func:`optimize`; the loss is
    :func:`image_distance`; ``settings.time_limit``, ``anneal`` and ``held`` act as there.
    Without ``render`` the outcome has no ``result`` (the whole image is not rendered) and the
    time limit is the iterations' alone.
    """
    if settings.mode != "global":
        raise WiseError("optimization on crops fits global parameters only; use mode 'global'")
    _check_crops(settings, content, target)
    height, width = content.shape[-2:]
    look = Look(effect, content, settings.at_reference)
    # ``crop`` and ``context`` are pixels of the render: of an enlarged picture's, fewer of its own
    crop = min(round(crop / look.enlargement), height, width)
    generator = generator if generator is not None else torch.Generator().manual_seed(0)
    params = initial_params(effect, init.to(content), "global", (height, width)).requires_grad_()
    optimizer = Adam([params], lr=settings.lr)
    outcome = Outcome(params=params.detach())
    start = time.perf_counter()
    iterations: deque[float] = deque(maxlen=RECENT_ITERATIONS)
    renders: deque[float] = deque(maxlen=RECENT_ITERATIONS)  # of the whole image, estimated from the crops'
    try:
        for iteration in range(1, settings.iterations + 1):
            follow_load()
            began = time.perf_counter()
            top, left = _random_box((height, width), crop, generator)
            optimizer.zero_grad(set_to_none=True)
            temperature = annealed_temperature(settings.anneal, _progress(settings, iteration, start))
            with smoothed_steps(temperature), softened_gradients(settings.soft_gradients):
                region = look.box(params, top, left, crop, crop, context)
            rendered = time.perf_counter() - began
            renders.append(rendered * height * width / (crop + 2 * context / look.enlargement) ** 2 if render else 0.0)
            loss = image_distance(settings.loss, region, target[..., top : top + crop, left : left + crop])
            loss.backward()
            _hold(params, effect, settings.held)
            optimizer.step()
            with torch.no_grad():
                params.clamp_(NORMALIZED_MIN, NORMALIZED_MAX)
            _schedule_learning_rate(optimizer, settings, iteration, start)
            outcome.losses.append(float(loss.detach()))
            outcome.params = params.detach().clone()
            iterations.append(time.perf_counter() - began)
            if settings.time_limit is not None and _next_would_overrun(settings.time_limit, start, iterations, renders):
                break
    except KeyboardInterrupt:
        outcome.interrupted = True
    if not render:
        outcome.seconds = time.perf_counter() - start
        return outcome
    return _finished(outcome, look, start)


def optimize_masks_on_crops(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    init: torch.Tensor,
    settings: Settings,
    generator: torch.Generator | None = None,
    crop: int = MASK_CROP_SIZE,
    context: int = CROP_CONTEXT,
    on_step: Callable[[int, float, torch.Tensor], None] | None = None,
    canvas: torch.Tensor | None = None,
) -> Outcome:
    """Parameter masks at their own (working) size fitted to renders of ``content`` at its size,
    one crop per iteration, the crops covering the picture once per pass (:func:`_covering_windows`).

    A render at a working size below the reference (512 pixels) draws every structure of the
    effect at the reduced scale, where the finest ones (the pencil contours of the watercolor,
    XDoG's thinnest lines) fall under a pixel and vanish; the result, rendered at the reference
    size, shows them wherever their masks were left at their start: dashes the target does not
    have. Here each iteration resizes the masks to ``content``'s size as the final render does
    (:func:`wise.params.resize_masks`), renders a ``crop`` x ``crop`` region with ``context``
    pixels around it at the scale and position of the whole picture, and takes an Adam step on
    :func:`image_distance` over the region. The learning rate, the masks' clamping and the
    gradient settings act as in :func:`optimize`, the time limit as in :func:`optimize_on_crops`.
    ``outcome.result`` is the whole render reduced to the masks' size. ``on_step`` sees each
    iteration's crop reduced to the masks' size and pasted into ``canvas`` (an image at the masks'
    size, e.g. the previous level's output, or the content).

    Args:
        content, target: ``(1, 3, H, W)`` in [0, 1], the size of the render to fit.
        init: normalized masks ``(1, P, h, w)`` (or global values, spread over ``h, w`` = H, W).
    """
    _check_crops(settings, content, target)
    height, width = content.shape[-2:]
    crop = min(crop, height, width)
    mask_size = tuple(init.shape[-2:]) if init.dim() == 4 else (height, width)
    scale = min(height, width) / REFERENCE_SHORT_SIDE
    generator = generator if generator is not None else torch.Generator().manual_seed(0)
    params = initial_params(effect, init.to(content), "local", mask_size).requires_grad_()
    optimizer = Adam([params], lr=settings.lr)
    outcome = Outcome(params=params.detach())
    canvas = content if canvas is None else canvas
    canvas = torch.nn.functional.interpolate(canvas.detach(), size=mask_size, mode="area")
    shrink = mask_size[0] / height, mask_size[1] / width
    windows: list[tuple[tuple[int, int, int], tuple[int, int, int]]] = []
    passes = 0
    start = time.perf_counter()
    iterations: deque[float] = deque(maxlen=RECENT_ITERATIONS)
    renders: deque[float] = deque(maxlen=RECENT_ITERATIONS)
    try:
        for iteration in range(1, settings.iterations + 1):
            follow_load()
            began = time.perf_counter()
            if not windows:
                windows = _covering_windows((height, width), crop, context, passes, generator)
                passes += 1
            (top, y0, y1), (left, x0, x1) = windows.pop()
            bottom, right = top + crop, left + crop
            optimizer.zero_grad(set_to_none=True)
            temperature = annealed_temperature(settings.anneal, _progress(settings, iteration, start))
            masks = resize_masks(params, (height, width))[..., y0:y1, x0:x1]
            with inward_gradients(), smoothed_steps(temperature), softened_gradients(settings.soft_gradients):
                output = effect(content[..., y0:y1, x0:x1], masks, scale=scale, origin=(y0, x0))
            rendered = time.perf_counter() - began
            renders.append(rendered * height * width / ((y1 - y0) * (x1 - x0)))
            region = output[..., top - y0 : bottom - y0, left - x0 : right - x0]
            loss = image_distance(settings.loss, region, target[..., top:bottom, left:right])
            loss.backward()
            _hold(params, effect, settings.held)
            optimizer.step()
            with torch.no_grad():
                clamp_masks(params, effect.param_specs)
            _schedule_learning_rate(optimizer, settings, iteration, start)
            value = float(loss.detach())
            outcome.losses.append(value)
            outcome.params = params.detach().clone()
            if on_step is not None:
                box = top * shrink[0], left * shrink[1], (bottom - top) * shrink[0], (right - left) * shrink[1]
                _paste(canvas, region.detach(), *box)
                on_step(iteration, value, canvas)
            iterations.append(time.perf_counter() - began)
            if settings.time_limit is not None and _next_would_overrun(settings.time_limit, start, iterations, renders):
                break
    except KeyboardInterrupt:
        outcome.interrupted = True
    outcome.seconds = time.perf_counter() - start
    with torch.no_grad():
        whole = effect(content, resize_masks(outcome.params, (height, width)))
        outcome.result = torch.nn.functional.interpolate(whole, size=mask_size, mode="area")
    return outcome


def _paste(canvas: torch.Tensor, image: torch.Tensor, top: float, left: float, height: float, width: float) -> None:
    """``image`` reduced to ``height`` x ``width`` pixels of ``canvas`` and put there at ``top``, ``left``."""
    y0, x0 = round(top), round(left)
    y1, x1 = min(canvas.shape[-2], y0 + max(1, round(height))), min(canvas.shape[-1], x0 + max(1, round(width)))
    canvas[..., y0:y1, x0:x1] = torch.nn.functional.interpolate(image, size=(y1 - y0, x1 - x0), mode="area")
