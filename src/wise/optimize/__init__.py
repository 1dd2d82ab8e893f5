"""Optimizing effect parameters to match a reference (parametric style transfer)."""

from wise.optimize.parametric import Outcome, Settings, optimize

__all__ = ["Outcome", "Settings", "optimize"]
