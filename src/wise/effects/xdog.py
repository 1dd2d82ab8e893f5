"""XDoG line drawing (Winnemöller et al. 2012) on a flow-abstracted image, as in WISE."""

from __future__ import annotations

from typing import Mapping

import torch

from wise.effects.base import Effect, RenderContext
from wise.effects.catalogue import xdog as declared
from wise.effects.common import (
    LUMINANCE_RANGE,
    colour_adjustments,
    detail_sigmas,
    edge_flow,
    flow_pipeline_halo,
    xdog_lines,
)
from wise.filters import adjust_color, oriented_bilateral, rgb_to_lab


class XDoG(Effect):
    """Black-and-white line drawing: flow-aligned abstraction followed by flow-based XDoG.

    Pipeline: colour adjustment -> CIE Lab -> smoothed structure tensor -> edge tangent
    flow -> orientation-aligned bilateral filter -> DoG across the flow -> line-integral
    smoothing along the flow -> soft threshold -> multiplied over the shading.

    The shading ``1 - s * (1 - L)`` of the abstracted luminance ``L`` adds pencil-like tones:
    with ``s = 0`` (the presets) the drawing is the classic black-on-white XDoG. The default
    is half-toned: the tone also gives optimization a gradient where the thresholded lines are
    flat white.
    """

    name = "xdog"
    param_specs = declared.PARAMS
    presets = declared.PRESETS

    def halo(self, scale: float) -> int:
        return flow_pipeline_halo(scale, self.kernel_size, 1)

    def abstraction(
        self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The abstracted luminance in [0, 1] and the edge tangent flow the lines follow."""
        sigmas = detail_sigmas(p["details"])
        adjusted = self.recomputed(adjust_color, image, **colour_adjustments(p))
        lab = self.recomputed(rgb_to_lab, adjusted)
        tangent = self.stage(edge_flow, lab[:, :1], sigmas["structure"], ctx.scale)
        abstracted = self.stage(
            oriented_bilateral,
            lab,
            tangent,
            sigmas["bilateral_spatial"],
            sigmas["bilateral_range"],
            self.kernel_size,
            ctx.scale,
        )
        return abstracted[:, :1] / LUMINANCE_RANGE, tangent

    def render(self, image: torch.Tensor, p: Mapping[str, torch.Tensor], ctx: RenderContext) -> torch.Tensor:
        luminance, tangent = self.abstraction(image, p, ctx)
        lines = self.stage(
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
        shading = 1.0 - p["shading"] * (1.0 - luminance.clamp(0.0, 1.0))
        return (lines * shading).expand(-1, 3, -1, -1)
