"""Every effect's declared parameters and presets, free of numerical libraries.

The pipelines (:mod:`wise.effects`) need PyTorch; the declarations do not, so the command line
lists the effects and checks effect, preset and parameter names and values against them before
PyTorch loads. Each effect class takes its ``param_specs`` and ``presets`` from its module here.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Mapping

from wise.errors import WiseError
from wise.paramspec import ParamSpec

NAMES = ("cartoon", "oilpaint", "watercolor", "xdog")
"""The registered effects, in the order they are listed."""

NO_EFFECT = "none"
"""The effect name of a model that is a CNN alone (image-to-image, no effect)."""


@dataclass(frozen=True)
class Entry:
    """One effect's declarations: its name, the first line of its description, its parameters
    (real units) and its presets."""

    name: str
    summary: str
    param_specs: tuple[ParamSpec, ...]
    presets: Mapping[str, Mapping[str, float]]

    @property
    def param_names(self) -> list[str]:
        return [s.name for s in self.param_specs]

    def spec(self, name: str) -> ParamSpec:
        """The parameter ``name``; an error naming the effect's parameters when it has none such."""
        for s in self.param_specs:
            if s.name == name:
                return s
        raise WiseError(
            f"effect {self.name!r} has no parameter {name!r}; its parameters: {', '.join(self.param_names)}"
        )

    def check_preset(self, name: str) -> None:
        """An error naming the effect's presets when it has no preset ``name``."""
        if name not in self.presets:
            known = ", ".join(self.presets) or "none"
            raise WiseError(f"effect {self.name!r} has no preset {name!r}; its presets: {known}")


def check_name(name: str) -> None:
    """An error naming the available effects when ``name`` is not one."""
    if name not in NAMES:
        raise WiseError(f"unknown effect {name!r}; available effects: {', '.join(NAMES)}")


def entry(name: str) -> Entry:
    """The declarations of the effect ``name``."""
    check_name(name)
    module = importlib.import_module(f"wise.effects.catalogue.{name}")
    return Entry(name, module.SUMMARY, module.PARAMS, module.PRESETS)
