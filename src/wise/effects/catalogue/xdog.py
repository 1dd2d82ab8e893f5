"""XDoG's parameters and presets, free of numerical libraries (the pipeline:
:mod:`wise.effects.xdog`)."""

from __future__ import annotations

from wise.paramspec import ParamSpec

SUMMARY = "Black-and-white line drawing: flow-aligned abstraction followed by flow-based XDoG."
"""The first line of the effect's description (``wise effects``)."""

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

PARAMS = (
    ParamSpec("brightness", -0.15, 0.5, 0.0, "added to the input colours"),
    ParamSpec("contrast", 0.2, 3.0, 1.15, "contrast of the input around mid-grey"),
    ParamSpec("saturation", 0.0, 3.0, 1.02, "colour saturation of the input"),
    ParamSpec("details", 0.0, 3.0, 2.27, "more detail: less abstraction and finer edges"),
    ParamSpec("stroke_width", 0.3, 1.2, 0.54, "width of the lines (sigma of the DoG)"),
    ParamSpec("contour", 0.0, 3.0, 1.0, "strength of the edge response"),
    ParamSpec("blackness", 0.01, 0.5, 0.15, "threshold below which pixels turn black"),
    ParamSpec("shading", 0.0, 1.0, 0.5, "grey tones of the abstracted image under the lines (0: lines on white)"),
)

PRESETS = {
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
