"""wise: whitebox image stylization by example.

Differentiable stylization effects (XDoG, ...) whose parameters, global or per
pixel, can be painted by hand, optimized to match a reference, or predicted.
"""

from wise._openmp import prefer_passive_waiting

prefer_passive_waiting()  # before anything imports torch

from wise import effects, filters, params  # noqa: E402
from wise.errors import WiseError  # noqa: E402

__version__ = "0.1.0"

__all__ = ["effects", "filters", "params", "WiseError", "__version__"]
