"""Hand-written rules that find a region in a photo, for the synthetic content-adaptive tasks
of ``wise data adaptive`` (WISE, Lötzsch et al. 2022, Sec. 4.2).

Every rule takes ``(B, 3, H, W)`` RGB in [0, 1] and returns a soft region ``(B, 1, H, W)`` in
[0, 1]: 1 inside, 0 outside, with feathered borders and no speckle; the true (binary) region is
where the soft one exceeds :data:`INSIDE`. Each rule is a deterministic function of the pixels
of one picture, in three steps:

1. a *score* map measured at a coarse scale (so it varies smoothly over the picture);
2. a threshold on the score chosen from the picture's own distribution (Otsu's, kept between
   two quantiles so that every picture gets a region of a reasonable size, :func:`threshold`);
3. a clean-up of the thresholded map (a majority vote in a Gaussian window removes speckle and
   rounds the border; the subject of the background rule is also closed and its holes filled)
   and a Gaussian feather (:func:`smooth_region`).

Lengths are in pixels of a 512-pixel short side (as in :mod:`wise.filters`) and a rule looks at
a picture at most :data:`ANALYSIS_SIDE` pixels on its short side, so it finds the same region
in a picture at any resolution.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F
from skimage import measure

from wise.filters import gaussian_blur, resolution_scale, rgb_to_lab
from wise.filters.gaussian import local_deviation

INSIDE = 0.5
"""The true region is where the soft region exceeds this."""
ANALYSIS_SIDE = 256
"""Largest short side (pixels) a rule looks at: larger pictures are reduced first and the region
enlarged again (the regions are smooth at this size; filling holes costs time that grows with
the cube of the side)."""
LAB_L_RANGE = 100.0
"""CIE L* spans [0, 100]; luminance is L* / 100, in [0, 1] and perceptually even."""

COARSE_SIGMA = 12.0
"""Window of the local statistics (reference pixels): about the size of a face's eye or a
hand; finer windows make the regions follow single strokes, coarser ones whole halves."""
FINE_SIGMA = 3.0
"""Blur that separates fine texture (what it removes) from structure (reference pixels): the
scale of grass blades, hair and wrinkles in a 512-pixel picture (a smaller blur leaves little
to remove once a picture is reduced to a few hundred pixels)."""
CLEAN_SIGMA = 10.0
"""Window of the majority vote that removes speckle from a thresholded map (reference pixels):
islands and holes much smaller than this disappear."""
SPECK_RADIUS = 4.0
"""Radius (reference pixels) of the opening and closing after the majority vote; at least the
feather's sigma, so that the feather keeps every part and hole whole."""
SMALLEST_PART = 24.0
"""Side (reference pixels) of the square whose area every part of a region and every hole in it
has at least: about 0.2 % of a picture, twice the majority vote's window."""
FEATHER_SIGMA = 4.0
"""Feather of the region's border (reference pixels); the Gaussian is cut off at two sigma,
so the soft region is exactly 0 or 1 beyond that distance from the border."""

HISTOGRAM_BINS = 256
"""Bins of the score histogram Otsu's threshold is chosen on."""

CONTRAST_SIGMA = 24.0
"""Window of the local contrast (reference pixels): parts of a picture such as a face, a wall or
a head of hair, each with edges of one kind."""
CONTRAST_FLOOR = 0.01
"""Added to the local contrast before its logarithm (luminance units, 2.5 steps of 8 bits): the
contrast of sensor noise, below which all flat areas count as equally flat."""
CONTOUR_SHARES = (0.3, 0.6)
"""Smallest and largest share of a picture the low-contrast region covers."""

TEXTURE_FLOOR = 1e-3
"""Energy (squared luminance) added to the texture share's denominator: about a 3 % standard
deviation, well above 8-bit and JPEG noise, so that flat and noisy areas have a share near 0."""
TEXTURE_MIN = 0.1
"""Smallest texture share of the region, whatever the picture's distribution: a picture without
fine texture (a defocused close-up) gets a small region or none."""
DETAIL_SHARES = (0.2, 0.55)
"""Smallest and largest share of a picture the fine-texture region covers (the smallest only as
far as :data:`TEXTURE_MIN` allows)."""

SALIENCY_BLUR = 3.0
"""Blur before the colour distance of frequency-tuned saliency (reference pixels; Achanta et
al. use a 5x5 binomial kernel on small pictures)."""
FOCUS_ENERGIES = (1e-6, 1e-3)
"""Fine-texture energies (squared luminance) mapped to sharpness 0 and 1, on a log scale: a
0.1 % standard deviation is flat or defocused, 3 % is texture in focus (skin, hair, bark)."""
SALIENCY_QUANTILE = 0.95
"""The saliency is divided by this quantile of the picture (robust to a few extreme pixels)."""
SALIENCY_WEIGHT = 0.5
"""Weight of colour saliency in the subject score; the rest is sharpness (focus)."""
CENTRE_WEIGHT = 0.6
"""Centre prior: the subject score falls by this share from the centre to the corners (by half
of it to the middles of the sides); without it the smooth skin of a face, neither sharp nor
far from the mean colour, would count as background."""
SUBJECT_SIGMA = 24.0
"""The subject score is averaged in this window (reference pixels) so that the subject is
found as blobs, not as its edges."""
SUBJECT_SHARES = (0.2, 0.55)
"""Smallest and largest share of a picture the subject covers (before its holes are filled)."""
SUBJECT_CLOSING = 16.0
"""Radius (reference pixels) of the closing that joins the parts of a subject (eyes, mouth and
hair of a face, whose smooth skin scores low) before its holes are filled."""
FOREGROUND_CONNECTIVITY, BACKGROUND_CONNECTIVITY = 2, 1
"""A region's parts join diagonal neighbours, its holes only side by side (the usual pair, so
that a diagonal wall of a region is closed)."""
TINY = 1e-6
"""Keeps divisions finite on perfectly flat pictures."""


def luminance(image: torch.Tensor) -> torch.Tensor:
    """CIE L* / 100 of sRGB ``image`` ``(B, 3, H, W)``: ``(B, 1, H, W)`` in [0, 1]."""
    return rgb_to_lab(image)[:, :1] / LAB_L_RANGE


def _quantile(score: torch.Tensor, q: float) -> torch.Tensor:
    """Per picture ``q``-quantile of ``score`` ``(B, 1, H, W)`` (the nearest rank; ``torch.quantile``
    refuses large pictures): ``(B, 1, 1, 1)``."""
    values = score.flatten(1)
    rank = min(values.shape[1], max(1, round(q * (values.shape[1] - 1)) + 1))
    return values.kthvalue(rank, dim=1).values.view(-1, 1, 1, 1)


def _analysed(image: torch.Tensor, rule: Callable[[torch.Tensor], torch.Tensor]) -> torch.Tensor:
    """``rule`` applied to each picture of ``image`` ``(B, 3, H, W)`` reduced to a short side of
    at most :data:`ANALYSIS_SIDE`, its soft region enlarged bilinearly to ``(B, 1, H, W)``.
    One picture at a time: convolution kernels may round differently for other batch sizes,
    and a region must not depend on the pictures beside it."""
    if image.shape[0] > 1:
        return torch.cat([_analysed(picture, rule) for picture in image.split(1)])
    height, width = image.shape[-2:]
    factor = ANALYSIS_SIDE / min(height, width)
    if factor >= 1.0:
        return rule(image)
    size = (max(1, round(height * factor)), max(1, round(width * factor)))
    soft = rule(F.interpolate(image, size=size, mode="area"))
    return F.interpolate(soft, size=(height, width), mode="bilinear", align_corners=False).clamp(0.0, 1.0)


def otsu_threshold(score: torch.Tensor) -> torch.Tensor:
    """Otsu's threshold (1979) of each picture of ``score`` ``(B, 1, H, W)``: the value that
    splits its histogram into two classes of the largest between-class variance; ``(B, 1, 1, 1)``."""
    thresholds = []
    for values in score.flatten(1):
        low, high = float(values.min()), float(values.max())
        if high - low <= 0.0:
            thresholds.append(high)
            continue
        counts = torch.histc(values, HISTOGRAM_BINS, low, high).double()
        centres = low + (torch.arange(HISTOGRAM_BINS, dtype=torch.float64) + 0.5) * (high - low) / HISTOGRAM_BINS
        weight_below = counts.cumsum(0)
        mass_below = (counts * centres).cumsum(0)
        total, mass = weight_below[-1], mass_below[-1]
        weight_above = total - weight_below
        between = (mass_below * total - mass * weight_below).square() / (weight_below * weight_above).clamp_min(1.0)
        best = int(between[:-1].argmax())
        thresholds.append(low + (best + 1) * (high - low) / HISTOGRAM_BINS)
    return torch.tensor(thresholds, dtype=score.dtype, device=score.device).view(-1, 1, 1, 1)


def threshold(score: torch.Tensor, shares: tuple[float, float]) -> torch.Tensor:
    """Where ``score`` ``(B, 1, H, W)`` is above Otsu's threshold, the threshold kept between
    the quantiles that give the region the smallest and largest of ``shares`` of the picture;
    ``(B, 1, H, W)`` booleans."""
    smallest, largest = shares
    lowest, highest = _quantile(score, 1.0 - largest), _quantile(score, 1.0 - smallest)
    chosen = torch.minimum(torch.maximum(otsu_threshold(score), lowest), highest)
    return score > chosen


def _dilate(binary: torch.Tensor, radius: float, outside: bool) -> torch.Tensor:
    """Dilation of ``binary`` ``(B, 1, H, W)`` by a square of ``radius`` reference pixels, the
    pixels beyond the picture's border taken as ``outside``."""
    pixels = max(1, round(radius * resolution_scale(binary)))
    padded = F.pad(binary.float(), (pixels,) * 4, value=float(outside))
    return F.max_pool2d(padded, 2 * pixels + 1, stride=1) > INSIDE


def opening(binary: torch.Tensor, radius: float) -> torch.Tensor:
    """Morphological opening of ``binary`` ``(B, 1, H, W)`` by a square of ``radius`` reference
    pixels (an erosion, then a dilation; nothing beyond the border): islands and slivers narrower
    than the square go, at the border too. ``(B, 1, H, W)`` booleans."""
    eroded = ~_dilate(~binary, radius, outside=True)
    return _dilate(eroded, radius, outside=False)


def closing(binary: torch.Tensor, radius: float) -> torch.Tensor:
    """Morphological closing of ``binary`` ``(B, 1, H, W)``: the opening of its complement
    (:func:`opening`); holes, gaps and channels narrower than the square close."""
    return ~opening(~binary, radius)


def _component_areas(binary: torch.Tensor, connectivity: int) -> torch.Tensor:
    """The area (pixels) of the component each pixel of ``binary`` ``(B, 1, H, W)`` belongs to, 0
    outside it; ``connectivity`` 1 joins the 4 nearest neighbours, 2 the 8 around a pixel.
    ``(B, 1, H, W)``."""
    areas = []
    for picture in binary[:, 0].cpu().numpy():
        labels = measure.label(picture, connectivity=connectivity)
        areas.append(np.bincount(labels.ravel())[labels] * picture)
    return torch.from_numpy(np.stack(areas)).unsqueeze(1).to(binary.device)


def remove_small_parts(binary: torch.Tensor, side: float) -> torch.Tensor:
    """``binary`` ``(B, 1, H, W)`` without the islands, and with the holes filled, smaller than a
    square of ``side`` reference pixels; ``(B, 1, H, W)`` booleans."""
    smallest = (side * resolution_scale(binary)) ** 2
    kept = binary & (_component_areas(binary, FOREGROUND_CONNECTIVITY) >= smallest)
    return ~(~kept & (_component_areas(~kept, BACKGROUND_CONNECTIVITY) >= smallest))


def clean(binary: torch.Tensor) -> torch.Tensor:
    """A thresholded map ``(B, 1, H, W)`` without speckle: a majority vote in a Gaussian window
    of :data:`CLEAN_SIGMA`, an opening and a closing by a square of :data:`SPECK_RADIUS` (necks
    and slivers narrower than the square go), and no part or hole smaller than a square of
    :data:`SMALLEST_PART` (:func:`remove_small_parts`); ``(B, 1, H, W)`` booleans."""
    majority = gaussian_blur(binary.float(), CLEAN_SIGMA) > INSIDE
    return remove_small_parts(closing(opening(majority, SPECK_RADIUS), SPECK_RADIUS), SMALLEST_PART)


def feather(binary: torch.Tensor) -> torch.Tensor:
    """A binary map ``(B, 1, H, W)`` with its border blurred by a Gaussian of
    :data:`FEATHER_SIGMA`; ``(B, 1, H, W)`` in [0, 1]."""
    return gaussian_blur(binary.float(), FEATHER_SIGMA).clamp(0.0, 1.0)


def smooth_region(binary: torch.Tensor) -> torch.Tensor:
    """A thresholded map ``(B, 1, H, W)`` cleaned (:func:`clean`) and feathered
    (:func:`feather`); ``(B, 1, H, W)`` in [0, 1]."""
    return feather(clean(binary))


def fill_holes(binary: torch.Tensor) -> torch.Tensor:
    """``binary`` ``(B, 1, H, W)`` with its holes filled: the parts outside it that do not touch
    the picture's border join it. ``(B, 1, H, W)`` booleans."""
    filled = []
    for picture in binary[:, 0].cpu().numpy():
        labels = measure.label(~picture, connectivity=BACKGROUND_CONNECTIVITY)
        border = np.unique(np.concatenate((labels[0], labels[-1], labels[:, 0], labels[:, -1])))
        filled.append(picture | ~np.isin(labels, border))
    return torch.from_numpy(np.stack(filled)).unsqueeze(1).to(binary.device)


def local_contrast(image: torch.Tensor) -> torch.Tensor:
    """The standard deviation of the luminance in a Gaussian window of :data:`CONTRAST_SIGMA`:
    how strong the edges around each pixel are. ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    return local_deviation(luminance(image), CONTRAST_SIGMA)


def low_contrast_region(image: torch.Tensor) -> torch.Tensor:
    """The ``contours`` rule: where the local contrast (:func:`local_contrast`) is low compared
    with the rest of the picture, i.e. where edges are weak. ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""

    def rule(picture: torch.Tensor) -> torch.Tensor:
        score = -torch.log(local_contrast(picture) + CONTRAST_FLOOR)
        return smooth_region(threshold(score, CONTOUR_SHARES))

    return _analysed(image, rule)


def fine_energy(image: torch.Tensor) -> torch.Tensor:
    """The energy of fine texture: the luminance minus its blur of :data:`FINE_SIGMA`, squared
    and averaged in a Gaussian window of :data:`COARSE_SIGMA`. ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    lum = luminance(image)
    fine = lum - gaussian_blur(lum, FINE_SIGMA)
    return gaussian_blur(fine.square(), COARSE_SIGMA)


def texture_share(image: torch.Tensor) -> torch.Tensor:
    """The share of the local luminance energy that is fine texture, in [0, 1): fine energy
    (:func:`fine_energy`) over itself plus the local variance of the coarse structure (the
    luminance blurred by :data:`FINE_SIGMA`) plus :data:`TEXTURE_FLOOR`. High on grass, hair and
    wrinkles; low on smooth shading, large clean edges and flat areas.
    ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    fine = fine_energy(image)
    structure = local_deviation(gaussian_blur(luminance(image), FINE_SIGMA), COARSE_SIGMA).square()
    return fine / (fine + structure + TEXTURE_FLOOR)


def fine_texture_region(image: torch.Tensor) -> torch.Tensor:
    """The ``details`` rule: where fine texture dominates (:func:`texture_share` high compared
    with the rest of the picture, and at least :data:`TEXTURE_MIN`). ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""

    def rule(picture: torch.Tensor) -> torch.Tensor:
        share = texture_share(picture)
        return smooth_region(threshold(share, DETAIL_SHARES) & (share > TEXTURE_MIN))

    return _analysed(image, rule)


def colour_saliency(image: torch.Tensor) -> torch.Tensor:
    """Frequency-tuned saliency (Achanta et al. 2009): the CIE Lab distance of the slightly
    blurred picture from the picture's mean colour, divided by its :data:`SALIENCY_QUANTILE`
    quantile and clamped to [0, 1]. ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    lab = rgb_to_lab(gaussian_blur(image, SALIENCY_BLUR))
    distance = (lab - lab.mean(dim=(2, 3), keepdim=True)).norm(dim=1, keepdim=True)
    return (distance / _quantile(distance, SALIENCY_QUANTILE).clamp_min(TINY)).clamp(0.0, 1.0)


def sharpness(image: torch.Tensor) -> torch.Tensor:
    """Focus: the fine-texture energy (:func:`fine_energy`; a defocused or flat area has none)
    on a log scale, mapped to [0, 1] between :data:`FOCUS_ENERGIES`; it saturates in every
    part that is in focus. ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    low, high = (math.log(e) for e in FOCUS_ENERGIES)
    energy = torch.log(fine_energy(image).clamp_min(FOCUS_ENERGIES[0]))
    return ((energy - low) / (high - low)).clamp(0.0, 1.0)


def centre_prior(height: int, width: int, like: torch.Tensor) -> torch.Tensor:
    """``1 - CENTRE_WEIGHT * r**2`` with ``r`` the distance from the centre, 1 at the corners;
    ``(1, 1, H, W)``."""
    ys = torch.linspace(-1.0, 1.0, height, dtype=like.dtype, device=like.device).view(-1, 1)
    xs = torch.linspace(-1.0, 1.0, width, dtype=like.dtype, device=like.device).view(1, -1)
    return (1.0 - CENTRE_WEIGHT * (ys.square() + xs.square()) / 2.0).view(1, 1, height, width)


def subject_score(image: torch.Tensor) -> torch.Tensor:
    """How much each pixel looks like the subject: colour saliency and sharpness, weighted by
    :data:`SALIENCY_WEIGHT`, times the centre prior, averaged in a window of
    :data:`SUBJECT_SIGMA`. ``(B, 3, H, W)`` -> ``(B, 1, H, W)`` in [0, 1]."""
    mixed = SALIENCY_WEIGHT * colour_saliency(image) + (1.0 - SALIENCY_WEIGHT) * sharpness(image)
    prior = centre_prior(image.shape[-2], image.shape[-1], image)
    return gaussian_blur(mixed * prior, SUBJECT_SIGMA)


def background_region(image: torch.Tensor) -> torch.Tensor:
    """The ``background`` rule: everything but the subject, the subject being where
    :func:`subject_score` is high compared with the rest of the picture (its share kept within
    :data:`SUBJECT_SHARES`), cleaned and with its holes filled (:func:`fill_holes`: a subject
    has no background inside it). ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""

    def rule(picture: torch.Tensor) -> torch.Tensor:
        subject = threshold(subject_score(picture), SUBJECT_SHARES)
        return feather(~fill_holes(closing(clean(subject), SUBJECT_CLOSING)))

    return _analysed(image, rule)


def true_region(soft: torch.Tensor) -> torch.Tensor:
    """The binary region of a soft one ``(B, 1, H, W)``: where it exceeds :data:`INSIDE`."""
    return soft > INSIDE


def region_share(soft: torch.Tensor) -> torch.Tensor:
    """The share of each picture inside the true region: ``(B,)``."""
    return true_region(soft).flatten(1).float().mean(dim=1)


__all__ = [
    "INSIDE",
    "background_region",
    "centre_prior",
    "colour_saliency",
    "fine_energy",
    "fine_texture_region",
    "local_contrast",
    "low_contrast_region",
    "luminance",
    "otsu_threshold",
    "region_share",
    "sharpness",
    "smooth_region",
    "subject_score",
    "texture_share",
    "threshold",
    "true_region",
]
