"""Differentiable image filters on ``(B, C, H, W)`` tensors.

Parameters may be Python floats, per-batch ``(B,)`` tensors or per-pixel maps
``(B, 1, H, W)``. Spatial sizes are given in pixels of a 512-pixel short side and scale
with the image (override with ``scale=``), so a pipeline looks the same at every size.
Every filtering operation of the WISE paper's Table 1 is here.
"""

from wise.filters._checks import resolution_scale
from wise.filters.bilateral import bilateral, bilateral_pass, oriented_bilateral
from wise.filters.color import adjust_color, hsv_to_rgb, lab_to_rgb, rgb_to_hsv, rgb_to_lab
from wise.filters.composite import blend, composite
from wise.filters.dog import flow_dog, flow_smoothing, xdog_threshold
from wise.filters.gaussian import gaussian_blur
from wise.filters.kuwahara import anisotropic_kuwahara
from wise.filters.log import flow_log
from wise.filters.noise import paper_texture, value_noise
from wise.filters.quantize import quantize
from wise.filters.sampling import sample, tap_sum
from wise.filters.shading import bump_phong
from wise.filters.structure import (
    coarse_structure_tensor,
    edge_tangent_flow,
    gradient_direction,
    relaxed_structure_tensor,
    smoothed_structure_tensor,
    structure_tensor,
)
from wise.filters.upsample import downsample, joint_bilateral_upsample
from wise.filters.watercolor import edge_darkening, gaps_overlaps, pigment_density, wet_in_wet, wobble

__all__ = [
    "adjust_color",
    "anisotropic_kuwahara",
    "bilateral",
    "bilateral_pass",
    "blend",
    "bump_phong",
    "composite",
    "downsample",
    "edge_darkening",
    "edge_tangent_flow",
    "flow_dog",
    "flow_log",
    "flow_smoothing",
    "gaps_overlaps",
    "gaussian_blur",
    "gradient_direction",
    "hsv_to_rgb",
    "joint_bilateral_upsample",
    "lab_to_rgb",
    "oriented_bilateral",
    "paper_texture",
    "pigment_density",
    "quantize",
    "resolution_scale",
    "rgb_to_hsv",
    "rgb_to_lab",
    "sample",
    "coarse_structure_tensor",
    "relaxed_structure_tensor",
    "smoothed_structure_tensor",
    "structure_tensor",
    "tap_sum",
    "value_noise",
    "wet_in_wet",
    "wobble",
    "xdog_threshold",
]
