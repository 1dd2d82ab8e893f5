"""What a look is made of, free of numerical libraries: the command line builds and checks it
before PyTorch loads; :class:`wise.batch.look.Look` loads it."""

from __future__ import annotations

from dataclasses import dataclass

from wise.errors import WiseError

Settings = tuple[tuple[str, float], ...]


@dataclass(frozen=True)
class LookSpec:
    """What to render: an effect name and where its parameters come from (see :mod:`wise.batch.look`)."""

    effect: str
    preset: str | None = None
    params: str | None = None
    settings: Settings = ()
    model: str | None = None
    kernel_size: int | None = None
    device: str = "cpu"

    def __post_init__(self) -> None:
        if self.params and self.preset:
            raise WiseError("--params and --preset cannot be combined; edit the file's values with --set instead")
