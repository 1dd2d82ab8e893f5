"""wise: whitebox image stylization by example.

Differentiable stylization effects (XDoG, ...) whose parameters, global or per
pixel, can be painted by hand, optimized to match a reference, or predicted.

The subpackages load on first use (``wise.effects``, ``wise.filters``, ``wise.params``), so that
the ``wise`` command answers ``--help`` and refuses bad arguments before PyTorch loads.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from wise._openmp import prefer_passive_waiting
from wise.threads import prefer_usable_cores

prefer_passive_waiting()  # before anything imports torch
prefer_usable_cores()

from wise.errors import WiseError  # noqa: E402

__version__ = "0.1.0"

__all__ = ["effects", "filters", "params", "WiseError", "__version__"]

_LAZY = ("effects", "filters", "params")

if TYPE_CHECKING:
    from wise import effects, filters, params


def __getattr__(name: str) -> object:
    if name in _LAZY:
        return importlib.import_module(f"wise.{name}")
    raise AttributeError(f"module 'wise' has no attribute {name!r}")
