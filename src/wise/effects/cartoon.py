"""Cartoon: flat colour regions with ink outlines (Winnemöller et al. 2006), as in WISE Fig. 3."""

from __future__ import annotations

from typing import Mapping

import torch

from wise.effects.base import Effect, RenderContext
from wise.effects.catalogue import cartoon as declared
from wise.effects.common import (
    LUMINANCE_RANGE,
    colour_adjustments,
    detail_sigmas,
    edge_flow,
    flow_pipeline_halo,
    xdog_lines,
)
from wise.filters import adjust_color, lab_to_rgb, oriented_bilateral, rgb_to_lab
from wise.filters.composite import blend
from wise.filters.quantize import quantize

ABSTRACTION_ITERATIONS = 2
"""Applications of the orientation-aligned bilateral filter (Winnemöller et al. use a few)."""


class Cartoon(Effect):
    """Cartoon: abstracted, luminance-quantized colours with XDoG outlines.

    Pipeline (WISE Fig. 3): colour adjustment (brightness, contrast, saturation, gamma) ->
    CIE Lab -> edge tangent flow -> orientation-aligned bilateral abstraction -> XDoG edges
    and soft luminance quantization (bins, softness) -> multiply the edges over the colours.
    """

    name = "cartoon"
    param_specs = declared.PARAMS
    presets = declared.PRESETS

    def halo(self, scale: float) -> int:
        return flow_pipeline_halo(scale, self.kernel_size, ABSTRACTION_ITERATIONS)

    def abstraction(
        self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The abstracted colours in CIE Lab and the edge tangent flow the outlines follow."""
        sigmas = detail_sigmas(p["details"])
        adjusted = self.recomputed(adjust_color, image, **colour_adjustments(p))
        lab = self.recomputed(rgb_to_lab, adjusted)
        tangent = self.stage(edge_flow, lab[:, :1], sigmas["structure"], ctx.scale)
        abstracted = lab
        for _ in range(ABSTRACTION_ITERATIONS):
            abstracted = self.stage(
                oriented_bilateral,
                abstracted,
                tangent,
                sigmas["bilateral_spatial"],
                sigmas["bilateral_range"],
                self.kernel_size,
                ctx.scale,
            )
        return abstracted, tangent

    def render(self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext) -> torch.Tensor:
        abstracted, tangent = self.abstraction(image, p, ctx)
        luminance = abstracted[:, :1] / LUMINANCE_RANGE
        outlines = self.stage(
            xdog_lines,
            luminance,
            tangent,
            p["stroke_width"],
            p["contour"],
            p["blackness"],
            detail_sigmas(p["details"])["edge_smoothing"],
            self.kernel_size,
            ctx.scale,
        )
        levels = self.stage(quantize, luminance.clamp(0.0, 1.0), p["bins"], p["softness"])
        colours = self.recomputed(lab_to_rgb, torch.cat((levels * LUMINANCE_RANGE, abstracted[:, 1:]), dim=1))
        return blend(colours, outlines.expand_as(colours), "multiply")
