"""XDoG line drawing (Winnemöller et al. 2012) on a flow-abstracted image, as in WISE."""

from __future__ import annotations

from typing import Mapping

import torch

from wise.effects.base import Effect, RenderContext
from wise.effects.common import (
    LUMINANCE_RANGE,
    colour_adjustments,
    detail_sigmas,
    edge_flow,
    flow_pipeline_halo,
    xdog_lines,
)
from wise.filters import adjust_color, oriented_bilateral, rgb_to_lab
from wise.params import ParamSpec

_PORTRAIT = {
    "brightness": 0.1,
    "contrast": 1.15,
    "saturation": 1.02,
    "details": 2.27,
    "stroke_width": 0.54,
    "contour": 1.0,
    "blackness": 0.15,
    "shading": 0.0,
}
"""The reference implementation's portrait preset; ``pencil`` draws the same lines over half tones."""


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
    param_specs = (
        ParamSpec("brightness", -0.15, 0.5, 0.0, "added to the input colours"),
        ParamSpec("contrast", 0.2, 3.0, 1.15, "contrast of the input around mid-grey"),
        ParamSpec("saturation", 0.0, 3.0, 1.02, "colour saturation of the input"),
        ParamSpec("details", 0.0, 3.0, 2.27, "more detail: less abstraction and finer edges"),
        ParamSpec("stroke_width", 0.3, 1.2, 0.54, "width of the lines (sigma of the DoG)"),
        ParamSpec("contour", 0.0, 3.0, 1.0, "strength of the edge response"),
        ParamSpec("blackness", 0.01, 0.5, 0.15, "threshold below which pixels turn black"),
        ParamSpec("shading", 0.0, 1.0, 0.5, "grey tones of the abstracted image under the lines (0: lines on white)"),
    )
    presets = {
        "portrait": _PORTRAIT,
        "pencil": {**_PORTRAIT, "shading": 0.5},
        "sketch": {
            "brightness": 0.14,
            "contrast": 1.0,
            "saturation": 0.0,
            "details": 2.0,
            "stroke_width": 0.4,
            "contour": 2.0,
            "blackness": 0.1,
            "shading": 0.57,
        },
        "lines": {
            "brightness": 0.1,
            "contrast": 0.9,
            "saturation": 1.0,
            "details": 1.8,
            "stroke_width": 0.6,
            "contour": 2.5,
            "blackness": 0.15,
            "shading": 0.0,
        },
    }

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
