"""Stylization effects: pipelines of differentiable filters with declared parameters.

The effect classes load on first use: names, parameters and presets are known without them
(:mod:`wise.effects.catalogue`), which keeps the command line quick.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from wise.effects.catalogue import NAMES, check_name

if TYPE_CHECKING:
    from wise.effects.base import Effect
    from wise.effects.cartoon import Cartoon
    from wise.effects.oilpaint import OilPaint
    from wise.effects.watercolor import Watercolor
    from wise.effects.xdog import XDoG

_CLASSES = {
    "Effect": ("base", "Effect"),
    "Cartoon": ("cartoon", "Cartoon"),
    "OilPaint": ("oilpaint", "OilPaint"),
    "Watercolor": ("watercolor", "Watercolor"),
    "XDoG": ("xdog", "XDoG"),
}
_BY_NAME = {"cartoon": "Cartoon", "oilpaint": "OilPaint", "watercolor": "Watercolor", "xdog": "XDoG"}


def __getattr__(name: str) -> object:
    if name in _CLASSES:
        module, attribute = _CLASSES[name]
        return getattr(importlib.import_module(f"wise.effects.{module}"), attribute)
    raise AttributeError(f"module 'wise.effects' has no attribute {name!r}")


def available() -> list[str]:
    """Names of the registered effects."""
    return sorted(NAMES)


def effect_class(name: str) -> type[Effect]:
    """The class of the effect ``name``."""
    check_name(name)
    module, attribute = _CLASSES[_BY_NAME[name]]
    return getattr(importlib.import_module(f"wise.effects.{module}"), attribute)


def create(name: str, **options: object) -> Effect:
    """Create an effect by name, e.g. ``create("xdog", kernel_size=3)``."""
    return effect_class(name)(**options)


__all__ = ["Cartoon", "Effect", "OilPaint", "Watercolor", "XDoG", "available", "create", "effect_class"]
