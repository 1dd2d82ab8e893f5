"""Optimizing effect parameters to match a reference (parametric style transfer).

The settings (:mod:`wise.optimize.settings`) load without PyTorch; the optimization on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from wise.optimize.settings import Settings

if TYPE_CHECKING:
    from wise.optimize.parametric import Outcome, optimize


def __getattr__(name: str) -> object:
    if name in ("Outcome", "optimize"):
        return getattr(importlib.import_module("wise.optimize.parametric"), name)
    raise AttributeError(f"module 'wise.optimize' has no attribute {name!r}")


__all__ = ["Outcome", "Settings", "optimize"]
