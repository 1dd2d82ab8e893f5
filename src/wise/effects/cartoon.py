"""Cartoon: flat colour regions with ink outlines (Winnemöller et al. 2006), as in WISE Fig. 3."""

from __future__ import annotations

from typing import Mapping

import torch

from wise.effects.base import Effect, RenderContext
from wise.effects.common import (
    LUMINANCE_RANGE,
    WHITE_BALANCE,
    brightness_spec,
    colour_adjustments,
    detail_sigmas,
    edge_flow,
    flow_pipeline_halo,
    xdog_lines,
)
from wise.filters import adjust_color, lab_to_rgb, oriented_bilateral, rgb_to_lab
from wise.filters.composite import blend
from wise.filters.quantize import quantize
from wise.params import ParamSpec

ABSTRACTION_ITERATIONS = 2
"""Applications of the orientation-aligned bilateral filter (Winnemöller et al. use a few)."""


class Cartoon(Effect):
    """Cartoon: abstracted, luminance-quantized colours with XDoG outlines.

    Pipeline (WISE Fig. 3): colour adjustment (brightness, contrast, saturation, gamma) ->
    CIE Lab -> edge tangent flow -> orientation-aligned bilateral abstraction -> XDoG edges
    and soft luminance quantization (bins, softness) -> multiply the edges over the colours.
    """

    name = "cartoon"
    param_specs = (
        brightness_spec(-0.3, 0.3, 0.0),
        ParamSpec("contrast", 0.5, 2.0, 1.1, "contrast of the input around mid-grey"),
        ParamSpec("saturation", 0.0, 3.0, 1.4, "colour saturation"),
        *WHITE_BALANCE,
        ParamSpec("gamma", 0.5, 2.0, 1.0, "gamma of the input (above 1 brightens mid-tones)"),
        ParamSpec("details", 0.0, 3.0, 1.2, "more detail: less abstraction and finer outlines"),
        ParamSpec("bins", 2.0, 16.0, 8.0, "number of luminance levels"),
        ParamSpec("softness", 0.0, 1.0, 0.3, "width of the ramps between levels, in levels"),
        ParamSpec("stroke_width", 0.3, 1.2, 0.6, "width of the outlines"),
        ParamSpec("contour", 0.0, 3.0, 1.0, "strength of the edge response"),
        ParamSpec("blackness", 0.01, 0.5, 0.2, "threshold below which outlines turn black"),
    )
    presets = {
        "classic": {
            "brightness": 0.05,
            "contrast": 1.1,
            "saturation": 1.4,
            "gamma": 1.0,
            "details": 1.2,
            "bins": 8.0,
            "softness": 0.3,
            "stroke_width": 0.6,
            "contour": 1.0,
            "blackness": 0.2,
        },
        "bold": {
            "brightness": 0.05,
            "contrast": 1.3,
            "saturation": 1.8,
            "gamma": 1.1,
            "details": 0.6,
            "bins": 4.0,
            "softness": 0.1,
            "stroke_width": 0.9,
            "contour": 1.5,
            "blackness": 0.3,
        },
        "pastel": {
            "brightness": 0.15,
            "contrast": 0.9,
            "saturation": 1.1,
            "gamma": 1.2,
            "details": 1.6,
            "bins": 6.0,
            "softness": 0.5,
            "stroke_width": 0.45,
            "contour": 0.6,
            "blackness": 0.1,
        },
    }

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
