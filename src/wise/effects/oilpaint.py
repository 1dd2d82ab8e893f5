"""Oil paint: flow-aligned brush strokes with relief and lighting (Semmo et al. 2016), as in WISE."""

from __future__ import annotations

import math
from typing import Mapping

import torch

from wise.effects.base import Effect, RenderContext
from wise.effects.catalogue import oilpaint as declared
from wise.effects.common import LUMINANCE_RANGE, colour_adjustments, detail_sigmas
from wise.filters import (
    adjust_color,
    coarse_structure_tensor,
    edge_tangent_flow,
    flow_smoothing,
    gradient_direction,
    lab_to_rgb,
    oriented_bilateral,
    relaxed_structure_tensor,
    rgb_to_lab,
    smoothed_structure_tensor,
)
from wise.filters.gaussian import SUPPORT, gaussian_blur, local_detail
from wise.filters.log import flow_log
from wise.filters.noise import value_noise
from wise.filters.shading import bump_phong, phong_highlight
from wise.filters.upsample import downsample, joint_bilateral_upsample

FLOW_DERIVATIVE = 1.0
"""Derivative scale of the structure tensor (reference pixels)."""
FLOW_SMOOTHING = 4.0
"""Smoothing of the structure tensor: brush strokes follow a smooth flow (reference pixels)."""
RELAX_SIGMA = 24.0
"""Reach of the flow relaxation (reference pixels): flat regions take the direction of the
strong edges within about this distance."""
RELAX_THRESHOLD = 48.0
"""Anisotropy (CIE L* per reference pixel, squared) below which the local flow is mostly
replaced: skin, sky and walls have less, the contours of shapes far more."""
RELAX_GAIN = 8.0
"""Weight of the spread strong structure against the weak local one."""
COARSE_FLOW_BLUR = 8.0
"""Blur before the coarse structure tensor (reference pixels): the shading of a surface
without the noise of its texture."""
WIDE_FLOW_SIGMA = 96.0
"""Scale of the picture's structure that orients the strokes where no strong edge is near
(reference pixels): the form of a face, the lighting of a wall. Wider than a cheek, so the strokes
on skin run along the face instead of circling the brightest spot of the cheek."""
ABSTRACTION_FACTOR = 2
"""The colour abstraction runs at 1/2 resolution and is joint-bilaterally upsampled."""
UPSAMPLING_RANGE = 12.0
"""Range sigma of the joint bilateral upsampling, in CIE Lab units."""
BRISTLE_CELL = 1.2
"""Cell size of the bristle noise before it is smeared into strokes (reference pixels): coarse
enough to be resolved at the reference resolution, so that the texture is the same at every
resolution instead of aliased at 512 px and resolved at 2048 px."""
BRISTLE_GAIN = 6.0
"""Scales the smeared noise to a paint height of roughly unit contrast."""
EDGE_SIGMA = 1.0
"""Sigma of the flow-based Laplacian of Gaussian that enhances edges (reference pixels)."""
MAX_STROKE_STEPS = 20
"""Most line-integral steps per side for the strokes: the longest stroke (two sigma of 12
reference pixels) is sampled every bristle cell, so no stroke breaks into dashes."""
MAX_EDGE_STEPS = 6
"""Most samples per side of the edge-enhancing LoG."""
RELIEF_FLOOR = 0.15
"""Share of the relief left where the paint does not vary (skin, sky): soft, still visible strokes."""
STROKE_FLOOR = 0.5
"""Share of the stroke length left where the paint does not vary: short dabs on skin and sky
rather than long grooves that run across a face like wood grain."""
RELIEF_VARIATION = 0.08
"""Local detail of the paint's lightness (L* / 100, :func:`~wise.filters.gaussian.local_detail`)
at which the relief and the stroke length are halfway to full."""
DETAIL_SIGMA = 2.0
"""Scale of that detail (reference pixels): texture and edges count, the smooth shading of a
cheek does not, so skin gets short, soft strokes."""
VARIATION_SIGMA = 4.0
"""Window over which the detail is averaged (reference pixels)."""
CAVITY_SHADE = 0.2
"""Darkening of the grooves and lightening of the ridges per unit of paint height and relief:
paint catches ambient light by its height, so strokes of every direction show, also those
running towards the light."""
STROKE_BODY_SIGMA = 2.5
"""Smoothing (reference pixels) of the paint height whose relief the highlights follow: about a
bristle groove's width, so a highlight runs along a stroke's body."""
BODY_RELIEF = 2.0
"""How much steeper the stroke bodies' relief is lit than the smoothed height's slope: smoothing
flattens the slopes, and a highlight needs a slope that faces the light."""
LIGHT_DIRECTION = (0.0, -1.0, 1.5)
"""Light from above, in front of the canvas: no side is preferred, so a mirrored picture is lit
as the mirror of the picture."""
FLAT_REFLECTION = LIGHT_DIRECTION[2] / math.hypot(*LIGHT_DIRECTION)
"""``R.V`` of flat paint under :data:`LIGHT_DIRECTION` (the light's height over its length)."""


def _low_resolution(value: torch.Tensor) -> torch.Tensor:
    """A parameter for the half-resolution abstraction: maps are reduced like the image."""
    return value if value.shape[-2:] == (1, 1) else downsample(value, ABSTRACTION_FACTOR)


class OilPaint(Effect):
    """Oil paint: abstracted colours painted with flow-aligned strokes that catch the light.

    Pipeline (WISE supplement, after Semmo et al. 2016, with colour adjustment instead of a
    palette): colour adjustment -> CIE Lab -> smoothed structure tensor and flow ->
    orientation-aligned bilateral abstraction at half resolution -> joint bilateral
    upsampling -> brush texture by flow-based smoothing of noise along and across the
    strokes -> paint height -> bump mapping with Phong lighting, the highlights on the strokes'
    bodies (the height smoothed) -> flow-based LoG edge enhancement.
    """

    name = "oilpaint"
    position_dependent = True
    guide_channels = 3
    tile_pixels = 5_000_000  # about 0.6 KB per pixel of intermediate images: within 4 GB at 4096²
    param_specs = declared.PARAMS
    presets = declared.PRESETS

    def __init__(self, kernel_size: int = 3, checkpoint: bool = False, seed: int = 0) -> None:
        super().__init__(kernel_size, checkpoint)
        self.seed = seed

    def guide_halo(self, scale: float) -> int:
        return math.ceil(self._flow_reach(scale)) + 4

    def halo(self, scale: float) -> int:
        stroke_spec, brush_spec = self.spec("stroke_length"), self.spec("brush_size")
        texture_reach = SUPPORT * (stroke_spec.max + brush_spec.max + STROKE_BODY_SIGMA) * scale
        abstraction_reach = ABSTRACTION_FACTOR * (2 * 2 * 2 * self.kernel_size * math.sqrt(2.0) + 4)
        edge_reach = SUPPORT * 2 * EDGE_SIGMA * scale
        variation_reach = SUPPORT * (DETAIL_SIGMA + VARIATION_SIGMA) * scale
        # the grooves across the strokes read strokes whose length follows the paint's variation there
        groove_reach = SUPPORT * brush_spec.max * scale + abstraction_reach + variation_reach
        return math.ceil(max(texture_reach, groove_reach, edge_reach)) + 4

    @staticmethod
    def _flow_reach(scale: float) -> float:
        """Pixels the relaxed structure tensor reads around a pixel."""
        relaxation_reach = max(FLOW_SMOOTHING + RELAX_SIGMA, COARSE_FLOW_BLUR + WIDE_FLOW_SIGMA)
        return (FLOW_DERIVATIVE + SUPPORT * relaxation_reach) * scale

    def paint_height(
        self, tangent: torch.Tensor, stroke_length: torch.Tensor, brush_size: torch.Tensor, ctx: RenderContext
    ) -> torch.Tensor:
        """The brush texture ``(B, 1, H, W)``: bristle noise smeared along the strokes, then across."""
        medium = ctx.medium_scale
        bristles = value_noise(tangent[:, :1], BRISTLE_CELL, self.seed, origin=ctx.origin, scale=medium) - 0.5
        strokes = self.stage(flow_smoothing, bristles, tangent, stroke_length, MAX_STROKE_STEPS, medium)
        across = gradient_direction(tangent)
        grooves = self.stage(flow_smoothing, strokes, across, brush_size, MAX_STROKE_STEPS, medium)
        return BRISTLE_GAIN * grooves

    def render_guide(self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext) -> torch.Tensor:
        """The relaxed structure tensor, whose flow the strokes follow: it reads far (the picture's
        structure at a coarse scale), so a renderer in tiles makes it once for the whole picture."""
        adjusted = self.recomputed(adjust_color, image, **colour_adjustments(p))
        return self._structure(self.recomputed(rgb_to_lab, adjusted), ctx.scale)

    def _structure(self, lab: torch.Tensor, scale: float) -> torch.Tensor:
        local = self.stage(smoothed_structure_tensor, lab[:, :1], FLOW_DERIVATIVE, FLOW_SMOOTHING, scale)
        coarse = self.stage(coarse_structure_tensor, lab[:, :1], COARSE_FLOW_BLUR, FLOW_DERIVATIVE, scale)
        return self.stage(
            relaxed_structure_tensor,
            local * (scale * scale),
            coarse * (scale * scale),
            RELAX_SIGMA,
            RELAX_THRESHOLD,
            RELAX_GAIN,
            WIDE_FLOW_SIGMA,
            scale,
        )

    def render(self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext) -> torch.Tensor:
        sigmas = detail_sigmas(p["details"])
        scale = ctx.scale

        adjusted = self.recomputed(adjust_color, image, **colour_adjustments(p))
        lab = self.recomputed(rgb_to_lab, adjusted)
        structure = self._structure(lab, scale) if ctx.guide is None else ctx.guide
        tangent = self.stage(edge_tangent_flow, structure)

        low_lab = downsample(lab, ABSTRACTION_FACTOR)
        low_tangent = edge_tangent_flow(downsample(structure, ABSTRACTION_FACTOR))
        low_abstracted = self.stage(
            oriented_bilateral,
            low_lab,
            low_tangent,
            _low_resolution(sigmas["bilateral_spatial"]),
            _low_resolution(sigmas["bilateral_range"]),
            self.kernel_size,
            scale / ABSTRACTION_FACTOR,
        )
        abstracted = self.stage(joint_bilateral_upsample, low_abstracted, lab, 1.0, UPSAMPLING_RANGE)
        colours = self.recomputed(lab_to_rgb, abstracted)

        variation = self.stage(local_detail, abstracted[:, :1] / LUMINANCE_RANGE, DETAIL_SIGMA, VARIATION_SIGMA, scale)
        structured = variation / (variation + RELIEF_VARIATION)  # 0 on even paint, towards 1 where it varies
        stroke_length = p["stroke_length"] * (STROKE_FLOOR + (1.0 - STROKE_FLOOR) * structured)
        height = self.paint_height(tangent, stroke_length, p["brush_size"], ctx)
        relief = p["relief"] * (RELIEF_FLOOR + (1.0 - RELIEF_FLOOR) * structured)
        lit = self.stage(bump_phong, colours, height, relief, LIGHT_DIRECTION, specular=0.0, scale=ctx.medium_scale)
        # the highlights follow the strokes' bodies (the relief without its bristle grooves), so
        # that wet paint shines along a stroke instead of glinting on single bristles; a
        # highlight adds the same to every channel, at most the paint's headroom below white:
        # the hue is kept and no channel clips (bright skin is not washed out)
        bodies = gaussian_blur(height, STROKE_BODY_SIGMA, scale=ctx.medium_scale)
        gloss = phong_highlight(bodies, relief * BODY_RELIEF, LIGHT_DIRECTION, p["shininess"], ctx.medium_scale)
        flat = FLAT_REFLECTION ** p["shininess"]  # what flat paint reflects: it keeps its colour
        gloss = (gloss - flat).clamp_min(0.0) / (1.0 - flat)
        headroom = 1.0 - colours.amax(dim=1, keepdim=True)
        lit = lit + p["specular"] * headroom * gloss
        lit = lit * (1.0 + CAVITY_SHADE * relief * torch.tanh(height))
        edges = self.stage(flow_log, abstracted[:, :1] / LUMINANCE_RANGE, tangent, EDGE_SIGMA, scale, MAX_EDGE_STEPS)
        return (lit - p["edge_enhancement"] * edges).clamp(0.0, 1.0)
