"""What a ``wise train local`` run is made of, checked before any work (no Lightning here):
the settings, the pairs and the parameters the network starts from."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import torch

from wise import effects
from wise.errors import WiseError
from wise.train.discriminator import GAN_LOSSES
from wise.train.pairs import Pair, check_pairs, pair_files
from wise.train.schedules import LR_SCHEDULES
from wise.train.settings import check_resumed, check_run_folder

TASK_FILE = "task.json"
"""Written by ``wise data adaptive`` into a pairs folder: the task, its effect and preset."""
DIRECTIONS = ("AtoB", "BtoA")
LOCAL_RESUMABLE = (
    "effect", "pairs", "start", "depth", "width", "max_width", "discriminator_width", "gan_weight", "batch",
    "load_size", "crop_size", "seed", "direction",
)  # fmt: skip
"""Settings a resumed run must share with the run it continues."""


@dataclass
class LocalSettings:
    """Everything a local training run is made of (``settings.json`` and the model's metadata)."""

    effect: str
    pairs: str
    start: str | None = None
    """The preset the untrained network paints everywhere (None: the task's preset, else the defaults)."""
    depth: int = 6
    width: int = 16
    max_width: int = 64
    discriminator_width: int = 64
    gan_loss: str = "vanilla"
    gan_weight: float = 1.0
    l1_weight: float = 100.0
    tv_weight: float = 1.0
    lr: float = 2e-4
    lr_schedule: str = "linear"
    batch: int = 1
    steps: int | None = None
    epochs: int | None = None
    load_size: int = 286
    crop_size: int = 256
    flip: bool = True
    direction: str = "AtoB"
    anneal: float = 0.0
    soft_gradients: float = 0.0
    workers: int = 0
    accelerator: str = "auto"
    devices: int = 1
    num_nodes: int = 1
    seed: int = 0
    half: bool = False
    checkpoint_every: int = 200

    def check(self) -> None:
        effects.create(self.effect)
        if self.gan_loss not in GAN_LOSSES:
            raise WiseError(f"unknown GAN loss {self.gan_loss!r}; use one of {', '.join(GAN_LOSSES)}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise WiseError(f"unknown learning-rate schedule {self.lr_schedule!r}; use {', '.join(LR_SCHEDULES)}")
        if self.direction not in DIRECTIONS:
            raise WiseError(f"unknown direction {self.direction!r}; use AtoB or BtoA")
        for name in ("gan_weight", "l1_weight", "tv_weight"):
            if getattr(self, name) < 0:
                flag = "--" + name.replace("_", "-")
                raise WiseError(f"{flag} {getattr(self, name)} must not be negative")
        if self.gan_weight == 0 and self.l1_weight == 0:
            raise WiseError("--gan-weight and --l1-weight are both 0: nothing would be learned; raise one of them")
        for name in ("anneal", "soft_gradients"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise WiseError(f"--{name.replace('_', '-')} {getattr(self, name)} must be from 0 to 1")
        if self.crop_size > self.load_size:
            raise WiseError(f"--crop-size {self.crop_size} is larger than --load-size {self.load_size}")


def read_task(folder: str | Path) -> dict:
    """The ``task.json`` of a pairs folder made by ``wise data adaptive`` ({} when there is none)."""
    path = Path(folder) / TASK_FILE
    if not path.is_file():
        return {}
    try:
        task = json.loads(path.read_text())
    except (OSError, ValueError):
        raise WiseError(f"{path}: not readable JSON; make the pairs again with 'wise data adaptive'") from None
    if not isinstance(task, dict):
        raise WiseError(f"{path}: not a task description; make the pairs again with 'wise data adaptive'")
    return task


def start_params(settings: LocalSettings) -> torch.Tensor:
    """The ``(P,)`` normalized parameters the untrained network paints: ``--start``'s preset,
    else the preset of the pairs' task (when it is of this effect), else the defaults."""
    effect = effects.create(settings.effect)
    if settings.start is not None:
        return effect.preset(settings.start)
    task = read_task(settings.pairs)
    if task.get("effect") == settings.effect and task.get("preset") in effect.presets:
        return effect.preset(task["preset"])
    return effect.default_params()


def check_task_effect(settings: LocalSettings) -> None:
    """Refuse pairs that an adaptive task made with another effect."""
    task_effect = read_task(settings.pairs).get("effect")
    if task_effect is not None and task_effect != settings.effect:
        raise WiseError(
            f"{settings.pairs}: pairs of the {task_effect!r} effect ({TASK_FILE}); train {task_effect}, "
            f"or make pairs of {settings.effect!r}"
        )


def prepare_local(settings: LocalSettings, folder: Path, resume: bool) -> tuple[list[Pair], list[Pair]]:
    """Check the settings, the run folder and the pairs; the training and test pairs."""
    settings.check()
    check_run_folder(folder, resume)
    if resume:
        check_resumed(folder, settings, LOCAL_RESUMABLE)
    check_task_effect(settings)
    start_params(settings)
    train = pair_files(settings.pairs, "train", settings.direction)
    test = pair_files(settings.pairs, "test", settings.direction)
    check_pairs(train)
    check_pairs(test)
    return train, test
