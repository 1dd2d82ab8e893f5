"""The colour parameters several effects declare alike."""

from __future__ import annotations

from wise.paramspec import ParamSpec

COLOUR_OFFSET_REACH = (-1.0, 1.0)
"""Where masks of the colour offsets (brightness, temperature, tint) fitted to a reference may go:
far enough to take any input colour to any other, so that a reference's colours are reached
rather than approximated by the most saturated colour the declared ranges allow."""
WHITE_BALANCE = (
    ParamSpec(
        "temperature", -0.5, 0.5, 0.0, "white balance: warmer (positive) or cooler colours", reach=COLOUR_OFFSET_REACH
    ),
    ParamSpec("tint", -0.5, 0.5, 0.0, "white balance: magenta (positive) or green tint", reach=COLOUR_OFFSET_REACH),
)
"""The white-balance parameters of the colour effects (:func:`wise.filters.adjust_color`)."""


def brightness_spec(
    low: float, high: float, default: float, description: str = "added to the input colours"
) -> ParamSpec:
    """The colour effects' ``brightness`` over an effect's own slider range, with the colour offsets' reach."""
    return ParamSpec("brightness", low, high, default, description, reach=COLOUR_OFFSET_REACH)
