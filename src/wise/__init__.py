"""wise: whitebox image stylization by example.

Differentiable stylization effects (XDoG, ...) whose parameters, global or per
pixel, can be painted by hand, optimized to match a reference, or predicted.
"""

from wise import effects, filters, params
from wise.errors import WiseError

__version__ = "0.1.0"

__all__ = ["effects", "filters", "params", "WiseError", "__version__"]
