"""Differentiable image filters on ``(B, C, H, W)`` tensors.

Parameters may be Python floats, per-batch ``(B,)`` tensors or per-pixel maps
``(B, 1, H, W)``. Spatial sigmas are given in pixels of a 512-pixel short side and scale
with the image (override with ``scale=``), so a pipeline looks the same at every size.
"""

from wise.filters._checks import resolution_scale
from wise.filters.bilateral import bilateral_pass, oriented_bilateral
from wise.filters.color import adjust_color, hsv_to_rgb, lab_to_rgb, rgb_to_hsv, rgb_to_lab
from wise.filters.dog import flow_dog, flow_smoothing, xdog_threshold
from wise.filters.gaussian import gaussian_blur
from wise.filters.sampling import sample, tap_sum
from wise.filters.structure import edge_tangent_flow, gradient_direction, smoothed_structure_tensor, structure_tensor

__all__ = [
    "adjust_color",
    "bilateral_pass",
    "edge_tangent_flow",
    "flow_dog",
    "flow_smoothing",
    "gaussian_blur",
    "gradient_direction",
    "hsv_to_rgb",
    "lab_to_rgb",
    "oriented_bilateral",
    "resolution_scale",
    "rgb_to_hsv",
    "rgb_to_lab",
    "sample",
    "smoothed_structure_tensor",
    "structure_tensor",
    "tap_sum",
    "xdog_threshold",
]
