"""One effect parameter's declaration and the normalized space, free of numerical libraries (the
command line checks names and values with them before PyTorch loads; see :mod:`wise.params`)."""

from __future__ import annotations

from dataclasses import dataclass

NORMALIZED_MIN = -0.5
NORMALIZED_MAX = 0.5


@dataclass(frozen=True)
class ParamSpec:
    """One effect parameter in real units."""

    name: str
    min: float
    max: float
    default: float
    description: str = ""
    reach: tuple[float, float] | None = None
    """Where per-pixel masks fitted to a reference may go, in real units (default: ``[min, max]``).
    Wider for the colour offsets, so that as masks they can give a pixel any colour."""

    def __post_init__(self) -> None:
        if not self.max > self.min:
            raise ValueError(f"parameter {self.name!r}: max must exceed min")
        if self.reach is not None and not self.reach[0] <= self.min < self.max <= self.reach[1]:
            raise ValueError(f"parameter {self.name!r}: reach must contain [min, max]")

    @property
    def span(self) -> float:
        return self.max - self.min

    def to_normalized(self, value: float) -> float:
        return (value - self.min) / self.span + NORMALIZED_MIN

    def to_real(self, value: float) -> float:
        return (value - NORMALIZED_MIN) * self.span + self.min

    def in_range(self, value: float, tolerance: float = 1e-9) -> bool:
        return self.min - tolerance <= value <= self.max + tolerance
