"""The watercolor's parameters and presets, free of numerical libraries (the pipeline:
:mod:`wise.effects.watercolor`)."""

from __future__ import annotations

from wise.effects.catalogue.colour import WHITE_BALANCE, brightness_spec
from wise.paramspec import ParamSpec

SUMMARY = "Watercolor: flat washes whose pigment pools at the edges, bleeds, wobbles and settles"
"""The first line of the effect's description (``wise effects``)."""

PARAMS = (
    brightness_spec(-0.2, 0.3, 0.05, "lighter (thinner) or darker (thicker) washes"),
    ParamSpec("contrast", 0.5, 2.0, 1.0, "contrast of the input around mid-grey"),
    ParamSpec("saturation", 0.0, 2.0, 1.15, "colour saturation"),
    *WHITE_BALANCE,
    ParamSpec("abstraction", 1.0, 8.0, 4.0, "radius of the Kuwahara washes"),
    ParamSpec("flatness", 0.0, 1.0, 0.5, "flat washes of even tone (1) or smooth shading (0)"),
    ParamSpec("bleeding", 0.0, 8.0, 3.0, "how far colours bleed across wet edges"),
    ParamSpec("wobble", 0.0, 3.0, 1.0, "displacement of the washes by the paper (reference pixels)"),
    ParamSpec("edge_darkening", 0.0, 3.0, 1.0, "pigment pooling at the edges of washes"),
    ParamSpec("turbulence", 0.0, 1.0, 0.3, "uneven, cloudy pigment density"),
    ParamSpec("dispersion", 0.0, 1.0, 0.2, "fine speckles of pigment"),
    ParamSpec("granulation", 0.0, 1.0, 0.4, "pigment settling in the paper grain"),
    ParamSpec("gaps_overlaps", -1.0, 1.0, 0.2, "paper gaps (negative) or overlaps (positive) at edges"),
    ParamSpec("paper", 0.0, 1.0, 0.5, "visibility of the paper's grain"),
    ParamSpec("contour", 0.0, 1.0, 0.25, "opacity of the pencil contours"),
    ParamSpec("accents", 0.0, 1.0, 1.0, "dark features the washes lost (eyes, brows, lips) put back"),
)

PRESETS = {
    "wet": {
        "brightness": 0.08,
        "contrast": 1.0,
        "saturation": 1.25,
        "abstraction": 7.0,
        "flatness": 0.7,
        "bleeding": 6.0,
        "wobble": 0.5,
        "edge_darkening": 1.2,
        "turbulence": 0.2,
        "dispersion": 0.05,
        "granulation": 0.2,
        "gaps_overlaps": 0.3,
        "paper": 0.7,
        "contour": 0.0,
    },
    "dry": {
        "brightness": 0.08,
        "contrast": 1.0,
        "saturation": 1.1,
        "abstraction": 4.0,
        "flatness": 0.9,
        "bleeding": 0.5,
        "wobble": 0.8,
        "edge_darkening": 2.5,
        "turbulence": 0.12,
        "dispersion": 0.2,
        "granulation": 0.35,
        "gaps_overlaps": -0.7,
        "paper": 0.9,
        "contour": 0.15,
    },
    "pale": {
        "brightness": 0.12,
        "contrast": 0.95,
        "saturation": 1.3,
        "abstraction": 8.0,
        "flatness": 1.0,
        "bleeding": 3.0,
        "wobble": 1.0,
        "edge_darkening": 2.5,
        "turbulence": 0.15,
        "dispersion": 0.05,
        "granulation": 0.3,
        "gaps_overlaps": -0.5,
        "paper": 0.8,
        "contour": 0.0,
    },
}
