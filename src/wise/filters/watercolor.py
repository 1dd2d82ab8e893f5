"""Watercolor-specific filters: flat washes, wobbling, edge darkening, pigment density, gaps & overlaps,
wet-in-wet, paper shading.

Colours are expected in [0, 1] (RGB, 1 = white paper). Every filter is differentiable
with respect to the image and to its tensor parameters (including the texture, edge,
noise and direction maps).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from wise.errors import WiseError
from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image, resolution_scale
from wise.filters.flow import check_direction
from wise.filters.gaussian import SUPPORT, gaussian_blur
from wise.filters.quantize import quantize
from wise.filters.resize import bilinear_resize
from wise.filters.sampling import sample, tap_sum
from wise.filters.upsample import downsample

PAPER_WHITE = 1.0
"""The colour the paper shows through gaps."""
OVERLAP_WIDTH = 2.0
"""How far across the edge (reference pixels) gaps_overlaps looks for the other wash."""
EDGE_SIGMA = 2.0
"""Default width (reference pixels) of the edge-darkening rim."""
EDGE_GAIN = 8.0
"""Edge strength per unit of colour difference to the blurred image: a step of 0.3 between two
washes gives a strength of about 1.2 at the boundary."""
ACCENT_REDUCTION = 2
"""Resolution reduction at which :func:`feature_accents` blurs the surroundings of a feature."""
RIM_DENSITY = 1.0
"""Most extra pigment density of a rim (d - 1): the rim darkens a colour C to C^2 at most."""
RIM_KNEE = 0.01
"""Width of the soft knee at the rim threshold: below it the rim fades out smoothly, so the
darkening keeps a gradient for optimization."""
WET_SAMPLES = 6
"""Default number of samples on each side of a pixel for the wet-in-wet bleeding."""
NOISE_FEATHERING = 0.5
"""How much the noise changes the reach of the wet-in-wet bleeding: by up to this fraction either way."""
WASH_LEVELS = 8.0
"""Tones of the flat washes (CIE L* steps of 12.5)."""
WASH_SMOOTHING = 3.0
"""Smoothing of the lightness before it is split into washes (reference pixels)."""
WASH_STEP_REDUCTION = 2
"""Resolution reduction at which the steps of the flat washes are found."""
SOFTEST_WASH = 1.5
SHARPEST_WASH = 0.12
"""Ramp half-widths (bin widths) of the wash quantization at flatness 0 and 1."""
PAPER_SHADE = 0.15
"""Darkening of the paper's deepest valleys at full paper visibility."""
WASH_LIGHTNESS_GAIN = 2.0
"""Rate of :func:`wash_lightness`: at mid-grey a small ``amount`` adds about ``amount``, as the
additive brightness of :func:`wise.filters.adjust_color` does."""
_SELECTION_EPS = 1e-6
"""Keeps the soft choice between the two sides of an edge finite where both sides agree."""
_MAGNITUDE_EPS = 1e-4
"""Smooths the gradient magnitude at zero, where its square root has no derivative."""


def _check_map(value: torch.Tensor, image: torch.Tensor, name: str) -> None:
    """``value`` must be a ``(B, 1, H, W)`` tensor (a batch of 1 broadcasts) matching ``image``."""
    check_image(value, name=name, channels=1)
    if value.shape[0] not in (1, image.shape[0]) or value.shape[-2:] != image.shape[-2:]:
        raise WiseError(f"{name} {tuple(value.shape)} does not match the image {tuple(image.shape)}")


def _scale(image: torch.Tensor, scale: float | None) -> float:
    return resolution_scale(image) if scale is None else scale


def _central_differences(x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """d/dx and d/dy of ``x`` (B, C, H, W) per pixel, by central differences (one-sided at the border)."""
    padded_x = F.pad(x, (1, 1, 0, 0), mode="replicate")
    padded_y = F.pad(x, (0, 0, 1, 1), mode="replicate")
    gx = (padded_x[..., :, 2:] - padded_x[..., :, :-2]) * 0.5
    gy = (padded_y[..., 2:, :] - padded_y[..., :-2, :]) * 0.5
    return gx, gy


def pigment_density(image: torch.Tensor, density: ParamLike) -> torch.Tensor:
    """Bousseau et al. 2006 pigment density: ``C' = C - (C - C^2) (d - 1)``.

    ``d = 1`` leaves the colour unchanged, ``d > 1`` darkens (more pigment), ``d < 1``
    lightens; white (``C = 1``) and black stay as they are. For ``d`` in [0, 2] colours in
    [0, 1] stay in [0, 1]. The watercolor effect drives ``d`` with low-frequency noise
    (turbulence: uneven pigment), high-frequency noise (pigment dispersion) and the paper
    height map (granulation: pigment settling in the paper's valleys), e.g.
    ``d = 1 + strength * (noise - 0.5)``.

    Args:
        image: ``(B, C, H, W)`` colours in [0, 1].
        density: d; a float, ``(B,)`` or ``(B, 1, H, W)``.

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    d = as_map(density, image, "density")
    return image - (image - image * image) * (d - 1.0)


def wash_lightness(image: torch.Tensor, amount: ParamLike) -> torch.Tensor:
    """Lighter or darker washes that keep their hue: a thinner wash lets the paper through,
    ``C' = 1 - (1 - C) exp(-k a)`` for ``a > 0``; a thicker one darkens towards black,
    ``C' = C exp(k a)`` for ``a < 0`` (``k`` = :data:`WASH_LIGHTNESS_GAIN`).

    An offset added to every channel and clamped, as a brightness is, turns a skin's highlight
    white where its red channel reaches 1 while the rest of the skin keeps its hue, so the
    highlight reads as a bluish blotch; here every colour moves by the same share of its distance
    to white, so no channel clips and the hue of highlights stays that of their surroundings.

    Args:
        image: ``(B, C, H, W)`` colours in [0, 1].
        amount: in [-1, 1]; a float, ``(B,)`` or ``(B, 1, H, W)``. 0 leaves the image unchanged.

    Returns:
        ``(B, C, H, W)`` in [0, 1].
    """
    check_image(image)
    a = as_map(amount, image, "amount")
    lighter = PAPER_WHITE - (PAPER_WHITE - image) * torch.exp(-WASH_LIGHTNESS_GAIN * a.clamp(min=0.0))
    return lighter * torch.exp(WASH_LIGHTNESS_GAIN * a.clamp(max=0.0))


def edge_darkening(
    image: torch.Tensor,
    amount: ParamLike,
    sigma: ParamLike = EDGE_SIGMA,
    scale: float | None = None,
    *,
    guide: torch.Tensor | None = None,
    threshold: float = 0.0,
) -> torch.Tensor:
    """Edge darkening: pigment pools where a wash ends and dries there into a thin dark rim
    (Bousseau et al. 2006; the difference-of-blur edge of Montesdeoca et al. 2017).

    The edge strength comes from ``m = mean_c |G - G_sigma * G|``, the difference between the
    ``guide`` (the image itself by default) and its Gaussian blur, averaged over the channels:
    it peaks at a wash's boundary and is zero inside a flat wash, also where a boundary is
    soft. ``e = EDGE_GAIN * m`` without a threshold; with one,
    ``e = EDGE_GAIN * k * softplus((m - threshold) / k)`` (``k`` = :data:`RIM_KNEE`), a soft
    ``max(m - threshold, 0)`` that leaves small, faint features without a rim and keeps a
    gradient below the threshold.
    The colour is darkened with :func:`pigment_density` at density
    ``d = 1 + D tanh(amount * e / D)`` (``D`` = :data:`RIM_DENSITY`): about ``1 + amount * e``
    for a faint rim, never beyond ``1 + D``, where the darkest rim is ``C^2`` and no colour
    turns black (specks of black along a face's outline read as dirt, not pigment).

    Args:
        image: ``(B, C, H, W)`` colours in [0, 1].
        amount: darkening strength; a float, ``(B,)`` or ``(B, 1, H, W)``. 0 leaves the image unchanged.
        sigma: width of the rim, in pixels of a 512-pixel short side.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).
        guide: ``(B, C', H, W)`` picture whose boundaries get the rims, e.g. the washes before
            their tones are flattened, so that the steps of flat tones inside soft shading get
            none; ``image`` itself by default.
        threshold: colour difference to the blur below which no rim forms.

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    guide = image if guide is None else guide
    check_image(guide, name="guide")
    s = _scale(image, scale)
    difference = guide - gaussian_blur(guide, sigma, scale=s)
    magnitude = torch.sqrt(difference * difference + _MAGNITUDE_EPS * _MAGNITUDE_EPS) - _MAGNITUDE_EPS
    mean_magnitude = magnitude.mean(dim=1, keepdim=True)
    if threshold > 0:
        strength = EDGE_GAIN * RIM_KNEE * F.softplus((mean_magnitude - threshold) / RIM_KNEE)
    else:
        strength = EDGE_GAIN * mean_magnitude
    pooled = as_map(amount, image, "amount") * strength
    # saturates at the most pigment a rim holds: beyond d = 2 the density turns colours black
    return pigment_density(image, 1.0 + RIM_DENSITY * torch.tanh(pooled / RIM_DENSITY))


def wobble(image: torch.Tensor, texture: torch.Tensor, amount: ParamLike, scale: float | None = None) -> torch.Tensor:
    """Wobbling of Bousseau et al. 2006: the image displaced by the gradient of a texture.

    ``out(p) = image(p + amount * grad T(p))`` sampled bilinearly (border clamped), where
    ``grad T`` is the central-difference gradient of ``texture`` per reference pixel and the
    displacement is in reference pixels, so the wobble looks the same at every resolution.

    Args:
        image: ``(B, C, H, W)``.
        texture: ``(B, 1, H, W)`` height map, e.g. :func:`wise.filters.noise.paper_texture`.
        amount: displacement in reference pixels per unit of texture slope (per reference
            pixel); a float, ``(B,)`` or ``(B, 1, H, W)``.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    _check_map(texture, image, "texture")
    s = _scale(image, scale)
    gx, gy = _central_differences(texture)
    # slope per reference pixel is s * (per pixel); the displacement in pixels is s * (reference pixels)
    pixels = as_map(amount, image, "amount") * (s * s)
    offset = torch.cat((gx, gy), dim=1) * pixels
    return sample(image, offset.expand(image.shape[0], -1, -1, -1))


def _other_side(image: torch.Tensor, direction: torch.Tensor, distance: float) -> torch.Tensor:
    """The colour ``distance`` pixels away across the edge, on the side that differs more.

    ``direction`` has no reliable sign, so both sides are sampled and weighted by their
    squared colour difference to the pixel: the side of the other wash dominates.
    """
    ahead = sample(image, direction * distance) - image
    behind = sample(image, direction * -distance) - image
    diff_ahead = (ahead * ahead).sum(dim=1, keepdim=True)
    diff_behind = (behind * behind).sum(dim=1, keepdim=True)
    norm = diff_ahead + diff_behind + _SELECTION_EPS
    return image + (ahead * diff_ahead + behind * diff_behind) / norm


def gaps_overlaps(
    image: torch.Tensor,
    edges: ParamLike,
    direction: torch.Tensor,
    amount: ParamLike,
    noise: ParamLike,
    scale: float | None = None,
    *,
    width: float = OVERLAP_WIDTH,
) -> torch.Tensor:
    """Gaps and overlaps at edges, after Montesdeoca et al. 2017.

    With the band ``b = edges * noise`` (the noise breaks it up irregularly), the gap
    strength ``g = max(-amount, 0)`` and the overlap strength ``o = max(amount, 0)``:

        out = C + b * (g * (1 - C) + o * (C * C_other - C))

    Gaps let the white paper show through; overlaps mix the colour subtractively
    (multiply) with ``C_other``, the colour ``width`` reference pixels across the edge along
    ``direction`` (whichever side differs more from ``C``), as where two washes overlap.

    Args:
        image: ``(B, C, H, W)`` colours in [0, 1].
        edges: edge strength in [0, 1], e.g. a normalized gradient magnitude; a float,
            ``(B,)`` or ``(B, 1, H, W)``.
        direction: ``(B, 2, H, W)`` unit vectors across the edges (the gradient direction).
        amount: in [-1, 1]: negative for gaps, positive for overlaps, 0 for neither.
        noise: in [0, 1]; a float, ``(B,)`` or ``(B, 1, H, W)``.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).
        width: how far across the edge the other colour is taken, in reference pixels.

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    check_direction(direction, image)
    s = _scale(image, scale)
    band = as_map(edges, image, "edges") * as_map(noise, image, "noise")
    a = as_map(amount, image, "amount")
    gap, overlap = torch.relu(-a), torch.relu(a)
    if fused.enabled(image, direction, band, a):
        from wise.filters.fused.watercolor import GapsOverlaps

        across = direction.expand(image.shape[0], -1, -1, -1)
        return GapsOverlaps.apply(image, across, band, gap, overlap, width * s, PAPER_WHITE, _SELECTION_EPS)
    other = _other_side(image, direction.expand(image.shape[0], -1, -1, -1), width * s)
    change = gap * (PAPER_WHITE - image) + overlap * (image * other - image)
    return image + band * change


def _wet_weights(samples: int) -> list[float]:
    """Gaussian weights of samples ``0..samples`` spaced evenly out to ``SUPPORT`` sigma."""
    return [math.exp(-0.5 * (SUPPORT * j / samples) ** 2) for j in range(samples + 1)]


def wet_in_wet(
    image: torch.Tensor,
    direction: torch.Tensor,
    edges: ParamLike,
    amount: ParamLike,
    noise: ParamLike,
    scale: float | None = None,
    *,
    samples: int = WET_SAMPLES,
) -> torch.Tensor:
    """Wet-in-wet bleeding across edges, after Wang et al. 2014.

    Colours are blurred across the edges: ``samples`` bilinear samples on each side along
    ``direction``, evenly spaced out to the reach
    ``r = amount * (1 + NOISE_FEATHERING * (2 noise - 1))`` reference pixels (the noise makes
    the bleeding irregular and feathered), weighted by a Gaussian of sigma ``r / 2``. The
    bled colour is blended in where the paint is wet: ``out = C + edges * (bled - C)``.
    Backward recomputes the samples, so memory does not grow with ``samples``.

    Args:
        image: ``(B, C, H, W)``.
        direction: ``(B, 2, H, W)`` unit vectors across the edges (the gradient direction).
        edges: blend weight in [0, 1], high at the edges that bleed; a float, ``(B,)`` or ``(B, 1, H, W)``.
        amount: reach of the bleeding in reference pixels; a float, ``(B,)`` or ``(B, 1, H, W)``.
        noise: in [0, 1]; a float, ``(B,)`` or ``(B, 1, H, W)``.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).
        samples: samples on each side.

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    check_direction(direction, image)
    if samples < 1:
        raise WiseError(f"samples must be at least 1, got {samples}")
    s = _scale(image, scale)
    feathering = 1.0 + NOISE_FEATHERING * (2.0 * as_map(noise, image, "noise") - 1.0)
    spacing = as_map(amount, image, "amount") * (s / samples) * feathering
    step = (direction * spacing).expand(image.shape[0], -1, -1, -1)
    weights = _wet_weights(samples)
    blend = as_map(edges, image, "edges")
    if fused.enabled(image, step, blend):
        from wise.filters.fused.watercolor import WetInWet

        return WetInWet.apply(image, step, blend, weights)

    def tap(k: int, image: torch.Tensor, step: torch.Tensor) -> tuple[torch.Tensor]:
        j = k + 1
        both_sides = sample(image, step * float(j)) + sample(image, step * -float(j))
        return (both_sides * weights[j],)

    (total,) = tap_sum(tap, samples, image, step)
    bled = (image * weights[0] + total) / (weights[0] + 2.0 * sum(weights[1:]))
    return image + blend * (bled - image)


def flat_washes(
    image: torch.Tensor,
    lightness: torch.Tensor,
    flatness: ParamLike,
    levels: float = WASH_LEVELS,
    smoothing: float = WASH_SMOOTHING,
    scale: float | None = None,
) -> torch.Tensor:
    """Flat washes: the tones of ``image`` moved onto ``levels`` steps of even lightness.

    A wash is one layer of pigment of even density, so its tone is flat and changes in steps
    where the painter laid another wash (Wang et al. 2014 segment the photo for this). The
    ``lightness`` of the picture, smoothed by a Gaussian of ``smoothing`` so that the steps
    run along calm curves, is quantized with the soft quantizer of Winnemöller et al. 2006
    (:func:`wise.filters.quantize.quantize`); the colours move by the difference,
    ``out = C + flatness * (Q(S) - S)``, so shading within a step flattens and the chroma
    stays. The ramp between the tones is :data:`SOFTEST_WASH` bin widths at ``flatness`` 0
    and :data:`SHARPEST_WASH` at 1 (distinct steps that still have a gradient).

    Args:
        image: ``(B, C, H, W)`` colours in [0, 1].
        lightness: ``(B, 1, H, W)`` lightness in [0, 1] (CIE L* / 100) of the picture.
        flatness: in [0, 1]; a float, ``(B,)`` or ``(B, 1, H, W)``.
        levels: the number of tones.
        smoothing: sigma of the smoothing before the quantization, in pixels of a 512-pixel short side.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    _check_map(lightness, image, "lightness")
    s = _scale(image, scale)
    f = as_map(flatness, image, "flatness").clamp(0.0, 1.0)
    # the smoothed lightness has no detail finer than a few pixels: its steps are found at a
    # reduced resolution, a quarter of the cost, and interpolated back
    reduction = WASH_STEP_REDUCTION if min(image.shape[-2:]) >= 2 * WASH_STEP_REDUCTION * 8 else 1
    low = downsample(lightness, reduction) if reduction > 1 else lightness
    smooth = gaussian_blur(low, smoothing, scale=s / reduction).clamp(0.0, 1.0)
    low_f = downsample(f, reduction) if reduction > 1 and f.shape[-2:] == image.shape[-2:] else f
    softness = SOFTEST_WASH + (SHARPEST_WASH - SOFTEST_WASH) * low_f
    steps = quantize(smooth, levels, softness) - smooth
    if reduction > 1:
        steps = bilinear_resize(steps, image.shape[-2:])
    return (image + f * steps).clamp(0.0, 1.0)


def paper_shading(image: torch.Tensor, paper: torch.Tensor, amount: ParamLike) -> torch.Tensor:
    """The paper's relief seen through the paint: its valleys darken, ``out = C (1 - k a (1 - P))``
    with ``k`` = :data:`PAPER_SHADE`, so the grain shows in washes and on bare paper alike.

    Args:
        image: ``(B, C, H, W)`` colours in [0, 1].
        paper: ``(B, 1, H, W)`` height map in [0, 1], e.g. :func:`wise.filters.noise.paper_texture`.
        amount: in [0, 1]; a float, ``(B,)`` or ``(B, 1, H, W)``.

    Returns:
        ``(B, C, H, W)``.
    """
    check_image(image)
    _check_map(paper, image, "paper")
    return image * (1.0 - PAPER_SHADE * as_map(amount, image, "amount") * (1.0 - paper))


def feature_accents(
    washes: torch.Tensor,
    photo: torch.Tensor,
    strength: ParamLike = 1.0,
    sigma: float = 3.0,
    threshold: float = 0.04,
    knee: float = 0.08,
    scale: float | None = None,
) -> torch.Tensor:
    """Put back, as darker strokes of the wash's own colour, the small dark features that the
    washes lost (eyes, brows, nostrils, the line of the lips).

    With ``y`` the mean of the channels and ``G`` a Gaussian of ``sigma``, the photo's local
    darkness ``y_photo / G(y_photo)`` is laid onto the washes' local tone: the target lightness is
    ``G(y_washes) * y_photo / G(y_photo)``. Where the washes are lighter than that target by more
    than ``threshold`` (rising smoothly to full at ``threshold + knee``) they are glazed down
    towards it: ``washes * (1 + (target / y_washes - 1) strength w)``. The global tone of the washes
    (a pale preset) is kept, a large dark area (hair) is left as it is, and no wash is glazed
    below its target. Hue is kept: all channels scale alike.

    Args:
        washes: ``(B, 3, H, W)`` in [0, 1].
        photo: ``(B, 3, H, W)`` in [0, 1], the picture the washes abstract.
        strength: float, ``(B,)`` or ``(B, 1, H, W)``: 0 leaves the washes, 1 glazes them to the target.
        sigma: size of a feature's surroundings (pixels of a 512-pixel short side).
        threshold, knee: lightness loss (0–1) where the glaze starts, and the width of its rise.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, 3, H, W)``.
    """
    check_image(washes, "washes", channels=3)
    check_image(photo, "photo", channels=3)
    if photo.shape[-2:] != washes.shape[-2:] or photo.shape[0] not in (1, washes.shape[0]):
        raise WiseError(f"photo {tuple(photo.shape)} must match washes {tuple(washes.shape)}")
    s = _scale(washes, scale)
    weight_map = as_map(strength, washes, "strength")
    wash_light = washes.mean(dim=1, keepdim=True).clamp_min(1e-3)
    photo_light = photo.mean(dim=1, keepdim=True).clamp_min(1e-3)
    lights = torch.cat((photo_light.expand_as(wash_light), wash_light), dim=1)
    # the surroundings are smooth: blurred at half resolution (an eighth of the cost), then enlarged
    low = gaussian_blur(downsample(lights, ACCENT_REDUCTION), sigma, scale=s / ACCENT_REDUCTION)
    surroundings = bilinear_resize(low, lights.shape[-2:])
    target = surroundings[:, 1:2] * photo_light / surroundings[:, 0:1]
    ramp = ((wash_light - target - threshold) / knee).clamp(0.0, 1.0)
    weight = ramp * ramp * (3.0 - 2.0 * ramp)  # smoothstep
    ratio = (target / wash_light).clamp(1e-3, 1.0)
    return washes * (1.0 + (ratio - 1.0) * (weight_map * weight))
