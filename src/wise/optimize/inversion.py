"""Step-like parameters read off the example in closed form, before gradient descent.

Some parameters make a staircase of the look: the gradient of a loss with respect to them points
nowhere useful until the steps line up, and descent settles in a local minimum (BENCHMARKS.md,
"Inversion of the step parameters"). The example itself says where its steps are:

- **cartoon** ``bins`` and ``softness``: the quantized luminance sits on plateaus at
  ``(k + 1/2) / bins`` (:func:`wise.filters.quantize.quantize`), whatever the colour adjustments
  before it did. The bin count is the period of the example's luminance histogram, the one whose
  comb ``cos(2 pi (L bins - 1/2))`` the plateaus agree with most (:func:`plateau_bins`); how
  close the values sit to the level centres gives the ramps' width (:func:`level_agreement`,
  :func:`softness_from_agreement`).
- **XDoG** ``contour``, ``blackness`` and ``shading``: outside the ink the drawing is the shading
  ``1 - s (1 - L)`` of the abstracted luminance ``L``, a line in ``s``; the ink is where the
  response ``u = u0 + contour u1`` of :func:`wise.effects.common.edge_response` lies below
  ``blackness``. ``u0`` and ``u1`` are computed from the content once; for each ``contour`` of a
  grid, ``blackness`` is the quantile of ``u`` at the example's ink share, and the contour whose
  ink covers the example's best is kept (:func:`xdog_threshold_from_ink`). Between the lines the
  shading also shows the tone: the colour adjustments whose luminance the example's values follow
  best, ``s`` by least squares for each (:func:`xdog_tones_from_shading`), give a second reading,
  and renders at the example's size decide. A cartoon's outlines are read the same way, its ink
  being the pixels much darker than the colour around them; with the colours fitted, their width
  too (the one whose ink overlaps the example's most).

- **cartoon colour adjustments**, once ``bins`` and ``softness`` are known: the quantizer is
  inverted (:func:`unquantized_bounds`; a point on a ramp, a level's width on a plateau) and the
  chroma is the example's away from the outlines, so the colour adjustments are fitted to the
  abstracted colours before quantization, where they act smoothly, rather than to the look's
  steps (:func:`fit_colours_to_levels`). Where seconds count (``wise predict``), the same fit runs
  on a sample of the plateau pixels of the content abstracted once before adjustment
  (:func:`colours_from_levels`, :func:`fit_quickly`).

:func:`read_steps` applies them to parameters ``(1, P)``; effects without such parameters are
returned unchanged. The estimates read the other parameters (the colour adjustments, ``details``)
where they stand: optimization calls it at the start and again between its levels, once descent
has moved them. A bin count the plateaus show clearly is held during descent; one they leave
open is settled by a short discrete search (each candidate descended briefly on a small copy).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import torch
import torch.nn.functional as F

from wise.effects.base import Effect
from wise.effects.cartoon import ABSTRACTION_ITERATIONS as CARTOON_PASSES
from wise.effects.common import COLOUR_ADJUSTMENTS, LUMINANCE_RANGE, detail_sigmas, edge_flow, edge_response, xdog_lines
from wise.filters import adjust_color, lab_to_rgb, oriented_bilateral, rgb_to_lab
from wise.filters.quantize import MIN_BINS, quantize
from wise.optimize.adam import Adam
from wise.optimize.parametric import Settings, closest, image_distance, optimize
from wise.params import NORMALIZED_MAX, NORMALIZED_MIN

WORKING_SIDE = 512
"""Short side at which the estimates are made (a larger example is reduced to it)."""
JUDGE_SIDE = 512
"""Short side (at most) at which renders decide between several readings (:attr:`Reading.alternatives`),
whatever size they were read at."""
BIN_STEP = 0.01
"""Resolution of the bin count searched over the parameter's range."""
HISTOGRAM_BINS = 2048
"""Bins of the luminance histogram that the comb is scored on."""
SOFTNESS_TABLE_VALUES = 4000
"""Evenly spread luminance values that tabulate the level agreement against the softness."""
OUTLINE_DEPTH = 0.01
"""A pixel this much (L* / 100) below the closing of the luminance lies on an outline or its
antialiased border, not on a plateau: it is left out of the histogram."""
END_TOLERANCE = 1e-3
"""Luminance (L* / 100) within which a pixel counts as lying at the example's darkest or brightest value."""
CLIPPED = 1.0 / 255.0
"""A colour channel this close to 0 or 1 was clipped on the way back to RGB, which moves its
luminance off the plateau."""
CLEAR_LEVELS = 3
CLEAR_AGREEMENT = 0.4
SHARP_LEVELS = 2
SHARP_AGREEMENT = 0.8
"""Plateaus on the comb of the best bin count, and its agreement, from which that count is taken
without comparing renders: three plateaus at their centres ``(k + 1/2) / b`` fix the spacing
and the offset, or two where the comb fits them sharply (hard steps). Two that fit it loosely
fit several counts (2.18 for levels of 13.45 in a trial of ``benchmarks/bench_bins.py``)."""
LEVEL_SHARE = 0.02
"""Share of the plateau pixels a level must hold to count as occupied."""
REGRESSION_BIN_STEP = 0.05
REGRESSION_SOFTNESS_VALUES = 11
REGRESSION_PIXELS = 4096
"""Grid and pixels of :func:`staircase_fit`, the bins and softness that map the content's
abstracted luminance to the example's."""
SEARCHED_BINS = (2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0)
"""Bin counts tried besides the estimates where the plateaus leave the count open."""
SEARCH_SIDE = 128
SEARCH_ITERATIONS = 20
SEARCH_LR = 0.1
"""The short discrete search: each candidate descended this often at this short side, at this rate."""
CONTOUR_CANDIDATES = 61
"""Contour values tried over the parameter's range when reading the ink."""
SETTLED_CONTOUR_REACH = 0.5
SETTLED_CONTOUR_STEP = 0.05
"""Contours tried when a cartoon's ink is read again after descent (:func:`read_after_descent`):
within this reach of descent's, at the step of the full grid."""
TIED_OVERLAP = 1e-6
"""Contours whose ink overlaps the example's within this much (pixel for pixel the same) mark it equally well."""
STROKE_WIDTHS = 10
"""Outline widths tried over the parameter's range where the outlines are read with the colours
fitted (:func:`_cartoon_outlines`): the ink's overlap with the example's peaks at the width of
the grid next to the true one (two trials of the functional benchmark: 0.99 and 0.94 at 1.2, the
true widths being 1.18 and 1.15; 0.69 and 0.49 at the narrowest)."""
OUTLINE_REACH = 3
"""Pixels around an outline pixel searched for the colour it darkens."""
VISIBLE_INK = 0.15
"""Brightness (mean of the channels) below which a cartoon's outline cannot be told from its colours."""
INK = 0.5
"""A pixel whose line factor (drawing over shading) is below this is ink."""
SHADING_FIT = 0.03
"""Pixels within this ratio of the fitted shading count as inliers of the shading fit."""
LEVEL_TOLERANCE = 0.004
"""Luminance (L* / 100) within which an example's value counts as one the quantizer gives: 8-bit
colours and the way back through RGB move a level by about this much."""
UNQUANTIZE_SAMPLES = 4097
"""Luminance values at which the quantizer is tabulated to invert it."""
FIT_SIDE = 128
FIT_ITERATIONS = 200
FIT_LR = 0.1
"""The fit of the colour adjustments to the un-quantized example (:func:`fit_colours_to_levels`):
short side, iterations and learning rate of its descent."""

LEVEL_FIT_PIXELS = 2000
LEVEL_FIT_ITERATIONS = 300
LEVEL_FIT_LR = 0.05
"""The quick fit of the colour adjustments to a cartoon's levels (:func:`colours_from_levels`): a
seeded sample of plateau pixels, and the iterations and learning rate of its descent (fewer
iterations at a higher rate left the colours a third further from the truth on the 18 trials
of ``wise bench ppn``)."""


SWEEP_PIXELS = 4096
SWEEP_COARSE_STEP = 0.25
SWEEP_FINE_STEP = 0.05
SWEEP_COARSE_SOFTNESS = 6
SWEEP_FINE_SOFTNESS = 21
"""The sweep of a cartoon's steps through its rendering (:func:`steps_from_rendering`): a seeded
sample of pixels; the bin counts tried over the range, then around the best; the softness
values tried with each in either pass."""


@dataclass
class Reading:
    """What an effect's estimate read off an example: its best ``params`` ``(1, P)``, whether the
    example showed them clearly (``clear``: then taken as they are), where it left them open,
    the ``candidates`` worth a brief descent each (:func:`read_steps` with ``search``), and
    ``alternatives``: other readings that renders at the example's size decide between."""

    params: torch.Tensor
    clear: bool
    candidates: list[torch.Tensor] = field(default_factory=list)
    alternatives: list[torch.Tensor] = field(default_factory=list)


# ----- cartoon: plateaus of the luminance ---------------------------------------------------


def example_luminance(example: torch.Tensor) -> torch.Tensor:
    """The normalized luminance (L* / 100) of ``example`` ``(1, 3, H, W)``, ``(1, 1, H, W)``."""
    return rgb_to_lab(example.clamp(0.0, 1.0))[:, :1] / 100.0


def plateau_pixels(example: torch.Tensor) -> torch.Tensor:
    """``(1, 1, H, W)``: the pixels of ``example`` that lie on its quantized plateaus or ramps, not
    on an outline, its border or a colour clipped on the way back to RGB. An outline is a thin
    valley of the luminance, which a closing (the brightest, then the darkest within
    :data:`OUTLINE_REACH` pixels) fills; a step between two levels it keeps."""
    luminance = example_luminance(example)
    width = 2 * OUTLINE_REACH + 1
    dilated = F.max_pool2d(luminance, kernel_size=width, stride=1, padding=OUTLINE_REACH)
    closed = -F.max_pool2d(-dilated, kernel_size=width, stride=1, padding=OUTLINE_REACH)
    clipped = ((example <= CLIPPED) | (example >= 1.0 - CLIPPED)).any(dim=1, keepdim=True)
    return (closed - luminance < OUTLINE_DEPTH) & ~clipped


def clamped_ends(luminance: torch.Tensor, kept: torch.Tensor) -> torch.Tensor:
    """The pixels at the darkest and the brightest value among ``kept`` (within
    :data:`END_TOLERANCE`): content clamped to black or white before quantization, which the
    soft ramps map to their outer ends ``Q(0)`` and ``Q(1)``, off the level centres."""
    values = luminance[kept]
    if values.numel() == 0:
        return torch.zeros_like(kept)
    low, high = float(values.min()), float(values.max())
    return (luminance < low + END_TOLERANCE) | (luminance > high - END_TOLERANCE)


def comb_agreement(luminance: torch.Tensor, bins: torch.Tensor) -> torch.Tensor:
    """How well the levels ``(k + 1/2) / b`` describe the histogram of ``luminance``, for each bin
    count ``b``: the comb ``cos(2 pi (L b - 1/2))`` summed over the histogram less its mean over
    one period ``1/b`` around each value (so the spread of the content's own tones, which varies
    slowly, does not count). 1 where every value sits on a level centre, about 0 for a count
    unrelated to the example's levels."""
    counts = torch.histc(luminance.double(), HISTOGRAM_BINS, 0.0, 1.0)
    weights = counts / counts.sum().clamp_min(1.0)
    cumulative = F.pad(weights.cumsum(0), (1, 0))
    centres = torch.arange(HISTOGRAM_BINS, dtype=torch.float64) + 0.5
    half = HISTOGRAM_BINS / (2.0 * bins.double()[:, None])

    def mass_below(position: torch.Tensor) -> torch.Tensor:  # linear within a histogram bin
        position = position.clamp(0.0, float(HISTOGRAM_BINS))
        low = position.floor().long().clamp_max(HISTOGRAM_BINS - 1)
        return cumulative[low] + (position - low) * weights[low]

    envelope = (mass_below(centres + half) - mass_below(centres - half)) / (2.0 * half)
    phases = 2.0 * math.pi * (centres[None, :] / HISTOGRAM_BINS * bins.double()[:, None] - 0.5)
    return (torch.cos(phases) * (weights[None, :] - envelope)).sum(dim=1)


def plateau_bins(luminance: torch.Tensor, low: float, high: float) -> tuple[list[float], list[float]]:
    """The bin counts in ``[low, high]`` whose combs agree with ``luminance`` most, best first (at
    most three local maxima within 0.8 of the best), and their agreements."""
    grid = torch.arange(max(low, MIN_BINS), high + BIN_STEP / 2, BIN_STEP, dtype=torch.float64)
    agreement = comb_agreement(luminance, grid)
    padded = F.pad(agreement[None, None], (1, 1), value=-2.0)[0, 0]
    peaks = ((agreement >= padded[:-2]) & (agreement >= padded[2:])).nonzero().flatten()
    best = float(agreement.max())
    ranked = sorted(peaks.tolist(), key=lambda i: -float(agreement[i]))
    chosen = [i for i in ranked if float(agreement[i]) >= 0.8 * best][:3] or ranked[:1]  # best <= 0: no comb fits
    return [float(grid[i]) for i in chosen], [float(agreement[i]) for i in chosen]


def level_agreement(luminance: torch.Tensor, bins: float) -> float:
    """``mean(cos(2 pi (L b - 1/2)))`` over the values between the first level centre and the one
    past the last inner boundary (:func:`inner_span`): how close they sit to the level centres
    of ``bins``, 1 on them. The outer half levels are left out: their ramps run on past the
    centre. Unlike :func:`comb_agreement` it does not depend on how many levels the values
    occupy, so it measures the ramps' width once the count is known."""
    low, high = inner_span(bins)
    inner = luminance[(luminance >= low) & (luminance <= high)]
    values = inner if inner.numel() else luminance
    return float(torch.cos(2.0 * math.pi * (values.double() * bins - 0.5)).mean())


def inner_span(bins: float) -> tuple[float, float]:
    """The first level centre and the centre past the last inner boundary of ``bins`` levels."""
    bins = max(bins, MIN_BINS)
    return 0.5 / bins, min(1.0, (math.ceil(bins) - 0.5) / bins)


def softness_from_agreement(agreement: float, bins: float, low: float, high: float) -> float:
    """The softness in ``[low, high]`` at which luminance spread evenly over the inner levels and quantized
    into ``bins`` gives the :func:`level_agreement` ``agreement`` (it falls from 1 at 0 as the
    ramps widen)."""
    grid = torch.linspace(low, high, 201)
    low_end, high_end = inner_span(bins)
    x = low_end + (high_end - low_end) * (torch.arange(SOFTNESS_TABLE_VALUES) + 0.5) / SOFTNESS_TABLE_VALUES
    x = x.view(1, 1, 1, -1)
    levels = quantize(x.expand(len(grid), 1, 1, -1), torch.full((len(grid),), bins), grid).view(len(grid), -1)
    table = torch.cos(2.0 * math.pi * (levels.double() * bins - 0.5)).mean(dim=1)
    return float(grid[(table - agreement).abs().argmin()])


def staircase_fit(
    before: torch.Tensor, after: torch.Tensor, bins_range: tuple[float, float], softness_range: tuple[float, float]
) -> tuple[float, float]:
    """``(bins, softness)`` of the quantizer that maps the luminance ``before`` to ``after`` (flat,
    the same pixels) with the least squared error, over a grid of both."""
    bins_grid = torch.arange(max(bins_range[0], MIN_BINS), bins_range[1] + 1e-6, REGRESSION_BIN_STEP)
    softness_grid = torch.linspace(softness_range[0], softness_range[1], REGRESSION_SOFTNESS_VALUES)
    bins = bins_grid.repeat_interleave(len(softness_grid))
    softness = softness_grid.repeat(len(bins_grid))
    stride = max(1, before.numel() // REGRESSION_PIXELS)
    x, y = before[::stride].float(), after[::stride].float()
    levels = quantize(x.clamp(0.0, 1.0).view(1, 1, 1, -1).expand(len(bins), 1, 1, -1), bins, softness)
    errors = (levels.view(len(bins), -1) - y).square().mean(dim=1)
    best = int(errors.argmin())
    return float(bins[best]), float(softness[best])


def unquantized_bounds(
    levels: torch.Tensor, bins: float, softness: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(low, high, known)``: the luminance before quantization that ``bins`` levels of ramps
    ``softness`` map to each value of ``levels`` (flat): a point on a ramp, where the quantizer can
    be inverted, or a whole level's width on a plateau. The outer levels reach on past 0 and 1
    (content clamped before quantization); ``known`` is false where no input gives the value
    (within :data:`LEVEL_TOLERANCE`), e.g. a pixel that mixes two levels."""
    like = {"device": levels.device, "dtype": levels.dtype}
    inputs = torch.linspace(0.0, 1.0, UNQUANTIZE_SAMPLES, **like)
    steps = torch.tensor([bins], **like), torch.tensor([max(softness, 1e-4)], **like)
    outputs = quantize(inputs.view(1, 1, 1, -1), *steps).flatten()
    outputs = torch.cummax(outputs, dim=0).values  # monotonic up to rounding, for the search below
    first = torch.searchsorted(outputs, levels - LEVEL_TOLERANCE, right=False)
    last = torch.searchsorted(outputs, levels + LEVEL_TOLERANCE, right=True) - 1
    known = first <= last
    low = torch.where(first == 0, -math.inf, inputs[first.clamp(max=UNQUANTIZE_SAMPLES - 1)])
    high = torch.where(last >= UNQUANTIZE_SAMPLES - 1, math.inf, inputs[last.clamp(min=0)])
    return low, high, known


def _level_targets(
    effect: Effect, example: torch.Tensor, params: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor] | None:
    """What a cartoon ``example`` says of its colours before quantization, at the ``bins`` and
    ``softness`` of ``params``: the flat indices of its plateau pixels whose level the quantizer
    gives, the bounds of their luminance (:func:`unquantized_bounds`) and their chroma ``(2, N)``
    (a* and b* / 100); None where fewer than 64 pixels show them."""
    values = effect.params_to_dict(params.reshape(-1))
    lab = rgb_to_lab(example.clamp(0.0, 1.0))
    low, high, known = unquantized_bounds((lab[:, :1] / 100.0).flatten(), values["bins"], values["softness"])
    used = (plateau_pixels(example).flatten() & known).nonzero().flatten()
    if len(used) < 64:
        return None
    return used, low[used], high[used], lab[0, 1:].flatten(1)[:, used] / 100.0


def _level_loss(abstracted: torch.Tensor, low: torch.Tensor, high: torch.Tensor, chroma: torch.Tensor) -> torch.Tensor:
    """How far abstracted colours ``(3, N)`` (CIE Lab / 100) are from lying where the quantizer maps
    them to the example's levels, with the example's chroma."""
    luminance = abstracted[0]
    outside = torch.relu(low - luminance) + torch.relu(luminance - high)
    return outside.square().mean() + (abstracted[1:] - chroma).square().mean()


def _colour_indices(effect: Effect) -> list[int]:
    return [effect.param_names.index(name) for name in COLOUR_ADJUSTMENTS if name in effect.param_names]


def fit_colours_to_levels(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor
) -> torch.Tensor:
    """``params`` ``(1, P)`` with the colour adjustments descended so that the content's
    abstracted colours agree with a cartoon ``example`` un-quantized at its ``bins`` and
    ``softness``: the chroma (a*, b*) is the example's wherever no outline darkens it, and the
    luminance lies where the quantizer maps it to the example's level (:func:`unquantized_bounds`).
    Unlike the rendered look, these change smoothly with the colour adjustments, so descent on
    them does not stall on the staircase. Runs at :data:`FIT_SIDE` pixels."""
    content, example = _working_copy(content, FIT_SIDE), _working_copy(example, FIT_SIDE)
    targets = _level_targets(effect, example, params)
    if targets is None:
        return params
    used, low, high, chroma = targets
    held = torch.ones(params.shape[-1], dtype=torch.bool, device=params.device)
    held[_colour_indices(effect)] = False
    descended = params.detach().clone().requires_grad_()
    optimizer = Adam([descended], lr=FIT_LR)
    for _ in range(FIT_ITERATIONS):
        optimizer.zero_grad(set_to_none=True)
        p, ctx = effect.real_values(content, descended)
        abstracted = effect.abstraction(content, p, ctx)[0].flatten(2)[0][:, used] / 100.0
        _level_loss(abstracted, low, high, chroma).backward()
        assert descended.grad is not None
        descended.grad[:, held] = 0.0
        optimizer.step()
        with torch.no_grad():
            descended.clamp_(NORMALIZED_MIN, NORMALIZED_MAX)
    return descended.detach()


def colours_from_levels(
    effect: Effect,
    content: torch.Tensor,
    example: torch.Tensor,
    params: torch.Tensor,
    deadline: float | None = None,
) -> torch.Tensor:
    """:func:`fit_colours_to_levels` in a fraction of a second: the content is abstracted once,
    before any colour adjustment (the bilateral filter smooths much as it would after them), and
    the colour adjustments are descended on a seeded sample of :data:`LEVEL_FIT_PIXELS` plateau
    pixels, each iteration adjusting those colours alone. The abstraction's dependence on the
    adjustments is left out, so this reads the tone at the resolution it is given and is a
    start to be judged, not an answer. ``params`` ``(1, P)`` unchanged where too few plateau
    pixels show the levels. With ``deadline`` (a :func:`time.perf_counter` value) the descent stops
    there, however far it got."""
    targets = _level_targets(effect, example, params)
    if targets is None:
        return params
    used, low, high, chroma = targets
    generator = torch.Generator().manual_seed(0)
    sample = torch.randperm(len(used), generator=generator)[:LEVEL_FIT_PIXELS].to(used.device)
    used, low, high, chroma = used[sample], low[sample], high[sample], chroma[:, sample]
    p, ctx = effect.real_values(content, params)
    with torch.no_grad():
        colours = _abstracted_colours(effect, content, p["details"], ctx.scale, CARTOON_PASSES)
    colours = colours.flatten(2)[:, :, used, None]
    indices = _colour_indices(effect)
    specs = [effect.param_specs[index] for index in indices]
    lows = torch.tensor([spec.min for spec in specs], dtype=params.dtype, device=params.device)
    spans = torch.tensor([spec.span for spec in specs], dtype=params.dtype, device=params.device)
    names = [spec.name for spec in specs]
    fitted = params.detach()[0, indices].clone().requires_grad_()
    optimizer = Adam([fitted], lr=LEVEL_FIT_LR)
    for _ in range(LEVEL_FIT_ITERATIONS):  # callers may hold autograd off; this descent needs it
        if deadline is not None and time.perf_counter() > deadline:
            break
        optimizer.zero_grad(set_to_none=True)
        with torch.enable_grad():
            real = (fitted - NORMALIZED_MIN) * spans + lows
            adjusted = adjust_color(colours, **{name: real[i : i + 1] for i, name in enumerate(names)})
            _level_loss(rgb_to_lab(adjusted)[0].flatten(1) / 100.0, low, high, chroma).backward()
        optimizer.step()
        with torch.no_grad():
            fitted.clamp_(NORMALIZED_MIN, NORMALIZED_MAX)
    result = params.detach().clone().reshape(1, -1)
    result[0, indices] = fitted.detach()
    return result.reshape(params.shape)


def _cartoon_ink(
    effect: Effect, luminance: torch.Tensor, tangent: torch.Tensor, p: dict[str, torch.Tensor], scale: float
) -> torch.Tensor:
    """The ink the cartoon's outlines multiply over its colours, from its abstracted ``luminance``
    (L* / 100) and flow, as its rendering draws it."""
    smoothing = detail_sigmas(p["details"])["edge_smoothing"]
    return xdog_lines(
        luminance, tangent, p["stroke_width"], p["contour"], p["blackness"], smoothing, effect.kernel_size, scale
    )


class _SampledPixels(NamedTuple):
    """What the cartoon's last stages need of a sample of ``N`` pixels: the abstracted luminance
    ``(N,)`` (L* / 100) and chroma ``(2, N)`` (a*, b*), the outlines' ink ``(N,)``, and the
    example's colours there ``(3, N)``."""

    luminance: torch.Tensor
    chroma: torch.Tensor
    ink: torch.Tensor
    colours: torch.Tensor


def _rendered_step_errors(sample: _SampledPixels, bins: torch.Tensor, softness: torch.Tensor) -> torch.Tensor:
    """The mean absolute error to the example's colours of the sampled pixels rendered with each
    pair of ``bins`` and ``softness`` (flat, the same length)."""
    luminance, chroma, ink, colours = sample
    count, pixels = len(bins), luminance.numel()
    levels = quantize(luminance.view(1, 1, 1, pixels).expand(count, 1, 1, pixels), bins, softness)
    lab = torch.cat((levels * LUMINANCE_RANGE, chroma.view(1, 2, 1, pixels).expand(count, 2, 1, pixels)), dim=1)
    rendered = (lab_to_rgb(lab) * ink.view(1, 1, 1, pixels)).clamp(0.0, 1.0)
    return (rendered - colours.view(1, 3, 1, pixels)).abs().mean(dim=(1, 2, 3))


def steps_from_rendering(
    effect: Effect,
    content: torch.Tensor,
    example: torch.Tensor,
    params: torch.Tensor,
    abstraction: tuple[torch.Tensor, torch.Tensor] | None = None,
) -> torch.Tensor:
    """``params`` ``(1, P)`` with the cartoon's ``bins`` and ``softness`` whose rendering of
    ``content``, the other parameters as they stand, is closest to ``example`` (L1) on a seeded
    sample of :data:`SWEEP_PIXELS` pixels, where closer than the values as they stand.

    Quantization is the pipeline's last stage before the outlines are multiplied: the abstracted
    colours and the ink are computed once, and each pair costs a quantization and a conversion of
    the sample, so the whole grid is tried (a coarse pass over the count's range, a fine one
    around the best). Unlike the histogram's plateaus (:func:`plateau_bins`), the rendering
    counts every pixel, clipped colours and outlines included, and unlike descent it does not
    stall on the staircase: once the colours are near the example's, this reads a count that the
    plateaus left open or read wrongly. ``abstraction``: the effect's abstracted colours and
    flow of ``content`` at ``params``, where the caller has them."""
    with torch.no_grad():
        p, ctx = effect.real_values(content, params)
        abstracted, tangent = effect.abstraction(content, p, ctx) if abstraction is None else abstraction
        luminance = abstracted[:, :1] / LUMINANCE_RANGE
        ink = _cartoon_ink(effect, luminance, tangent, p, ctx.scale)
        generator = torch.Generator().manual_seed(0)
        chosen = torch.randperm(luminance.numel(), generator=generator)[:SWEEP_PIXELS].to(content.device)
        sample = _SampledPixels(
            luminance=luminance.flatten()[chosen].clamp(0.0, 1.0),
            chroma=abstracted[0, 1:].flatten(1)[:, chosen],
            ink=ink.flatten()[chosen],
            colours=example[0].flatten(1)[:, chosen].to(abstracted),
        )
        like = {"dtype": abstracted.dtype, "device": abstracted.device}
        bins_spec, softness_spec = effect.spec("bins"), effect.spec("softness")

        def best_of(bins_grid: torch.Tensor, softness_values: int) -> tuple[float, float, float]:
            softness_grid = torch.linspace(softness_spec.min, softness_spec.max, softness_values, **like)
            bins = bins_grid.repeat_interleave(len(softness_grid))
            softness = softness_grid.repeat(len(bins_grid))
            errors = _rendered_step_errors(sample, bins, softness)
            index = int(errors.argmin())
            return float(errors[index]), float(bins[index]), float(softness[index])

        low, high = max(bins_spec.min, MIN_BINS), bins_spec.max
        coarse = best_of(torch.arange(low, high + 1e-6, SWEEP_COARSE_STEP, **like), SWEEP_COARSE_SOFTNESS)
        reach = SWEEP_COARSE_STEP + 1e-6
        around = torch.arange(coarse[1] - SWEEP_COARSE_STEP, coarse[1] + reach, SWEEP_FINE_STEP, **like)
        error, bins, softness = best_of(around.clamp(low, high), SWEEP_FINE_SOFTNESS)
        current = _rendered_step_errors(sample, p["bins"].reshape(1).to(**like), p["softness"].reshape(1).to(**like))
    if error >= float(current[0]):
        return params
    return _with(effect, params, bins=bins, softness=softness).to(params)


def _cartoon(effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor) -> Reading:
    bins_spec, softness_spec = effect.spec("bins"), effect.spec("softness")
    bins_range, softness_range = (bins_spec.min, bins_spec.max), (softness_spec.min, softness_spec.max)
    kept = plateau_pixels(example)
    if int(kept.sum()) >= 64:
        kept &= ~clamped_ends(example_luminance(example), kept)
    if int(kept.sum()) < 64:  # nothing flat to read: an outline drawing or a blank example
        return Reading(params, False)
    luminance = example_luminance(example)[kept]
    found = []
    candidates, agreements = plateau_bins(luminance, *bins_range)
    for bins in candidates:
        softness = softness_from_agreement(level_agreement(luminance, bins), bins, *softness_range)
        found.append(_with(effect, params, bins=bins, softness=softness))
    p, ctx = effect.real_values(content, params)
    abstracted, tangent = effect.abstraction(content, p, ctx)
    outlines = _outline_reading(effect, example, abstracted[:, :1] / 100.0, tangent, p, ctx.scale)[0]
    levels = occupied_levels(luminance, candidates[0])
    if (levels >= CLEAR_LEVELS and agreements[0] >= CLEAR_AGREEMENT) or (
        levels >= SHARP_LEVELS and agreements[0] >= SHARP_AGREEMENT
    ):
        # the period shows: plateaus so spaced and placed fit no other count; the outlines,
        # read from darker pixels that may also be dark paint, only where they fit better
        return Reading(closest(effect, content, example, [found[0], _with(effect, found[0], **outlines)]), True)
    # plateaus that fit several periods: the content's abstracted luminance, mapped onto the
    # example's by a staircase, is one more candidate, and the renders decide, at the outlines as
    # they stand, then with the outlines read (read wrongly, they would spoil every comparison)
    bins, softness = staircase_fit((abstracted[:, :1] / 100.0)[kept], luminance, bins_range, softness_range)
    found.append(_with(effect, params, bins=bins, softness=softness))
    steps = closest(effect, content, example, found)
    best = closest(effect, content, example, [steps, _with(effect, steps, **outlines)])
    found = [_with(effect, best, **_real(effect, f, "bins", "softness")) for f in found]
    others = [_with(effect, found[-1], bins=b) for b in SEARCHED_BINS if bins_range[0] <= b <= bins_range[1]]
    return Reading(best, False, found + others)


def _cartoon_outlines(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor, all_widths: bool = True
) -> dict[str, float]:
    """The cartoon's ``stroke_width``, ``contour`` and ``blackness`` read from the outlines of
    ``example``, with the other parameters at ``params``: for each of :data:`STROKE_WIDTHS` widths
    (or only the width of ``params``) the threshold that draws the example's ink best
    (:func:`_outline_reading`), the width whose ink overlaps the example's most kept (empty where
    no outline shows)."""
    p, ctx = effect.real_values(content, params)
    abstracted, tangent = effect.abstraction(content, p, ctx)
    luminance = abstracted[:, :1] / 100.0
    spec = effect.spec("stroke_width")
    widths = torch.linspace(spec.min, spec.max, STROKE_WIDTHS) if all_widths else p["stroke_width"].flatten()[:1]
    best: dict[str, float] = {}
    best_overlap = -1.0
    for width in widths.tolist():
        with_width = {**p, "stroke_width": torch.full_like(p["stroke_width"], width)}
        read, overlap = _outline_reading(effect, example, luminance, tangent, with_width, ctx.scale)
        if read and overlap > best_overlap:
            best, best_overlap = {"stroke_width": width, **read}, overlap
    return best


def _cartoon_colours(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor
) -> torch.Tensor:
    """``params`` with the colour adjustments fitted to the example's levels
    (:func:`fit_colours_to_levels`) and the outlines read again at them, where that fits better."""
    fitted = fit_colours_to_levels(effect, content, example, params)
    with torch.no_grad():
        outlines = _cartoon_outlines(effect, content, example, fitted)
        return closest(effect, content, example, [params, fitted, _with(effect, fitted, **outlines)])


def outline_ink(example: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The ink of outlines multiplied over colours, and where it can be seen: a pixel at less than
    :data:`INK` of the brightest colour near it (the colour the outline darkens), among pixels
    whose brightest neighbour is bright enough (:data:`VISIBLE_INK`) for a dark line to show."""
    brightness = example.clamp(0.0, 1.0).mean(dim=1, keepdim=True)
    around = F.max_pool2d(brightness, kernel_size=2 * OUTLINE_REACH + 1, stride=1, padding=OUTLINE_REACH)
    visible = around > VISIBLE_INK
    return (brightness < INK * around) & visible, visible


def _outline_reading(
    effect: Effect,
    example: torch.Tensor,
    luminance: torch.Tensor,
    tangent: torch.Tensor,
    p: dict[str, torch.Tensor],
    scale: float,
    contours: torch.Tensor | None = None,
) -> tuple[dict[str, float], float]:
    """``contour`` and ``blackness`` of the outlines of ``example``, read from its ink and the
    edge response of the abstracted ``luminance`` (empty where no outline shows), and how well
    that threshold's ink overlaps the example's (intersection over union; -1 where none shows).
    ``contours``: those tried (default: :data:`CONTOUR_CANDIDATES` over the parameter's range)."""
    smoothing = detail_sigmas(p["details"])["edge_smoothing"]
    flat, sharpened = (
        edge_response(luminance, tangent, p["stroke_width"], c, smoothing, effect.kernel_size, scale)
        for c in (0.0, 1.0)
    )
    ink, visible = outline_ink(example)
    contour_spec, blackness_spec = effect.spec("contour"), effect.spec("blackness")
    contour, blackness, overlap = xdog_threshold_from_ink(
        ink,
        flat,
        sharpened - flat,
        torch.linspace(contour_spec.min, contour_spec.max, CONTOUR_CANDIDATES) if contours is None else contours,
        (blackness_spec.min, blackness_spec.max),
        current=float(p["contour"].mean()),
        valid=visible,
    )
    return ({} if overlap < 0 else {"contour": contour, "blackness": blackness}), overlap


def occupied_levels(luminance: torch.Tensor, bins: float) -> int:
    """How many of the levels ``(k + 1/2) / bins`` hold at least :data:`LEVEL_SHARE` of the
    luminance values within a quarter of a level's width."""
    position = luminance.double() * bins - 0.5
    nearest = position.round()
    near = (position - nearest).abs() < 0.25
    counts = torch.bincount(nearest[near].clamp_min(0).long())
    return int((counts >= LEVEL_SHARE * luminance.numel()).sum())


# ----- XDoG: ink share and the edge response ------------------------------------------------


def shading_from_example(drawing: torch.Tensor, luminance: torch.Tensor, low: float, high: float) -> float:
    """The shading ``s`` in ``[low, high]`` of a drawing ``(1, 1, H, W)`` (grey) over the
    abstracted luminance: the value whose shading ``1 - s (1 - L)`` most pixels follow within
    :data:`SHADING_FIT` (the ink falls below it), refined by least squares on those pixels."""
    darkness = 1.0 - luminance.clamp(0.0, 1.0)
    grid = torch.linspace(low, high, 41)
    shaded = 1.0 - grid.view(-1, 1, 1, 1) * darkness
    inliers = ((drawing / shaded.clamp_min(1e-3) - 1.0).abs() < SHADING_FIT).flatten(1).sum(dim=1)
    rough = grid[int(inliers.argmax())]
    near = ((drawing / (1.0 - rough * darkness).clamp_min(1e-3) - 1.0).abs() < SHADING_FIT) & (darkness > 0.02)
    if int(near.sum()) < 16:
        return float(rough)
    fitted = ((1.0 - drawing[near]) * darkness[near]).sum() / darkness[near].square().sum()
    return float(fitted.clamp(low, high))


def _row_quantile(values: torch.Tensor, share: float) -> torch.Tensor:
    """The ``share`` quantile of each row of ``values`` ``(R, N)``, interpolated linearly between
    order statistics as :func:`torch.quantile` does, from two selections instead of a sort
    (a third of the time for the 61 contours of a 512-pixel picture)."""
    count = values.shape[1]
    position = share * (count - 1)
    below = min(int(position), count - 1)
    low = torch.kthvalue(values, below + 1, dim=1).values
    high = torch.kthvalue(values, min(below + 2, count), dim=1).values
    return torch.lerp(low, high, torch.full_like(low, position - below))


def xdog_threshold_from_ink(
    ink: torch.Tensor,
    flat: torch.Tensor,
    edges: torch.Tensor,
    contours: torch.Tensor,
    blackness_range: tuple[float, float],
    current: float | None = None,
    valid: torch.Tensor | None = None,
) -> tuple[float, float, float]:
    """``(contour, blackness, overlap)``: the response ``u = flat + contour * edges`` (each
    ``(1, 1, H, W)``) thresholded at ``blackness`` marks the ink mask ``ink`` best (intersection
    over union) among ``contours``, each with the blackness that gives the example's ink share
    (a quantile of ``u``, clamped to ``blackness_range``). Of contours that mark it equally
    well (the ink does not tell them apart), the one nearest ``current`` is kept. Only the
    pixels of ``valid`` (default: all) are compared: where the example could show ink."""
    valid = torch.ones_like(ink) if valid is None else valid
    ink = ink[valid]
    share = float(ink.float().mean()) if ink.numel() else 0.0
    if share == 0.0:
        return float(contours[0]), blackness_range[0], -1.0
    flat, edges = flat[valid], edges[valid]
    responses = flat[None, :] + contours.to(flat)[:, None] * edges[None, :]
    stride = max(1, responses.shape[1] // 1_000_000)
    blackness = _row_quantile(responses[:, ::stride], share).clamp(*blackness_range)
    drawn = responses < blackness[:, None]
    overlaps = (drawn & ink).sum(dim=1) / (drawn | ink).sum(dim=1).clamp_min(1)
    tried = list(zip(contours.tolist(), blackness.tolist(), overlaps.tolist()))
    best = max(overlap for _, _, overlap in tried)
    ties = [entry for entry in tried if entry[2] >= best - TIED_OVERLAP]
    return min(ties, key=lambda entry: abs(entry[0] - (ties[0][0] if current is None else current)))


TONE_PARAMS = ("brightness", "contrast", "saturation")
"""The colour adjustments an XDoG's tone is read for (:func:`xdog_tones_from_shading`)."""
TONE_PIXELS = 500
"""Pixels of the example's shading the tone is fitted on: a random sample (seeded), enough for
three parameters and fast enough to score thousands of tones."""
TONE_CLEAR = 0.9
"""A pixel at this share or more of the brightest within :data:`OUTLINE_REACH` pixels lies off
the lines: its value is the shading alone."""
TONE_WHITE = 0.99
TONE_BLACK = 0.05
"""Pixels this bright or brighter are left out: content clamped to white (and a shading of 0)
puts them there whatever the tone; so are pixels this dark or darker: inside a wide area of ink,
no brighter pixel nearby tells them from the shading."""
TONE_TRIM = 0.6
"""Share of the pixels the fit keeps, those the tone describes best: the rest lie in the soft
border of the ink, which darkens them."""
TONE_DETAILS = (0.0, 0.75, 1.5, 2.25, 3.0)
TONE_DETAIL_STARTS = 1
"""The ``details`` tried where the abstraction is read with the tone, and the starts of each one's search."""
TONE_GRID = 8
TONE_STARTS = 3
TONE_ROUNDS = 4
"""The search over the tone: a grid of this many values of each colour adjustment, the best
:data:`TONE_STARTS` of it each refined by :data:`TONE_ROUNDS` rounds of a 5-point grid around it,
each 2.5 times finer than the one before."""


def _tone_residuals(
    colours: torch.Tensor, drawing: torch.Tensor, tones: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """For each tone ``(T, 3)`` (brightness, contrast, saturation) of ``colours`` ``(1, 3, N, 1)``:
    the shading ``s`` of the drawing's values ``(N,)`` over their luminance, by least squares on the
    :data:`TONE_TRIM` share of pixels it describes best, and that share's mean absolute residual."""
    adjusted = adjust_color(
        colours.expand(len(tones), -1, -1, -1), brightness=tones[:, 0], contrast=tones[:, 1], saturation=tones[:, 2]
    )
    darkness = 1.0 - (rgb_to_lab(adjusted)[:, 0] / 100.0).flatten(1).clamp(0.0, 1.0)
    weights = torch.ones_like(darkness)
    keep = max(1, int(TONE_TRIM * darkness.shape[1]))
    for _ in range(3):  # least squares, then again on the pixels it describes best
        shading = ((1.0 - drawing) * darkness * weights).sum(1) / (darkness.square() * weights).sum(1).clamp_min(1e-6)
        shading = shading.clamp(0.0, 1.0)
        residuals = (drawing - (1.0 - shading[:, None] * darkness)).abs()
        weights = (residuals <= residuals.kthvalue(keep, dim=1).values[:, None]).to(residuals)
    return shading, (residuals * weights).sum(1) / weights.sum(1)


def _shading_sample(example: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor] | None:
    """Indices (flat) and values of up to :data:`TONE_PIXELS` pixels of an XDoG ``example`` that
    show its shading alone (off the lines, neither white nor black); None where fewer than 64 do."""
    drawing = example.mean(dim=1, keepdim=True)
    around = F.max_pool2d(drawing, kernel_size=2 * OUTLINE_REACH + 1, stride=1, padding=OUTLINE_REACH)
    shown = (drawing >= TONE_CLEAR * around) & (drawing > TONE_BLACK) & (drawing < TONE_WHITE)
    clear = shown.flatten().nonzero().flatten()
    if len(clear) < 64:
        return None
    generator = torch.Generator().manual_seed(0)
    clear = clear[torch.randperm(len(clear), generator=generator)[:TONE_PIXELS].to(clear.device)]
    return clear, drawing.flatten()[clear]


def _abstracted_colours(
    effect: Effect, content: torch.Tensor, details: torch.Tensor, scale: float, passes: int = 1
) -> torch.Tensor:
    """``content`` ``(1, 3, H, W)`` smoothed by ``passes`` of the effects' flow-aligned bilateral
    filter at ``details`` (the XDoG's one, the cartoon's :data:`CARTOON_PASSES`), before any colour
    adjustment, in RGB."""
    sigmas = detail_sigmas(details)
    smoothed = rgb_to_lab(content)
    tangent = edge_flow(smoothed[:, :1], sigmas["structure"], scale)
    for _ in range(passes):
        smoothed = oriented_bilateral(
            smoothed, tangent, sigmas["bilateral_spatial"], sigmas["bilateral_range"], effect.kernel_size, scale
        )
    return lab_to_rgb(smoothed)


def _best_tone(effect: Effect, colours: torch.Tensor, values: torch.Tensor, starts: int) -> tuple[torch.Tensor, float]:
    """The tone (brightness, contrast, saturation) whose shading of ``colours`` ``(1, 3, N, 1)``
    follows the drawing's ``values`` ``(N,)`` best (:func:`_tone_residuals`), by the coarse-to-fine
    search of :data:`TONE_GRID` from the best ``starts`` of its grid, and its residual."""
    like = {"dtype": colours.dtype, "device": colours.device}
    specs = [effect.spec(name) for name in TONE_PARAMS]
    low = torch.tensor([spec.min for spec in specs], **like)
    high = torch.tensor([spec.max for spec in specs], **like)
    grid = torch.cartesian_prod(*(torch.linspace(spec.min, spec.max, TONE_GRID) for spec in specs)).to(**like)
    errors = _tone_residuals(colours, values, grid)[1]
    offsets = torch.cartesian_prod(*[torch.linspace(-2.0, 2.0, 5)] * 3).to(**like)
    best, best_error = grid[0], math.inf
    for centre in grid[errors.argsort()[:starts]]:
        step = (high - low) / (TONE_GRID - 1)
        for _ in range(TONE_ROUNDS):
            step = step / 2.5
            tones = torch.cat([centre[None], torch.minimum(torch.maximum(centre + offsets * step, low), high)])
            errors = _tone_residuals(colours, values, tones)[1]
            centre = tones[int(errors.argmin())]
        if float(errors.min()) < best_error:
            best, best_error = centre, float(errors.min())
    return best, best_error


def xdog_tones_from_shading(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor
) -> list[dict[str, float]]:
    """The colour adjustments and ``shading`` of an XDoG ``example`` read off its shading: off the
    lines the drawing is ``1 - s (1 - L)``, with ``L`` the luminance of the adjusted, abstracted
    content. The content is abstracted once per ``details`` (the bilateral filter smooths much as
    it would after the adjustments), each tone of a coarse-to-fine search adjusts it, and ``s``
    follows by least squares: no descent, so no local minimum of the lines' threshold. Two
    readings: at the ``details`` of ``params``, and with the abstraction's ``details`` read too,
    among :data:`TONE_DETAILS` (each with a shorter search), the one whose shading fits best (its
    dict has ``details``). Empty where the example shows too little shading off its lines."""
    sample = _shading_sample(example)
    if sample is None:
        return []
    pixels, values = sample
    p, ctx = effect.real_values(content, params)
    abstracted: dict[float, torch.Tensor] = {}

    def colours(details: float) -> torch.Tensor:  # each abstraction computed once
        if details not in abstracted:
            smoothed = _abstracted_colours(effect, content, torch.full_like(p["details"], details), ctx.scale)
            abstracted[details] = smoothed.flatten(2)[:, :, pixels, None]
        return abstracted[details]

    def reading(details: float) -> dict[str, float]:
        tone = _best_tone(effect, colours(details), values, TONE_STARTS)[0]
        shading = float(_tone_residuals(colours(details), values, tone[None])[0])
        shading_spec = effect.spec("shading")
        return {
            **dict(zip(TONE_PARAMS, tone.tolist())),
            "shading": min(max(shading, shading_spec.min), shading_spec.max),
        }

    fits = [(_best_tone(effect, colours(value), values, TONE_DETAIL_STARTS)[1], value) for value in TONE_DETAILS]
    chosen = min(fits)[1]
    return [reading(float(p["details"].flatten()[0])), {**reading(chosen), "details": chosen}]


def _xdog_lines_read(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor, shading: float | None
) -> torch.Tensor:
    """``params`` with ``contour`` and ``blackness`` read off the ink of ``example`` at the other
    parameters, and ``shading`` (read off the example where None)."""
    p, ctx = effect.real_values(content, params)
    luminance, tangent = effect.abstraction(content, p, ctx)
    smoothing = detail_sigmas(p["details"])["edge_smoothing"]
    response = [
        edge_response(luminance, tangent, p["stroke_width"], c, smoothing, effect.kernel_size, ctx.scale)
        for c in (0.0, 1.0)
    ]
    drawing = example.mean(dim=1, keepdim=True)
    shading_spec = effect.spec("shading")
    if shading is None:
        shading = shading_from_example(drawing, luminance, shading_spec.min, shading_spec.max)
    shaded = (1.0 - shading * (1.0 - luminance.clamp(0.0, 1.0))).clamp_min(1e-3)
    ink = drawing / shaded < INK
    contour_spec, blackness_spec = effect.spec("contour"), effect.spec("blackness")
    contours = torch.linspace(contour_spec.min, contour_spec.max, CONTOUR_CANDIDATES)
    contour, blackness, overlap = xdog_threshold_from_ink(
        ink,
        response[0],
        response[1] - response[0],
        contours,
        (blackness_spec.min, blackness_spec.max),
        current=float(p["contour"].mean()),
    )
    if overlap < 0:  # no ink: the lines are not there to read
        return _with(effect, params, shading=shading)
    return _with(effect, params, shading=shading, contour=contour, blackness=blackness)


def _xdog(effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor) -> Reading:
    with torch.no_grad():
        lines = _xdog_lines_read(effect, content, example, params, None)
        toned = []
        for tone in xdog_tones_from_shading(effect, content, example, params):
            adjusted = _with(effect, params, **{name: tone[name] for name in (*TONE_PARAMS, "details") if name in tone})
            toned.append(_xdog_lines_read(effect, content, example, adjusted, tone["shading"]))
        # taken only where it fits better (read_steps): read at the other parameters' current
        # values, the ink can be drawn by a threshold that descent must be free to leave (one trial
        # of the benchmark: held, 0.935 SSIM; free, 0.994)
        return Reading(lines, False, alternatives=toned)


# ----- shared -------------------------------------------------------------------------------


INVERTED_PARAMS: dict[str, tuple[str, ...]] = {
    "cartoon": ("bins", "softness", "contour", "blackness"),
    "xdog": ("contour", "blackness", "shading"),
}
"""The parameters each effect's estimate sets; the others are left where they stand."""

FITTED_PARAMS: dict[str, tuple[str, ...]] = {
    "cartoon": (*COLOUR_ADJUSTMENTS, "stroke_width"),
    "xdog": (*TONE_PARAMS, "details"),
}
"""The parameters fitted besides those read: cartoon's in :func:`read_starts`, for its second
start (the colours and the outlines' width); xdog's with its shading, the tone and the
abstraction (:func:`xdog_tones_from_shading`)."""

HELD_PARAMS: dict[str, tuple[str, ...]] = {"cartoon": ("bins",), "xdog": ()}
"""Of those, the ones with no useful gradient: read clearly, descent holds them. The others have
a gradient once the steps line up (softness and shading everywhere, the soft threshold at the
ink's border) and are refined."""

_ESTIMATES: dict[str, Callable[[Effect, torch.Tensor, torch.Tensor, torch.Tensor], Reading]] = {
    "cartoon": _cartoon,
    "xdog": _xdog,
}

_COLOUR_FITS: dict[str, Callable[[Effect, torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor]] = {
    "cartoon": _cartoon_colours,
}
"""Fits of the other parameters that the steps, once read, make smooth (:func:`read_starts`)."""


def _with(effect: Effect, params: torch.Tensor, **values: float) -> torch.Tensor:
    """``params`` ``(1, P)`` with the named parameters set to real ``values`` (normalized, clamped)."""
    changed = params.detach().clone()
    for name, value in values.items():
        normalized = effect.spec(name).to_normalized(value)
        changed[0, effect.param_names.index(name)] = min(max(normalized, NORMALIZED_MIN), NORMALIZED_MAX)
    return changed


def _real(effect: Effect, params: torch.Tensor, *names: str) -> dict[str, float]:
    """The named parameters of ``params`` ``(1, P)`` in real units."""
    values = effect.params_to_dict(params.reshape(-1))
    return {name: values[name] for name in names}


def _working_copy(image: torch.Tensor, side: int) -> torch.Tensor:
    short = min(image.shape[-2:])
    if short <= side:
        return image
    factor = side / short
    size = (max(8, round(image.shape[-2] * factor)), max(8, round(image.shape[-1] * factor)))
    return F.interpolate(image, size=size, mode="area")


def invertible(effect: Effect) -> bool:
    """Whether :func:`invert_steps` estimates any of ``effect``'s parameters."""
    return getattr(effect, "name", None) in _ESTIMATES


def invert_steps(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor, side: int = WORKING_SIDE
) -> torch.Tensor:
    """:func:`read_steps` without the names to hold."""
    return read_steps(effect, content, example, params, side)[0]


def read_steps(
    effect: Effect,
    content: torch.Tensor,
    example: torch.Tensor,
    params: torch.Tensor,
    side: int = WORKING_SIDE,
    search: bool = False,
    at_reference: bool = False,
) -> tuple[torch.Tensor, tuple[str, ...]]:
    """``params`` (normalized ``(1, P)``) with the step-like parameters of ``effect`` read off
    ``example``, the effect's rendering of ``content`` (both ``(1, 3, H, W)``, same size); the
    others unchanged. An estimate the example shows clearly (several plateaus, ink drawn as the
    example's) is taken; one it leaves open only where its render fits the example better.
    Estimated on copies whose short side is ``side`` at most; without autograd. Returns the
    parameters and, where the example showed them clearly, the staircase parameters
    (:data:`HELD_PARAMS`) that descent should hold (:attr:`wise.optimize.parametric.Settings.held`).
    With ``search``, an estimate the example leaves open is settled by a short discrete search:
    each candidate descended briefly at :data:`SEARCH_SIDE` pixels, the best kept (seconds).
    ``at_reference``: the example is drawn as ``wise apply`` draws it (a small picture enlarged),
    and the renders that judge are drawn so (:class:`wise.render.Look`)."""
    estimate = _ESTIMATES.get(getattr(effect, "name", ""))  # a wrapped effect (a test's) has none
    if estimate is None:
        return params, ()
    device = params.device
    with torch.no_grad():
        full_content, full_example = content.detach(), example.detach()
        content, example = _working_copy(content.detach(), side), _working_copy(example.detach(), side).to(content)
        given = params.detach().reshape(1, -1).to(content)
        reading = estimate(effect, content, example, given)
        found = reading.params
        if not reading.clear and reading.alternatives:
            # several readings: judged at up to JUDGE_SIDE, because a small copy's render is another
            # look (lines and steps at another scale) that can favour the wrong one
            judged_content = _working_copy(full_content, max(side, JUDGE_SIDE))
            judged_example = _working_copy(full_example, max(side, JUDGE_SIDE)).to(judged_content)
            found = closest(
                effect, judged_content, judged_example, [given, found, *reading.alternatives], at_reference=at_reference
            )
        elif not reading.clear:  # an estimate that the example leaves open must fit better than what was there
            found = closest(effect, content, example, [given, found])
    if not reading.clear and search and len(reading.candidates) > 1:
        found = best_after_brief_descent(effect, content, example, [given, *reading.candidates])
    held = HELD_PARAMS[effect.name] if reading.clear else ()
    return found.to(device=device, dtype=params.dtype).reshape(params.shape), held


def read_starts(
    effect: Effect,
    content: torch.Tensor,
    example: torch.Tensor,
    params: torch.Tensor,
    side: int = WORKING_SIDE,
    at_reference: bool = False,
) -> tuple[list[torch.Tensor], tuple[str, ...]]:
    """The starts of a multi-start descent and the parameters it holds: :func:`read_steps` with
    ``search``, and where the effect has a fit of the parameters the steps make smooth (cartoon:
    the colours and the outlines' width, :func:`fit_colours_to_levels`) and it changes them, the
    reading so fitted as a second start. Fitted to steps or outlines read wrongly, the colours
    mislead descent; fitted to nearly right ones, they lead it to the example (BENCHMARKS.md, "Two
    starts where the count is unclear", "Two starts where the steps are clear"): only a descent
    from both tells which."""
    found, held = read_steps(effect, content, example, params, side, search=True, at_reference=at_reference)
    fit = _COLOUR_FITS.get(getattr(effect, "name", ""))
    if fit is None:
        return [found], held
    small_content, small_example = _working_copy(content.detach(), side), _working_copy(example.detach(), side)
    reading = found.detach().reshape(1, -1).to(small_content)
    fitted = fit(effect, small_content, small_example.to(small_content), reading)
    if torch.equal(fitted, reading):
        return [found], held
    return [found, fitted.to(device=params.device, dtype=params.dtype).reshape(params.shape)], held


def _cartoon_colours_quickly(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor, deadline: float | None
) -> torch.Tensor:
    """``params`` with the colour adjustments fitted by :func:`colours_from_levels`, and the
    outlines' threshold read again at them at the width as it stands (the ink is read off the
    adjusted luminance; :func:`_cartoon_colours` reads every width, seconds), where that renders
    closer at this size."""
    fitted = colours_from_levels(effect, content, example, params, deadline)
    if deadline is not None and time.perf_counter() > deadline:
        return fitted
    with torch.no_grad():
        outlines = _cartoon_outlines(effect, content, example, fitted, all_widths=False)
    return closest(effect, content, example, [fitted, _with(effect, fitted, **outlines)]) if outlines else fitted


_QUICK_FITS: dict[str, Callable[[Effect, torch.Tensor, torch.Tensor, torch.Tensor, float | None], torch.Tensor]] = {
    "cartoon": _cartoon_colours_quickly,
}


def fits_quickly(effect: Effect) -> bool:
    """Whether :func:`fit_quickly` has a fit for ``effect``."""
    return getattr(effect, "name", None) in _QUICK_FITS


def fit_quickly(
    effect: Effect,
    content: torch.Tensor,
    example: torch.Tensor,
    params: torch.Tensor,
    side: int = WORKING_SIDE,
    deadline: float | None = None,
    at_reference: bool = False,
) -> torch.Tensor:
    """``params`` (normalized ``(1, P)``) with the parameters that the steps read make smooth fitted
    within about a second, where a refinement of seconds has no time for :func:`read_starts`'
    fit (cartoon: the colour adjustments, :func:`colours_from_levels`, and the outlines' threshold
    read again at them, on copies whose short side is ``side``); kept where its render at up to
    :data:`JUDGE_SIDE` pixels fits ``example`` better. Unchanged for effects without such a fit.
    With ``deadline`` (a :func:`time.perf_counter` value) the fit stops there with what it has,
    which is then judged as before; ``at_reference`` as for :func:`read_steps`."""
    fit = _QUICK_FITS.get(getattr(effect, "name", ""))
    if fit is None:
        return params
    small_content = _working_copy(content.detach(), side)
    small_example = _working_copy(example.detach(), side).to(small_content)
    given = params.detach().reshape(1, -1).to(small_content)
    fitted = fit(effect, small_content, small_example, given, deadline)
    if torch.equal(fitted, given):
        return params
    judged_content = _working_copy(content.detach(), max(side, JUDGE_SIDE))
    judged_example = _working_copy(example.detach(), max(side, JUDGE_SIDE)).to(judged_content)
    best = closest(
        effect,
        judged_content,
        judged_example,
        [given.to(judged_content), fitted.to(judged_content)],
        at_reference=at_reference,
    )
    return best.to(device=params.device, dtype=params.dtype).reshape(params.shape)


def _contours_near(effect: Effect, contour: float) -> torch.Tensor:
    """The contours within :data:`SETTLED_CONTOUR_REACH` of ``contour``, at :data:`SETTLED_CONTOUR_STEP`."""
    spec = effect.spec("contour")
    low, high = max(spec.min, contour - SETTLED_CONTOUR_REACH), min(spec.max, contour + SETTLED_CONTOUR_REACH)
    return torch.linspace(low, high, max(2, round((high - low) / SETTLED_CONTOUR_STEP) + 1))


def _cartoon_after_descent(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor
) -> list[torch.Tensor]:
    """The count and ramps swept through the rendering (:func:`steps_from_rendering`), then the
    outlines' threshold read again at the width as it stands, among contours within
    :data:`SETTLED_CONTOUR_REACH` of descent's (:func:`_outline_reading`). Neither changes the
    abstraction, so it is computed once."""
    with torch.no_grad():
        p, ctx = effect.real_values(content, params)
        abstraction = effect.abstraction(content, p, ctx)
        swept = steps_from_rendering(effect, content, example, params, abstraction)
        luminance, tangent = abstraction[0][:, :1] / LUMINANCE_RANGE, abstraction[1]
        contours = _contours_near(effect, float(p["contour"].mean()))
        outlines = _outline_reading(effect, example, luminance, tangent, p, ctx.scale, contours)[0]
    answers = [swept, _with(effect, swept, **outlines)] if outlines else [swept]
    return [answer for answer in answers if not torch.equal(answer, params)]


_AFTER_DESCENT: dict[str, Callable[[Effect, torch.Tensor, torch.Tensor, torch.Tensor], list[torch.Tensor]]] = {
    "cartoon": _cartoon_after_descent,
}
"""xdog's threshold and shading read again after descent won in 15 of 18 trials, but the time
kept back for it cost descent as much (BENCHMARKS.md, "Readings after descent")."""


def readable_after_descent(effect: Effect) -> bool:
    """Whether :func:`read_after_descent` has readings for ``effect``."""
    return getattr(effect, "name", None) in _AFTER_DESCENT


def read_after_descent(
    effect: Effect, content: torch.Tensor, example: torch.Tensor, params: torch.Tensor, side: int = JUDGE_SIDE
) -> list[torch.Tensor]:
    """Other answers than ``params`` (normalized ``(1, P)``, where descent ended), read off
    ``example`` with the other parameters as descent left them, on copies whose short side is
    ``side`` at most; for the caller to judge by rendering (cartoon: the count and ramps swept
    through the rendering, :func:`steps_from_rendering`, and the outlines read again; none for
    other effects). For parameters near the answer: from a start far from it, the steps and the
    ink would be read against the wrong colours."""
    read = _AFTER_DESCENT.get(getattr(effect, "name", ""))
    if read is None:
        return []
    small_content = _working_copy(content.detach(), side)
    small_example = _working_copy(example.detach(), side).to(small_content)
    given = params.detach().reshape(1, -1).to(small_content)
    return [
        answer.to(device=params.device, dtype=params.dtype).reshape(params.shape)
        for answer in read(effect, small_content, small_example, given)
    ]


OUTLINE_PARAMS: dict[str, tuple[str, ...]] = {"cartoon": ("stroke_width", "contour", "blackness")}
"""The parameters that draw an effect's outlines over its colours (:func:`outline_darkening`)."""


def outline_darkening(effect: Effect, content: torch.Tensor, params: torch.Tensor) -> float:
    """How much the outlines of ``params`` ``(1, P)`` darken ``content``'s rendering: the mean of
    one less the ink the outlines multiply over the colours (0: no outlines, 1: black all over)."""
    with torch.no_grad():
        p, ctx = effect.real_values(content, params)
        abstracted, tangent = effect.abstraction(content, p, ctx)
        ink = _cartoon_ink(effect, abstracted[:, :1] / LUMINANCE_RANGE, tangent, p, ctx.scale)
    return float(1.0 - ink.mean())


def undoable_starts(
    effect: Effect, content: torch.Tensor, starts: list[torch.Tensor], given: torch.Tensor, side: int = SEARCH_SIDE
) -> list[torch.Tensor]:
    """``starts`` for per-pixel descent, each without what its masks could not undo: the outlines
    of ``given`` (``(1, P)``) where its own darken ``content`` more (:func:`outline_darkening`, on a
    copy whose short side is ``side``), and ramps between the levels no narrower than ``given``'s.

    A pixel inked black lies on the flat end of the outlines' threshold, and a pixel on a level's
    plateau on the flat of the quantizer: their masks get no gradient that would take the ink
    away or move the luminance. Outlines and hard steps read off a reference that is no cartoon
    (a neural style transfer: its dark paint, its banded tones) then stay, and descent buys the
    luminance it cannot reach with invented colours. Ink missing where the reference has some lies
    on the threshold's slope at the edges, and wider ramps on their slopes, where descent can
    move them."""
    if getattr(effect, "name", "") != "cartoon":
        return starts
    small = _working_copy(content.detach(), side)
    given = given.detach().reshape(1, -1).to(small)
    limit = outline_darkening(effect, small, given)
    outlines = [effect.param_names.index(name) for name in OUTLINE_PARAMS["cartoon"]]
    softness = effect.param_names.index("softness")
    kept = []
    for start in starts:
        flat = start.detach().reshape(1, -1).to(small).clone()
        if outline_darkening(effect, small, flat) > limit:
            flat[:, outlines] = given[:, outlines]
        flat[:, softness] = torch.maximum(flat[:, softness], given[:, softness])
        kept.append(start if torch.equal(flat, start.reshape(1, -1).to(small)) else flat.to(start).reshape(start.shape))
    return kept


def best_after_brief_descent(
    effect: Effect,
    content: torch.Tensor,
    example: torch.Tensor,
    candidates: list[torch.Tensor],
    settings: Settings | None = None,
    side: int = SEARCH_SIDE,
) -> torch.Tensor:
    """The candidate that, descended with ``settings`` (default: :data:`SEARCH_ITERATIONS` global
    iterations with its staircase parameters held) on copies whose short side is ``side``, fits
    ``example`` best by the settings' loss (:func:`~wise.optimize.parametric.image_distance`), the
    candidate as it was, not as descended: the full descent follows."""
    small_content, small_example = _working_copy(content, side), _working_copy(example, side)
    if settings is None:
        settings = Settings(
            mode="global", iterations=SEARCH_ITERATIONS, lr=SEARCH_LR, loss="l2", held=HELD_PARAMS[effect.name]
        )
    losses = []
    for candidate in candidates:
        outcome = optimize(effect, small_content, small_example, candidate, settings)
        with torch.no_grad():
            rendered = effect(small_content, outcome.params).clamp(0.0, 1.0)
            losses.append(float(image_distance(settings.loss, rendered, small_example)))
    return candidates[losses.index(min(losses))]


def inversion_between_levels(
    effect: Effect, content: torch.Tensor, example: torch.Tensor
) -> Callable[[torch.Tensor], torch.Tensor] | None:
    """:func:`invert_steps` for ``content`` and ``example`` as a hook of
    :func:`wise.optimize.parametric.optimize_coarse_to_fine`; None for an effect without estimates."""
    if not invertible(effect):
        return None
    return lambda params: invert_steps(effect, content, example, params)


def describe_estimates(effect: Effect, before: torch.Tensor, after: torch.Tensor) -> str | None:
    """``"bins 4.02, softness 0.10"``: the parameters :func:`read_steps` changed (read or
    fitted), in real units; None when it changed none."""
    old, new = effect.params_to_dict(before.reshape(-1)), effect.params_to_dict(after.reshape(-1))
    names = INVERTED_PARAMS.get(effect.name, ()) + FITTED_PARAMS.get(effect.name, ())
    changed = [f"{name} {new[name]:.2f}" for name in names if new[name] != old[name]]
    return ", ".join(changed) or None
