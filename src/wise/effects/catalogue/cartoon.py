"""The cartoon's parameters and presets, free of numerical libraries (the pipeline:
:mod:`wise.effects.cartoon`)."""

from __future__ import annotations

from wise.effects.catalogue.colour import WHITE_BALANCE, brightness_spec
from wise.paramspec import ParamSpec

SUMMARY = "Cartoon: abstracted, luminance-quantized colours with XDoG outlines."
"""The first line of the effect's description (``wise effects``)."""

PARAMS = (
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

PRESETS = {
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
