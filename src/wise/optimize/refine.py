"""A short optimization from predicted parameters that fits a time budget.

``wise predict`` and ``wise bench ppn --refine`` continue from the network's prediction with
this: global parameters optimized on random crops of a copy of photo and example whose short side
is 512 pixels (:data:`GLOBAL_LEVELS`), per-pixel masks coarse to fine on whole copies
(:data:`LOCAL_LEVELS`), each level given its share of the budget, the steps of the look smoothed
at first and sharpened as the budget runs out (graduated non-convexity,
:mod:`wise.filters.smoothing`). A level ends when its share of the time is spent or its
iterations are done, whichever comes first.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import torch
import torch.nn.functional as F

from wise.effects.base import Effect
from wise.errors import WiseError
from wise.filters._checks import REFERENCE_SHORT_SIDE
from wise.optimize.inversion import (
    HELD_PARAMS,
    fit_quickly,
    fits_quickly,
    read_after_descent,
    read_steps,
    readable_after_descent,
)
from wise.optimize.parametric import CROP_CONTEXT, Outcome, Settings, optimize_coarse_to_fine, optimize_on_crops
from wise.optimize.settings import DEFAULT_BUDGET
from wise.threads import following_load


@dataclass(frozen=True)
class Level:
    """A stage of the refinement: descent on copies of photo and example whose short side is
    ``side`` (the photo's own where that is smaller) for ``share`` of the budget, at ``rate``
    times :data:`REFINE_LR`; with ``crop``, on one random square of that many pixels per
    iteration, rendered at the copy's scale and position
    (:func:`~wise.optimize.parametric.optimize_on_crops`; global parameters only). The photo's
    own size is drawn as ``wise apply`` draws it (:class:`wise.render.Look`: a photo below the
    reference enlarged and the render reduced), a reduced copy at its own scale."""

    side: int
    share: float
    rate: float
    crop: int | None = None


GLOBAL_LEVELS = (Level(512, 1.0, 0.5, crop=128),)
"""Global parameters descend on crops of the 512-pixel copy: the look at the size it is judged
at, an iteration about a sixth of a whole one, so six times the iterations of the budget.
Reduced copies cost more than they give: an effect rendered on a small copy is another look
than its large rendering reduced (line widths, texture scales), so they pull the parameters
away from the answer (BENCHMARKS.md, "Refinement levels", "Refinement on crops")."""
LOCAL_LEVELS = (Level(256, 0.7, 1.0), Level(512, 0.3, 0.5))
"""Per-pixel masks descend on whole copies: a crop would move only its own part of the masks."""
CROP_MARGIN = 2
"""A crop level works on crops only where the copy's short side is this many crops and their
context or more; a smaller copy is descended whole."""
MAX_LEVEL_ITERATIONS = 400
"""Iterations of a level when its time share allows more (a small picture on a fast machine)."""
REFINE_LR = 0.05
"""Learning rate of the coarsest level: lower than the functional benchmark's 0.1, because
refinement starts near the answer."""
REFINE_ANNEAL = 0.3
"""Step temperature at the start of the coarsest level."""
REFINE_LOSSES = {"global": "l1", "local": "l2"}
"""The image loss of each mode by default. L1 for global parameters: where a step or a line sits
a pixel off, L2 favours the blurred compromise (fewer, softer levels; greyer lines) that a
painter would not call the example (BENCHMARKS.md, "The loss of the crops"); masks keep L2, as
measured for them."""
REFINE_FINAL_LR = 0.1
"""Learning rate at the end of a crop level, as a share of its start (a half cosine over the
budget): the random crops' noise settles instead of moving the answer at the last iterations
(BENCHMARKS.md, "The learning rate of the crops")."""
INVERSION_SIDE = 128
"""Short side at which the staircase parameters are read off the example before the levels
(:func:`wise.optimize.inversion.read_steps`): the luminance plateaus and the shading show at any
size. The readings are then judged by renders at up to 512 pixels, where the look is the
example's (at 128 pixels lines and steps are another picture); with that, the reading costs
about 1.4 s of the budget for xdog (BENCHMARKS.md, "The XDoG's tone read off its shading")."""
INVERSION_MIN_BUDGET = 2.0
"""Budgets below this many seconds go to descent alone: the reading would take a quarter or more."""
SETTLE_SECONDS = 1.0
"""Seconds kept back at the end of the budget for the readings after descent
(:func:`wise.optimize.inversion.read_after_descent`): the cartoon's steps and outlines take about
0.8 s at 512 pixels on a 2-core CPU."""
READING_SHARE = 0.5
"""Most of the budget the readings before descent may take: a reading planned to take more is
left out, and one that runs longer than planned stops at that share with what it has, so that
descent keeps at least the rest."""
FIT_PER_READING = 5.0
"""The quick fit of the colours (:func:`~wise.optimize.inversion.fit_quickly`) takes about this
many times the steps' reading before it (cartoon at 512 pixels: 2.3 s against 0.47 s on a quiet
2-core CPU, 7.7 s against 1.1 s beside two busy processes), so its cost is planned from what the
reading took on the machine as it is now."""
SETTLE_PER_READING = 2.0
"""The readings after descent take up to this many times the steps' reading before it (cartoon:
0.9 s against 0.47 s quiet, 1.6 s against 1.1 s busy): the time kept back for them, at least
:data:`SETTLE_SECONDS`."""
RENDER_SHARE = 1.5
"""An iteration and the level's final render take about this many iterations' time: a level
starts only when that much of the budget is left (estimated from the level before, per pixel)."""


def answers(outcome: Outcome) -> list[tuple[str, torch.Tensor]]:
    """The refinement's candidate answers, named, simplest first: the steps read off the target
    before descent (``read``, where the reading changed the start), where descent ended
    (``descent``), and the readings from there after it (``read after descent``, then ``... 2``
    and on, :attr:`~wise.optimize.parametric.Outcome.settled`). Descent on the image loss can stray from
    a reading that was right, and a reading can be wrong where descent was right, so callers keep
    the one that re-creates the target best, the network's own prediction among them (ties to
    the simpler). Each answer is listed once, so that none is rendered twice."""
    candidates = ([] if outcome.read is None else [("read", outcome.read)]) + [("descent", outcome.params)]
    candidates += [("read after descent", settled) for settled in outcome.settled]
    distinct: list[tuple[str, torch.Tensor]] = []
    for name, candidate in candidates:
        if not any(candidate.shape == seen.shape and torch.equal(candidate, seen) for _, seen in distinct):
            count = sum(seen_name.startswith(name) for seen_name, _ in distinct)
            distinct.append((name if count == 0 else f"{name} {count + 1}", candidate))
    return distinct


def _levels(content: torch.Tensor, mode: str) -> list[Level]:
    """The mode's levels that are smaller than the photo, then the photo's own size with the
    share of those that are not; crops only on copies whose render is large enough for them
    (the photo's own is at least the reference's, :class:`wise.render.Look`)."""
    short = min(content.shape[-2:])
    plan = GLOBAL_LEVELS if mode == "global" else LOCAL_LEVELS
    levels = [level for level in plan if level.side < short]
    if len(levels) < len(plan):
        spare = sum(level.share for level in plan if level.side >= short)
        levels.append(replace(plan[len(levels)], side=short, share=spare))
    return [
        level
        if level.crop is None
        or CROP_MARGIN * (level.crop + 2 * CROP_CONTEXT)
        <= (max(level.side, REFERENCE_SHORT_SIDE) if level.side == short else level.side)
        else replace(level, crop=None)
        for level in levels
    ]


def _compile_kernels(effect: Effect, content: torch.Tensor, start: torch.Tensor) -> None:
    """One forward and backward pass on a thumbnail: the first of a process compiles (or loads)
    the fused CPU kernels, which must not eat the refinement's budget."""
    thumbnail = F.interpolate(content, size=(32, 32), mode="area")
    params = start.detach().clone().to(content.device).requires_grad_(True)
    effect(thumbnail, params).mean().backward()


def refine(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    start: torch.Tensor,
    budget: float = DEFAULT_BUDGET,
    mode: str = "global",
    max_iterations: int | None = None,
    loss: str | None = None,
) -> Outcome:
    """Optimize from ``start`` (normalized ``(1, P)``) for about ``budget`` seconds; returns the
    outcome of the last level (its ``result`` at that level's size, none after crops; render the
    parameters at the photo's own size with :func:`wise.render.render`), with the steps read off the target
    before descent as its ``read`` where the reading changed the start, and the readings from where
    descent ended as its ``settled`` (:func:`answers` names them all). ``max_iterations`` caps
    the iterations, shared out over the levels (at least one each); ``loss`` defaults to the
    mode's (:data:`REFINE_LOSSES`). Computes on the cores other programs leave free
    (:func:`wise.threads.following_load`)."""
    if not budget > 0:
        raise WiseError(f"the refinement budget must be positive, got {budget}")
    with following_load():
        return _refine(effect, content, target, start, budget, mode, max_iterations, loss)


def _refine(
    effect: Effect,
    content: torch.Tensor,
    target: torch.Tensor,
    start: torch.Tensor,
    budget: float,
    mode: str,
    max_iterations: int | None,
    loss: str | None,
) -> Outcome:
    loss = loss if loss is not None else REFINE_LOSSES.get(mode, "l2")
    _compile_kernels(effect, content, start)
    began = time.perf_counter()
    plan = _levels(content, mode)
    per_level = MAX_LEVEL_ITERATIONS if max_iterations is None else max(1, math.ceil(max_iterations / len(plan)))
    # the staircase parameters read off the example, within the budget
    params, held, read = start, (), None
    reading = start.dim() <= 2 and budget >= INVERSION_MIN_BUDGET  # global parameters, time to read
    reading_seconds = 0.0
    left_out: list[str] = []
    if reading:
        given = start.reshape(1, -1)
        params, held = read_steps(effect, content, target, given, side=INVERSION_SIDE, at_reference=True)
        reading_seconds = time.perf_counter() - began
        if not torch.equal(params, given.to(params)):
            # held even where the example left the count open: in a budget of seconds, descent
            # from a network's start trades a count read rightly for a smooth look of two or
            # three soft levels, and has no time to find the example's from there (BENCHMARKS.md,
            # "The count held in the refinement")
            held = HELD_PARAMS.get(getattr(effect, "name", ""), held)
        # the cartoon's colours fitted to the levels read, on a sample of pixels: descent from a
        # tone curve that fits but is not the example's trades one for another
        if reading_seconds * (1.0 + FIT_PER_READING) <= READING_SHARE * budget:
            deadline = began + READING_SHARE * budget
            params = fit_quickly(
                effect, content, target, params, side=INVERSION_SIDE, deadline=deadline, at_reference=True
            )
        elif fits_quickly(effect):
            left_out.append("the colour fit")
        read = None if torch.equal(params, start.reshape(params.shape)) else params
    losses: list[float] = []
    outcome: Outcome | None = None
    # after descent, the steps and the ink read again: with the colours near the example's, a count
    # the plateaus left open or read wrongly shows, one descent cannot move across the staircase
    # (BENCHMARKS.md, "Readings after descent")
    settling = reading and readable_after_descent(effect)
    kept_back = max(SETTLE_SECONDS, SETTLE_PER_READING * reading_seconds) if settling else 0.0
    seconds_per_pixel = 0.0  # of an iteration and a render at the level before
    for index, level in enumerate(plan):
        factor = level.side / min(content.shape[-2:])
        size = (max(8, round(content.shape[-2] * factor)), max(8, round(content.shape[-1] * factor)))
        # the photo's own size is drawn as the user's render draws it; a reduced copy at its own scale
        at_reference = factor == 1
        enlargement = max(1.0, REFERENCE_SHORT_SIDE / min(size)) if at_reference else 1.0
        rendered = size[0] * size[1] * enlargement**2 if level.crop is None else (level.crop + 2 * CROP_CONTEXT) ** 2
        # the level's share of what is left, so that a level that ends early leaves its time to the next
        left = budget - kept_back - (time.perf_counter() - began)
        if left <= seconds_per_pixel * rendered:  # not even one iteration would fit
            break
        settings = Settings(
            mode=mode,
            iterations=per_level,
            lr=REFINE_LR * level.rate,
            loss=loss,
            levels=1,
            time_limit=left * level.share / sum(later.share for later in plan[index:]),
            anneal=REFINE_ANNEAL if index == 0 else 0.0,
            held=held,
            final_lr=REFINE_FINAL_LR if level.crop is not None else None,  # whole copies: the paper's decay
            at_reference=at_reference,
        )
        small_content = F.interpolate(content, size=size, mode="area") if factor < 1 else content
        small_target = F.interpolate(target, size=size, mode="area") if factor < 1 else target
        if level.crop is None:
            outcome = optimize_coarse_to_fine(effect, small_content, small_target, params, ((1, settings),))
        else:
            outcome = optimize_on_crops(
                effect, small_content, small_target, params, settings, crop=level.crop, render=False
            )
        seconds_per_pixel = outcome.seconds / max(1, len(outcome.losses)) * RENDER_SHARE / rendered
        params = outcome.params
        losses.extend(outcome.losses)
        if outcome.interrupted:
            break
    settled: tuple[torch.Tensor, ...] = ()
    if settling and not (outcome is not None and outcome.interrupted):
        settled = tuple(read_after_descent(effect, content, target, params))
    if outcome is None:
        return Outcome(
            params=params.detach().clone(), seconds=time.perf_counter() - began, read=read, settled=settled,
            left_out=tuple(left_out),
        )  # fmt: skip
    return replace(
        outcome, losses=losses, seconds=time.perf_counter() - began, read=read, settled=settled,
        left_out=tuple(left_out),
    )  # fmt: skip
