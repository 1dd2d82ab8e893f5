"""Watercolor: abstracted washes with wet-in-wet, wobbling, edge darkening and paper
(Bousseau et al. 2006; Wang et al. 2014), as in WISE."""

from __future__ import annotations

import math
from typing import Mapping

import torch

from wise.effects.base import Effect, RenderContext
from wise.effects.catalogue import watercolor as declared
from wise.effects.common import (
    LUMINANCE_RANGE,
    colour_adjustments,
    detail_sigmas,
    xdog_lines,
)
from wise.filters import (
    adjust_color,
    edge_tangent_flow,
    gradient_direction,
    rgb_to_lab,
    smoothed_structure_tensor,
)
from wise.filters.composite import blend
from wise.filters.gaussian import SUPPORT, gaussian_blur
from wise.filters.kuwahara import anisotropic_kuwahara
from wise.filters.noise import paper_texture, value_noise
from wise.filters.upsample import downsample, joint_bilateral_upsample
from wise.filters.watercolor import (
    edge_darkening,
    feature_accents,
    flat_washes,
    gaps_overlaps,
    paper_shading,
    pigment_density,
    wash_lightness,
    wet_in_wet,
    wobble,
)

FLOW_DERIVATIVE = 1.0
"""Derivative scale of the structure tensor (reference pixels)."""
FLOW_SMOOTHING = 2.0
"""Smoothing of the structure tensor (reference pixels)."""
EDGE_CONTRAST = 12.0
"""Luminance change per reference pixel (CIE L*) at which an edge counts as fully strong."""
TURBULENCE_CELL = 40.0
"""Cell size of the low-frequency pigment turbulence (reference pixels)."""
DISPERSION_CELL = 2.5
"""Cell size of the high-frequency pigment dispersion (reference pixels)."""
TURBULENCE_GAIN = 0.6
DISPERSION_GAIN = 0.35
GRANULATION_GAIN = 0.5
"""Pigment-density change at full turbulence, dispersion and granulation."""
CONTOUR_DETAILS = 2.0
"""Detail level of the pencil contours (as ``details`` of the XDoG effect)."""
CONTOUR_STROKE = 0.5
CONTOUR_STRENGTH = 1.0
CONTOUR_THRESHOLD = 0.25
ACCENT_SURROUNDINGS = 5.0
"""Size of a feature's surroundings for the accents (reference pixels): an eye, a nostril."""
RIM_THRESHOLD = 0.03
"""Colour difference to the blurred washes below which no dark rim forms: small, faint
features (pores, nostrils, soft shading) stay without one, boundaries between washes get it."""
TREMOR_CELL = 10.0
"""Cell size of the hand tremor that wobbles the wash boundaries (reference pixels)."""
TREMOR_AMPLITUDE = 2.0
"""Height of the tremor added to the paper for the wobbling: about 1.5 reference pixels of
displacement at ``wobble`` 1."""
WOBBLE_PAPER_SMOOTHING = 1.0
"""Smoothing of the paper before its slope displaces the washes (reference pixels of the medium)."""
WOBBLE_GAIN = 8.0
"""The paper's slope is about 1/8 per reference pixel: one unit of ``wobble`` then shifts the
washes by about one reference pixel."""
KUWAHARA_SAMPLES_PER_SECTOR = 2
"""Samples per Kuwahara sector: 17 in all; the washes need no more and it keeps 4096² renders fast."""
KUWAHARA_MAX_STRETCH = 2.0
WASH_REDUCTION = 2
WASH_REDUCTION_FROM_SCALE = 4.0
"""From a 2048-pixel short side on, the washes (Kuwahara and wet-in-wet, smooth by nature) are
computed at half resolution and joint-bilaterally upsampled: a quarter of their cost."""
WASH_UPSAMPLING_RANGE = 0.1
"""Range sigma of that upsampling, on the adjusted RGB colours."""
"""Longest semi-axis of the anisotropic Kuwahara ellipse per unit of radius."""


def edge_strength(structure: torch.Tensor, scale: float) -> torch.Tensor:
    """Edges in [0, 1] from a luminance structure tensor: the gradient magnitude per reference pixel."""
    magnitude = torch.sqrt(structure[:, 0:1] + structure[:, 2:3] + 1e-12) * scale
    return torch.tanh(magnitude / EDGE_CONTRAST)


class Watercolor(Effect):
    """Watercolor: flat washes whose pigment pools at the edges, bleeds, wobbles and settles
    into the paper.

    Pipeline: colour adjustment -> wash lightness -> structure tensor and flow -> anisotropic Kuwahara
    abstraction -> wet-in-wet bleeding across edges -> flat washes (soft tone quantization)
    -> wobbling by the paper texture and hand tremor -> edge darkening -> pigment
    turbulence, dispersion and paper granulation (pigment density) -> gaps and overlaps at
    edges -> paper shading -> pencil contours (flow-based XDoG) multiplied on top.
    """

    name = "watercolor"
    tile_pixels = 6_000_000  # its washes and textures keep many images per pixel: within 4 GB at 4096²
    position_dependent = True
    # bleeding: a symmetric blur's reach has a zero gradient at zero reach; abstraction, flatness
    # and edge darkening: structures at a few reference pixels, lost on the coarse levels' copies
    searched_params = ("abstraction", "flatness", "bleeding", "edge_darkening")
    param_specs = declared.PARAMS
    added_params = ("accents",)
    presets = declared.PRESETS

    def __init__(self, kernel_size: int = 3, checkpoint: bool = False, seed: int = 0) -> None:
        super().__init__(kernel_size, checkpoint)
        self.seed = seed

    def halo(self, scale: float) -> int:
        flow_reach = FLOW_DERIVATIVE + SUPPORT * FLOW_SMOOTHING
        abstraction_reach = KUWAHARA_MAX_STRETCH * self.spec("abstraction").max
        bleeding_reach = 1.5 * self.spec("bleeding").max
        texture_reach = WOBBLE_GAIN * self.spec("wobble").max / 4.0 + 4.0 + SUPPORT * WOBBLE_PAPER_SMOOTHING
        contour_reach = SUPPORT * float(detail_sigmas(torch.tensor(CONTOUR_DETAILS))["edge_smoothing"])
        accent_reach = SUPPORT * ACCENT_SURROUNDINGS  # the accents read the finished washes around a pixel
        reach = flow_reach + max(abstraction_reach + bleeding_reach + texture_reach + accent_reach, contour_reach)
        return math.ceil(reach * scale + math.sqrt(2.0) * 2 * (self.kernel_size + 2)) + 4

    def _washes(
        self,
        colours: torch.Tensor,
        structure: torch.Tensor,
        edges: torch.Tensor,
        noise: torch.Tensor,
        p: Mapping[str, torch.Tensor],
        scale: float,
        reduction: int,
    ) -> torch.Tensor:
        """Kuwahara washes with wet-in-wet bleeding; at ``reduction`` > 1 computed at that
        fraction of the resolution and joint-bilaterally upsampled, guided by ``colours``."""

        def reduce(value: torch.Tensor) -> torch.Tensor:
            return value if reduction == 1 or value.shape[-2:] == (1, 1) else downsample(value, reduction)

        low_structure = reduce(structure)
        across = gradient_direction(edge_tangent_flow(low_structure))
        washes = self.stage(
            anisotropic_kuwahara,
            reduce(colours),
            low_structure,
            reduce(p["abstraction"]),
            scale=scale / reduction,
            samples_per_sector=KUWAHARA_SAMPLES_PER_SECTOR,
        )
        bled = self.stage(
            wet_in_wet, washes, across, reduce(edges), reduce(p["bleeding"]), reduce(noise), scale / reduction
        )
        if reduction == 1:
            return bled
        return self.stage(joint_bilateral_upsample, bled, colours, 1.0, WASH_UPSAMPLING_RANGE)

    def render(self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext) -> torch.Tensor:
        scale, origin, seed = ctx.scale, ctx.origin, self.seed

        # the brightness thins or thickens the washes instead of adding to the photo's colours
        balanced = self.recomputed(adjust_color, image, **{**colour_adjustments(p), "brightness": 0.0})
        adjusted = self.recomputed(wash_lightness, balanced, p["brightness"])
        luminance = self.recomputed(rgb_to_lab, adjusted)[:, :1]
        structure = self.stage(smoothed_structure_tensor, luminance, FLOW_DERIVATIVE, FLOW_SMOOTHING, scale)
        tangent = edge_tangent_flow(structure)
        across = gradient_direction(tangent)
        edges = edge_strength(structure, scale)

        # the paper's grain and the pigment's speckles at the medium's scale, the rest at the picture's
        paper = paper_texture(luminance, seed, origin=origin, scale=ctx.medium_scale)
        turbulence_noise = value_noise(luminance, TURBULENCE_CELL, seed + 1, octaves=3, origin=origin, scale=scale)
        dispersion_noise = value_noise(
            luminance, DISPERSION_CELL, seed + 2, octaves=2, origin=origin, scale=ctx.medium_scale
        )
        tremor = value_noise(luminance, TREMOR_CELL, seed + 3, octaves=2, origin=origin, scale=scale)

        reduction = WASH_REDUCTION if scale >= WASH_REDUCTION_FROM_SCALE else 1
        bled = self._washes(adjusted, structure, edges, turbulence_noise, p, scale, reduction)
        flat = self.stage(flat_washes, bled, luminance / LUMINANCE_RANGE, p["flatness"], scale=scale)
        # the washes waver along the paper's bumps and fibres; its finest tooth would break their
        # boundaries into specks that the rims then darken
        paper_bumps = gaussian_blur(paper, WOBBLE_PAPER_SMOOTHING, scale=ctx.medium_scale)
        trembling_paper = paper_bumps + TREMOR_AMPLITUDE * tremor
        # one displacement for both: the washes before flattening guide the rims
        wobbled, wobbled_washes = self.stage(
            wobble, torch.cat((flat, bled), dim=1), trembling_paper, WOBBLE_GAIN * p["wobble"], scale
        ).chunk(2, dim=1)
        darkened = self.stage(
            edge_darkening, wobbled, p["edge_darkening"], scale=scale, guide=wobbled_washes, threshold=RIM_THRESHOLD
        )
        density = (
            1.0
            + TURBULENCE_GAIN * p["turbulence"] * (2.0 * turbulence_noise - 1.0)
            + DISPERSION_GAIN * p["dispersion"] * (2.0 * dispersion_noise - 1.0)
            + GRANULATION_GAIN * p["granulation"] * (2.0 * paper - 1.0)
        )
        pigmented = self.recomputed(pigment_density, darkened, density)
        overlapped = self.stage(gaps_overlaps, pigmented, edges, across, p["gaps_overlaps"], dispersion_noise, scale)
        shaded = self.recomputed(paper_shading, overlapped, paper, p["paper"])
        finished = self.stage(feature_accents, shaded, image, p["accents"], ACCENT_SURROUNDINGS, scale=scale)

        if not torch.is_grad_enabled() and float(p["contour"].max()) <= 0.0:
            return finished.clamp(0.0, 1.0)  # invisible contours: skip their cost when rendering
        contour_sigmas = detail_sigmas(torch.tensor(CONTOUR_DETAILS))
        pencil = self.stage(
            xdog_lines,
            luminance / LUMINANCE_RANGE,
            tangent,
            CONTOUR_STROKE,
            CONTOUR_STRENGTH,
            CONTOUR_THRESHOLD,
            float(contour_sigmas["edge_smoothing"]),
            self.kernel_size,
            scale,
        )
        return blend(finished, pencil.expand_as(finished), "multiply", p["contour"]).clamp(0.0, 1.0)
