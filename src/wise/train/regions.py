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
   rounds the border) and a Gaussian feather (:func:`smooth_region`).

Lengths are in pixels of a 512-pixel short side (as in :mod:`wise.filters`), so a rule finds
the same region in a picture at any resolution.
"""

from __future__ import annotations

import torch

from wise.filters import gaussian_blur, rgb_to_lab
from wise.filters.gaussian import local_deviation

INSIDE = 0.5
"""The true region is where the soft region exceeds this."""
LAB_L_RANGE = 100.0
"""CIE L* spans [0, 100]; luminance is L* / 100, in [0, 1] and perceptually even."""

COARSE_SIGMA = 12.0
"""Window of the local statistics (reference pixels): about the size of a face's eye or a
hand; finer windows make the regions follow single strokes, coarser ones whole halves."""
FINE_SIGMA = 2.0
"""Blur that separates fine texture (what it removes) from structure (reference pixels): the
scale of grass blades, hair and wrinkles in a 512-pixel picture."""
CLEAN_SIGMA = 10.0
"""Window of the majority vote that removes speckle from a thresholded map (reference pixels):
islands and holes much smaller than this disappear."""
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

TEXTURE_FLOOR = 2e-4
"""Energy (squared luminance) added to the texture share's denominator: about a 1.4 % standard
deviation, above 8-bit and JPEG noise, so that flat areas have a share near 0."""
DETAIL_SHARES = (0.2, 0.55)
"""Smallest and largest share of a picture the fine-texture region covers."""

SALIENCY_BLUR = 3.0
"""Blur before the colour distance of frequency-tuned saliency (reference pixels; Achanta et
al. use a 5x5 binomial kernel on small pictures)."""
SHARPNESS_QUANTILES = (0.05, 0.95)
"""The log fine-texture energy is mapped to [0, 1] between these quantiles of the picture."""
SALIENCY_QUANTILE = 0.95
"""The saliency is divided by this quantile of the picture (robust to a few extreme pixels)."""
SALIENCY_WEIGHT = 0.5
"""Weight of colour saliency in the subject score; the rest is sharpness (focus)."""
CENTRE_WEIGHT = 0.35
"""Mild centre prior: the subject score falls by this share from the centre to the corners."""
SUBJECT_SIGMA = 16.0
"""The subject score is averaged in this window (reference pixels) so that the subject is
found as blobs, not as its edges."""
SUBJECT_SHARES = (0.2, 0.55)
"""Smallest and largest share of a picture the subject covers; the background is the rest."""
ENERGY_EPS = 1e-6
"""Keeps logarithms of energies finite on perfectly flat pictures."""


def luminance(image: torch.Tensor) -> torch.Tensor:
    """CIE L* / 100 of sRGB ``image`` ``(B, 3, H, W)``: ``(B, 1, H, W)`` in [0, 1]."""
    return rgb_to_lab(image)[:, :1] / LAB_L_RANGE


def _quantile(score: torch.Tensor, q: float) -> torch.Tensor:
    """Per picture ``q``-quantile of ``score`` ``(B, 1, H, W)``: ``(B, 1, 1, 1)``."""
    return torch.quantile(score.flatten(1), q, dim=1).view(-1, 1, 1, 1)


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


def smooth_region(binary: torch.Tensor) -> torch.Tensor:
    """A thresholded map ``(B, 1, H, W)`` without speckle and with a feathered border: a majority
    vote in a Gaussian window of :data:`CLEAN_SIGMA`, then a Gaussian of :data:`FEATHER_SIGMA`;
    ``(B, 1, H, W)`` in [0, 1]."""
    majority = (gaussian_blur(binary.float(), CLEAN_SIGMA) > INSIDE).float()
    return gaussian_blur(majority, FEATHER_SIGMA).clamp(0.0, 1.0)


def local_contrast(image: torch.Tensor) -> torch.Tensor:
    """The standard deviation of the luminance in a Gaussian window of :data:`CONTRAST_SIGMA`:
    how strong the edges around each pixel are. ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    return local_deviation(luminance(image), CONTRAST_SIGMA)


def low_contrast_region(image: torch.Tensor) -> torch.Tensor:
    """The ``contours`` rule: where the local contrast (:func:`local_contrast`) is low compared
    with the rest of the picture, i.e. where edges are weak. ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    score = -torch.log(local_contrast(image) + CONTRAST_FLOOR)
    return smooth_region(threshold(score, CONTOUR_SHARES))


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
    with the rest of the picture). ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    return smooth_region(threshold(texture_share(image), DETAIL_SHARES))


def _robust_unit(values: torch.Tensor, low_q: float, high_q: float) -> torch.Tensor:
    """``values`` ``(B, 1, H, W)`` mapped linearly to [0, 1] between two of its quantiles."""
    low, high = _quantile(values, low_q), _quantile(values, high_q)
    return ((values - low) / (high - low).clamp_min(ENERGY_EPS)).clamp(0.0, 1.0)


def colour_saliency(image: torch.Tensor) -> torch.Tensor:
    """Frequency-tuned saliency (Achanta et al. 2009): the CIE Lab distance of the slightly
    blurred picture from the picture's mean colour, divided by its :data:`SALIENCY_QUANTILE`
    quantile and clamped to [0, 1]. ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    lab = rgb_to_lab(gaussian_blur(image, SALIENCY_BLUR))
    distance = (lab - lab.mean(dim=(2, 3), keepdim=True)).norm(dim=1, keepdim=True)
    return (distance / _quantile(distance, SALIENCY_QUANTILE).clamp_min(ENERGY_EPS)).clamp(0.0, 1.0)


def sharpness(image: torch.Tensor) -> torch.Tensor:
    """Focus: the logarithm of the fine-texture energy (:func:`fine_energy`; a defocused
    background has none), mapped to [0, 1] between two quantiles of the picture
    (:data:`SHARPNESS_QUANTILES`). ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    return _robust_unit(torch.log(fine_energy(image) + ENERGY_EPS), *SHARPNESS_QUANTILES)


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
    :data:`SUBJECT_SHARES`). ``(B, 3, H, W)`` -> ``(B, 1, H, W)``."""
    subject = threshold(subject_score(image), SUBJECT_SHARES)
    return smooth_region(~subject)


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
