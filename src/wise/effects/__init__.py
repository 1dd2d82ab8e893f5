"""Stylization effects: pipelines of differentiable filters with declared parameters."""

from __future__ import annotations

from wise.effects.base import Effect
from wise.effects.cartoon import Cartoon
from wise.effects.oilpaint import OilPaint
from wise.effects.watercolor import Watercolor
from wise.effects.xdog import XDoG
from wise.errors import WiseError

_REGISTRY: dict[str, type[Effect]] = {cls.name: cls for cls in (Cartoon, OilPaint, Watercolor, XDoG)}


def available() -> list[str]:
    """Names of the registered effects."""
    return sorted(_REGISTRY)


def create(name: str, **options: object) -> Effect:
    """Create an effect by name, e.g. ``create("xdog", kernel_size=3)``."""
    try:
        cls = _REGISTRY[name]
    except KeyError:
        raise WiseError(f"unknown effect {name!r}; available effects: {', '.join(available())}") from None
    return cls(**options)


__all__ = ["Cartoon", "Effect", "OilPaint", "Watercolor", "XDoG", "available", "create"]
