"""What a training run is made of, checked before any work (no Lightning here, so that bad
input is refused quickly): the settings, the run folder and the photos."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import torch

from wise import effects, ppn
from wise.errors import WiseError, WiseWarning
from wise.train.choices import LOSSES, SAMPLINGS
from wise.train.data import SCALE_RANGE, checked_photos, photo_files, read_photos, split_files

CHECKPOINT = Path("checkpoints") / "last.ckpt"
SETTINGS_FILE = "settings.json"
MODEL_FILE = "model.safetensors"
REPORT_FILE = "report.html"
LOGS = "logs"
"""Lightning's CSV logs, one numbered part per start of the run (``logs/<n>/metrics.csv``)."""
VALIDATION_SHARE = 0.15
"""Share of the photos held out for validation when no ``--val-images`` are given."""
VALIDATION_EXAMPLES = 64
PATH_SETTINGS = ("images", "val_images", "backbone_weights", "cache")
RESUMABLE = (
    "effect", "architecture", "loss", "size", "render_size", "window", "batch", "examples", "sampling", "seed",
    "fresh", "procedural", "augmentation",
)  # fmt: skip
"""Settings a resumed run must share with the run it continues."""


@dataclass
class TrainSettings:
    """Everything a training run is made of (``settings.json`` and the model's metadata)."""

    effect: str
    images: str
    architecture: str = "simple"
    loss: str = "image-l1"
    param_weight: float = 0.0
    """Weight of the parameter L1 added to an image-space loss."""
    size: int = 512
    render_size: int = 512
    window: int | None = None
    """Side of the training windows in network pixels (``size`` when None)."""
    batch: int = 16
    steps: int | None = None
    epochs: int | None = None
    examples: int = 2000
    lr: float = 1e-3
    sampling: str = "uniform"
    fresh: bool = False
    """New examples every epoch instead of one fixed set of ``examples``."""
    procedural: float = 0.0
    """Share of the training examples on dead-leaves pictures instead of photos."""
    augmentation: bool = False
    anneal: float = 0.0
    """Step temperature of the first training step, lowered to 0 by the middle of the run."""
    soft_gradients: float = 0.0
    """Surrogate-gradient softness of the effect's steps (:func:`wise.filters.smoothing.softened_gradients`)."""
    workers: int = 0
    """Processes that render the examples of a fresh stream while the steps run."""
    lr_schedule: str = "constant"
    """``cosine``: the learning rate falls along a half cosine to 5 % of ``lr`` at the last step."""
    val_images: str | None = None
    accelerator: str = "auto"
    devices: int = 1
    num_nodes: int = 1
    seed: int = 0
    half: bool = False
    checkpoint_every: int = 200
    backbone_weights: str | None = None
    cache: str | None = None
    """A folder for the rendered examples, reused by later runs with the same settings and photos."""

    def shareable(self) -> dict:
        """The settings for a model's metadata: folders and files by their names only, so a
        model that is passed on does not carry the paths of the machine it was trained on."""
        values = dataclasses.asdict(self)
        for key in PATH_SETTINGS:
            if values[key] is not None:
                values[key] = Path(values[key]).name
        return values

    def check(self) -> None:
        effects.create(self.effect)
        if self.architecture not in ppn.ARCHITECTURES:
            raise WiseError(f"unknown architecture {self.architecture!r}; use one of {', '.join(ppn.ARCHITECTURES)}")
        if self.loss not in LOSSES:
            raise WiseError(f"unknown loss {self.loss!r}; use one of {', '.join(LOSSES)}")
        if self.sampling not in SAMPLINGS:
            raise WiseError(f"unknown sampling {self.sampling!r}; use one of {', '.join(SAMPLINGS)}")
        if not 0.0 <= self.procedural <= 1.0:
            raise WiseError(f"the procedural share must be in [0, 1], got {self.procedural}")
        if not 0.0 <= self.param_weight < float("inf"):
            raise WiseError(f"--param-weight {self.param_weight} must be a finite number from 0 up")
        if self.param_weight and not self.loss.startswith("image"):
            raise WiseError(f"--param-weight adds to an image-space loss; --loss {self.loss} is one already")
        for name in ("anneal", "soft_gradients"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise WiseError(f"--{name.replace('_', '-')} {getattr(self, name)} must be from 0 to 1")
        if self.lr_schedule not in ("constant", "cosine"):
            raise WiseError(f"unknown learning-rate schedule {self.lr_schedule!r}; use constant or cosine")
        if self.workers and not self.fresh:
            raise WiseError("--workers renders a fresh stream; a --fixed set is rendered in the training process")
        if self.cache is not None and self.fresh:
            raise WiseError("a cache keeps a fixed set of examples; a fresh stream has nothing to keep")
        if self.window is not None and not 8 <= self.window <= self.size:
            raise WiseError(f"--window {self.window} must be from 8 to --size ({self.size})")
        if self.render_size < self.size:
            raise WiseError(f"--render-size {self.render_size} is below --size {self.size}; render at least as large")
        if self.examples < self.batch * self.devices * self.num_nodes:
            raise WiseError(
                f"--examples {self.examples} is fewer than one global batch "
                f"({self.batch} x {self.devices * self.num_nodes} processes)"
            )


def is_launched_rank() -> bool:
    """Whether this process is a further rank started by the DDP launcher (not the user's)."""
    return os.environ.get("LOCAL_RANK", "0") != "0" or os.environ.get("NODE_RANK", "0") != "0"


def check_run_folder(folder: Path, resume: bool) -> None:
    """A new run needs a folder without a run in it; ``--resume`` needs one."""
    has_run = (folder / SETTINGS_FILE).exists() or (folder / CHECKPOINT).exists()
    if resume and not (folder / CHECKPOINT).is_file():
        raise WiseError(f"{folder}: no checkpoint to resume ({CHECKPOINT} is missing); start a run without --resume")
    if not resume and has_run and not is_launched_rank():
        raise WiseError(f"{folder}: holds a training run; pass --resume to continue it, or choose another folder")


def check_resumed(folder: Path, settings: object, keys: tuple[str, ...] = RESUMABLE) -> None:
    """Refuse to resume the run in ``folder`` with other ``keys`` of the settings (a dataclass)."""
    try:
        before = json.loads((folder / SETTINGS_FILE).read_text())
    except (OSError, ValueError):
        raise WiseError(f"{folder}: {SETTINGS_FILE} is missing or unreadable; cannot resume this run") from None
    now = dataclasses.asdict(settings)  # type: ignore[call-overload]
    changed = [key for key in keys if before.get(key) != now.get(key)]
    if changed:
        listed = ", ".join(f"{key} {before.get(key)!r} -> {now.get(key)!r}" for key in changed)
        raise WiseError(f"{folder}: --resume with other settings than the run ({listed}); repeat its settings")


def load_photos(settings: TrainSettings) -> tuple[list[torch.Tensor], list[torch.Tensor], list[str]]:
    """Training and validation photos (disjoint: other files, or a share of the readable
    training photos held out), and notes on skipped files."""
    files = photo_files(settings.images)
    largest = math.ceil(settings.render_size / SCALE_RANGE[0])
    if settings.val_images is None:
        photos, note = checked_photos(settings.images, files, settings.size, largest)
        order = list(range(len(photos)))
        kept, held_out = split_files(order, VALIDATION_SHARE, settings.seed)  # type: ignore[arg-type]
        return [photos[i] for i in kept], [photos[i] for i in held_out], [note] if note else []
    validation_files = photo_files(settings.val_images)
    shared = {p.resolve() for p in files} & {p.resolve() for p in validation_files}
    if shared:
        raise WiseError(
            f"{settings.val_images}: {len(shared)} validation photos are also training photos "
            f"(e.g. {sorted(shared)[0].name}); keep the folders apart"
        )
    training, note = checked_photos(settings.images, files, settings.size, largest)
    validation, skipped = read_photos(validation_files, settings.size, largest)
    if not validation:
        raise WiseError(
            f"{settings.val_images}: no readable validation photos of at least {settings.size} pixels a side"
        )
    notes = [note] if note else []
    if skipped:
        notes.append(f"{settings.val_images}: skipped {len(skipped)} unreadable or too small files")
    return training, validation, notes


def prepare(settings: TrainSettings, folder: Path, resume: bool) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
    """Check the settings and the run folder and read the photos (training, validation)."""
    settings.check()
    check_run_folder(folder, resume)
    if resume:
        check_resumed(folder, settings)
    training, validation, notes = load_photos(settings)
    for note in notes:
        warnings.warn(note, WiseWarning, stacklevel=2)
    return training, validation
