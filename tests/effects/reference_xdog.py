"""The presets of the public reference XDoG implementation, in this project's units.

Presets serve users; fidelity to the reference is a property of the pipeline, checked with
these values passed explicitly (``benchmarks/compare_reference.py`` keeps the same values).
The reference's sketch has a ``stroke_width`` below the declared range and fills dark regions
with black, which is why the ``sketch`` preset differs from it.
"""

REFERENCE_PORTRAIT = {
    "brightness": 0.1,
    "contrast": 1.15,
    "saturation": 1.02,
    "details": 2.27,
    "stroke_width": 0.54,
    "contour": 1.0,
    "blackness": 0.15,
    "shading": 0.0,
}
REFERENCE_SKETCH = {
    "brightness": 0.1,
    "contrast": 1.0,
    "saturation": 0.0,
    "details": 1.3,
    "stroke_width": 0.2,
    "contour": 3.0,
    "blackness": 0.5,
    "shading": 0.0,
}
