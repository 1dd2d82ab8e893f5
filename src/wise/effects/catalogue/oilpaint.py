"""The oil paint's parameters and presets, free of numerical libraries (the pipeline:
:mod:`wise.effects.oilpaint`)."""

from __future__ import annotations

from wise.effects.catalogue.colour import WHITE_BALANCE, brightness_spec
from wise.paramspec import ParamSpec

SUMMARY = "Oil paint: abstracted colours painted with flow-aligned strokes that catch the light."
"""The first line of the effect's description (``wise effects``)."""

PARAMS = (
    brightness_spec(-0.2, 0.3, 0.0),
    ParamSpec("contrast", 0.5, 2.0, 1.1, "contrast of the input around mid-grey"),
    ParamSpec("saturation", 0.0, 2.5, 1.2, "colour saturation"),
    *WHITE_BALANCE,
    ParamSpec("details", 0.0, 3.0, 1.5, "more detail: less colour abstraction"),
    ParamSpec("stroke_length", 1.0, 12.0, 5.0, "length of the brush strokes along the flow"),
    ParamSpec("brush_size", 0.3, 3.0, 0.8, "width of the bristle grooves across the strokes"),
    ParamSpec("relief", 0.0, 3.0, 1.0, "height of the paint relief"),
    ParamSpec("specular", 0.0, 1.0, 0.3, "strength of the highlights"),
    ParamSpec("shininess", 2.0, 40.0, 12.0, "tightness of the highlights"),
    ParamSpec("edge_enhancement", 0.0, 2.0, 0.5, "darkening and sharpening of edges"),
)

PRESETS = {
    "impasto": {
        "brightness": 0.02,
        "contrast": 1.1,
        "saturation": 1.3,
        "details": 1.2,
        "stroke_length": 6.0,
        "brush_size": 0.8,
        "relief": 1.8,
        "specular": 0.35,
        "shininess": 14.0,
        "edge_enhancement": 0.6,
    },
    "glaze": {
        "brightness": 0.02,
        "contrast": 1.0,
        "saturation": 1.1,
        "details": 2.0,
        "stroke_length": 3.0,
        "brush_size": 0.5,
        "relief": 0.5,
        "specular": 0.15,
        "shininess": 25.0,
        "edge_enhancement": 0.3,
    },
    "knife": {
        "brightness": 0.03,
        "contrast": 1.15,
        "saturation": 1.25,
        "details": 0.6,
        "stroke_length": 10.0,
        "brush_size": 2.0,
        "relief": 1.0,
        "specular": 0.45,
        "shininess": 8.0,
        "edge_enhancement": 0.4,
    },
}
