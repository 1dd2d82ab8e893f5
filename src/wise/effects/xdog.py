"""XDoG line drawing (Winnemöller et al. 2012) on a flow-abstracted image, as in WISE."""

from __future__ import annotations

from typing import Mapping

import torch

from wise.effects.base import Effect
from wise.filters import (
    adjust_color,
    edge_tangent_flow,
    flow_dog,
    flow_smoothing,
    oriented_bilateral,
    resolution_scale,
    rgb_to_lab,
    smoothed_structure_tensor,
    xdog_threshold,
)
from wise.params import ParamSpec

STRUCTURE_SMOOTHING = 1.5
"""Sigma of the Gaussian that smooths the structure tensor (reference pixels)."""
CONTOUR_GAIN = 100.0
"""DoG sharpening p per unit of ``contour``."""
EDGE_SHARPNESS = 1000.0
"""phi of the soft threshold, in units of normalized luminance."""
LUMINANCE_RANGE = 100.0
"""CIE L* of white; luminance is normalized to [0, 1] before the DoG."""


def detail_sigmas(details: torch.Tensor) -> dict[str, torch.Tensor]:
    """The internal sigmas controlled by ``details`` (in [0, 3]; more detail, less smoothing).

    Follows the mapping of the public WISE reference implementation: the structure
    tensor's derivative scale, the bilateral filter's spatial and range sigmas, and the
    line-integral smoothing of the edges all shrink linearly as detail grows.
    """
    coarseness = 3.0 - details
    return {
        "structure": 0.75 * (1.0 - details / 3.0) + 0.25,
        "bilateral_spatial": 2.5 * coarseness,
        "bilateral_range": (15.0 / 7.0) * coarseness,
        "edge_smoothing": 1.2 * coarseness + 1.42,
    }


class XDoG(Effect):
    """Black-and-white line drawing: flow-aligned abstraction followed by flow-based XDoG.

    Pipeline: colour adjustment -> CIE Lab -> smoothed structure tensor -> edge tangent
    flow -> orientation-aligned bilateral filter -> DoG across the flow -> line-integral
    smoothing along the flow -> soft threshold.
    """

    name = "xdog"
    param_specs = (
        ParamSpec("brightness", -0.15, 0.5, 0.1, "added to the input colours"),
        ParamSpec("contrast", 0.2, 3.0, 1.15, "contrast of the input around mid-grey"),
        ParamSpec("saturation", 0.0, 3.0, 1.02, "colour saturation of the input"),
        ParamSpec("details", 0.0, 3.0, 2.27, "more detail: less abstraction and finer edges"),
        ParamSpec("stroke_width", 0.3, 1.2, 0.54, "width of the lines (sigma of the DoG)"),
        ParamSpec("contour", 0.0, 3.0, 1.0, "strength of the edge response"),
        ParamSpec("blackness", 0.01, 0.5, 0.15, "threshold below which pixels turn black"),
    )
    presets = {
        "portrait": {
            "brightness": 0.1,
            "contrast": 1.15,
            "saturation": 1.02,
            "details": 2.27,
            "stroke_width": 0.54,
            "contour": 1.0,
            "blackness": 0.15,
        },
        "sketch": {
            "brightness": 0.1,
            "contrast": 1.0,
            "saturation": 0.0,
            "details": 1.3,
            "stroke_width": 0.2,
            "contour": 3.0,
            "blackness": 0.5,
        },
    }

    def render(self, image: torch.Tensor, p: Mapping[str, torch.Tensor]) -> torch.Tensor:
        scale = resolution_scale(image)
        sigmas = detail_sigmas(p["details"])
        samples = self.kernel_size

        adjusted = self.recomputed(
            adjust_color, image, brightness=p["brightness"], contrast=p["contrast"], saturation=p["saturation"]
        )
        lab = self.recomputed(rgb_to_lab, adjusted)
        structure = self.stage(
            smoothed_structure_tensor, lab[:, :1], sigmas["structure"], STRUCTURE_SMOOTHING, scale
        )
        tangent = self.stage(edge_tangent_flow, structure)
        abstracted = self.stage(
            oriented_bilateral,
            lab,
            tangent,
            sigmas["bilateral_spatial"],
            sigmas["bilateral_range"],
            samples,
            scale,
        )
        luminance = abstracted[:, :1] / LUMINANCE_RANGE
        edges = self.stage(
            flow_dog, luminance, tangent, p["stroke_width"], CONTOUR_GAIN * p["contour"], 2 * (samples + 2), scale
        )
        smoothed_edges = self.stage(flow_smoothing, edges, tangent, sigmas["edge_smoothing"], scale=scale)
        lines = xdog_threshold(smoothed_edges, p["blackness"], EDGE_SHARPNESS)
        return lines.expand(-1, 3, -1, -1)
