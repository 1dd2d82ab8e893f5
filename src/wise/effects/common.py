"""Sub-pipelines shared by several effects: the edge flow and XDoG lines."""

from __future__ import annotations

import math
from typing import Mapping

import torch

from wise.filters import (
    edge_tangent_flow,
    flow_dog,
    flow_smoothing,
    smoothed_structure_tensor,
    xdog_threshold,
)
from wise.filters.dog import WIDE_TO_NARROW
from wise.filters.gaussian import SUPPORT

STRUCTURE_SMOOTHING = 1.5
"""Sigma of the Gaussian that smooths the structure tensor (reference pixels)."""
CONTOUR_GAIN = 100.0
"""DoG sharpening p per unit of ``contour``."""
EDGE_SHARPNESS = 1000.0
"""phi of the XDoG soft threshold, in units of normalized luminance."""
LUMINANCE_RANGE = 100.0
"""CIE L* of white; luminance is normalized to [0, 1] before the DoG."""
MAX_STROKE_WIDTH = 1.2
"""Largest ``stroke_width`` (DoG sigma, reference pixels) the effects offer."""
DIAGONAL_STEP = math.sqrt(2.0)
"""Longest distance of one pixel step along a direction field."""


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


def edge_flow(luminance: torch.Tensor, derivative_sigma: torch.Tensor | float, scale: float) -> torch.Tensor:
    """Edge tangent flow ``(B, 2, H, W)`` of a luminance image ``(B, 1, H, W)`` (any units)."""
    structure = smoothed_structure_tensor(luminance, derivative_sigma, STRUCTURE_SMOOTHING, scale)
    return edge_tangent_flow(structure)


def xdog_lines(
    luminance: torch.Tensor,
    tangent: torch.Tensor,
    stroke_width: torch.Tensor,
    contour: torch.Tensor,
    blackness: torch.Tensor,
    edge_smoothing: torch.Tensor,
    kernel_size: int,
    scale: float,
) -> torch.Tensor:
    """Flow-based XDoG (Winnemöller et al. 2012): black lines on white, ``(B, 1, H, W)``.

    ``luminance`` is normalized to [0, 1]; DoG across the flow, line-integral smoothing along
    it (:func:`edge_response`), soft threshold at ``blackness``.
    """
    response = edge_response(luminance, tangent, stroke_width, contour, edge_smoothing, kernel_size, scale)
    return xdog_threshold(response, blackness, EDGE_SHARPNESS)


def edge_response(
    luminance: torch.Tensor,
    tangent: torch.Tensor,
    stroke_width: torch.Tensor | float,
    contour: torch.Tensor | float,
    edge_smoothing: torch.Tensor,
    kernel_size: int,
    scale: float,
) -> torch.Tensor:
    """The XDoG response before its threshold, ``(B, 1, H, W)``: the flow DoG with sharpening
    ``CONTOUR_GAIN * contour``, smoothed along the flow. Both steps are linear in the
    sharpening, so the response is ``u(0) + contour * (u(1) - u(0))``."""
    edges = flow_dog(luminance, tangent, stroke_width, CONTOUR_GAIN * contour, kernel_size + 2, scale)
    return flow_smoothing(edges, tangent, edge_smoothing, scale=scale)


def flow_pipeline_halo(scale: float, kernel_size: int, bilateral_applications: int) -> int:
    """Pixels read around a tile by edge flow -> oriented bilateral (applied
    ``bilateral_applications`` times) -> XDoG lines, at the largest sigmas ``details`` allows."""
    coarsest = detail_sigmas(torch.tensor(0.0))
    structure_reach = float(coarsest["structure"]) + SUPPORT * STRUCTURE_SMOOTHING
    flow_reach = (structure_reach + SUPPORT * float(coarsest["edge_smoothing"])) * scale
    bilateral_steps = bilateral_applications * 2 * 2 * kernel_size
    dog_reach = max(kernel_size + 2, SUPPORT * WIDE_TO_NARROW * MAX_STROKE_WIDTH * scale)
    return math.ceil(flow_reach + DIAGONAL_STEP * (bilateral_steps + dog_reach)) + 2


COLOUR_ADJUSTMENTS = ("brightness", "contrast", "saturation", "gamma", "temperature", "tint")


def colour_adjustments(p: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The colour-adjustment parameters an effect declares, as keywords of ``adjust_color``."""
    return {name: p[name] for name in COLOUR_ADJUSTMENTS if name in p}
