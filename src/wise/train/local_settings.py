"""What a ``wise train local`` run is made of, checked before any work (no Lightning here):
the settings, the pairs and the parameters the network starts from."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import torch

from wise import effects
from wise.effects.catalogue import NO_EFFECT
from wise.errors import WiseError
from wise.ppn.choices import NO_POST, POST_KINDS, PPN_KINDS
from wise.ppn.modelfile import model_info, resolve_model
from wise.ppn.postprocess import DEFAULT_WIDTH
from wise.train.choices import DIRECTIONS, GAN_LOSSES, LR_SCHEDULES, TASK_FILE
from wise.train.pairs import Pair, check_pairs, pair_files
from wise.train.settings import check_resumed, check_run_folder

LOCAL_RESUMABLE = (
    "effect", "pairs", "start", "depth", "width", "max_width", "discriminator_width", "gan_weight", "batch",
    "load_size", "crop_size", "seed", "direction", "post", "post_width", "ppn", "dropout",
)  # fmt: skip
"""Settings a resumed run must share with the run it continues."""


@dataclass
class LocalSettings:
    """Everything a local training run is made of (``settings.json`` and the model's metadata)."""

    effect: str
    pairs: str
    start: str | None = None
    """The preset the untrained network paints everywhere (None: the task's preset, else the defaults)."""
    init: str | None = None
    """A local model of the effect (file or ``builtin:<task>``) whose weights the network starts
    from instead (fine-tuning); its depth and widths must be the run's."""
    depth: int = 6
    width: int = 16
    max_width: int = 64
    discriminator_width: int = 64
    gan_loss: str = "vanilla"
    gan_weight: float = 1.0
    l1_weight: float = 100.0
    tv_weight: float = 1.0
    preset_weight: float = 0.0
    """δ: L1 of the masks to the start preset (0: none)."""
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
    post: str = NO_POST
    """The post-processing CNN after the effect (``resnet``, ``unet``; ``none``: no CNN)."""
    post_width: int = DEFAULT_WIDTH
    ppn: str = "local"
    """``local``: a PPN paints the masks; ``preset``: the effect runs at the start preset."""
    dropout: bool = False
    """pix2pix's dropout in the post-processing CNN."""
    workers: int = 0
    accelerator: str = "auto"
    devices: int = 1
    num_nodes: int = 1
    seed: int = 0
    half: bool = False
    checkpoint_every: int = 200

    @property
    def has_effect(self) -> bool:
        return self.effect != NO_EFFECT

    @property
    def translates(self) -> bool:
        """Whether the model is a translator (:mod:`wise.ppn.translation`), not a plain local PPN."""
        return self.post != NO_POST or self.ppn != "local" or not self.has_effect

    def check(self) -> None:
        if self.has_effect:
            effects.create(self.effect)
        if self.post not in POST_KINDS:
            raise WiseError(f"unknown post-processing network {self.post!r}; use one of {', '.join(POST_KINDS)}")
        if self.ppn not in PPN_KINDS:
            raise WiseError(f"unknown --ppn {self.ppn!r}; use one of {', '.join(PPN_KINDS)}")
        if not self.has_effect and self.post == NO_POST:
            raise WiseError("the effect 'none' trains a CNN alone: choose one with --post resnet or --post unet")
        if self.has_effect and self.ppn == "preset" and self.post == NO_POST:
            raise WiseError(
                "--ppn preset with --post none has nothing to learn: add a CNN with --post, or use --ppn local"
            )
        if self.init is not None and (not self.has_effect or self.ppn != "local"):
            raise WiseError("--init starts the PPN from a local model: it needs an effect and --ppn local")
        if self.post_width < 1:
            raise WiseError(f"--post-width {self.post_width} must be at least 1")
        if self.gan_loss not in GAN_LOSSES:
            raise WiseError(f"unknown GAN loss {self.gan_loss!r}; use one of {', '.join(GAN_LOSSES)}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise WiseError(f"unknown learning-rate schedule {self.lr_schedule!r}; use {', '.join(LR_SCHEDULES)}")
        if self.direction not in DIRECTIONS:
            raise WiseError(f"unknown direction {self.direction!r}; use AtoB or BtoA")
        for name in ("gan_weight", "l1_weight", "tv_weight", "preset_weight"):
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
    """The ``(P,)`` normalized parameters the untrained network paints (and the effect runs
    at with ``--ppn preset``): ``--start``'s preset, else the preset of the pairs' task (when it
    is of this effect), else the effect's first preset (xdog: ``portrait``) with ``--ppn preset``, else its
    defaults; empty without an effect."""
    if not settings.has_effect:
        return torch.zeros(0)
    effect = effects.create(settings.effect)
    if settings.start is not None:
        return effect.preset(settings.start)
    task = read_task(settings.pairs)
    if task.get("effect") == settings.effect and task.get("preset") in effect.presets:
        return effect.preset(task["preset"])
    if settings.ppn == "preset" and effect.presets:
        return effect.preset(next(iter(effect.presets)))
    return effect.default_params()


def check_task_effect(settings: LocalSettings) -> None:
    """Refuse pairs that an adaptive task made with another effect."""
    task_effect = read_task(settings.pairs).get("effect")
    if task_effect is not None and task_effect != settings.effect and settings.has_effect:
        raise WiseError(
            f"{settings.pairs}: pairs of the {task_effect!r} effect ({TASK_FILE}); train {task_effect}, "
            f"or make pairs of {settings.effect!r}"
        )


def init_model(settings: LocalSettings) -> Path | None:
    """The checked file of ``--init``: a local model of the run's effect, with its network
    options; None without ``--init``."""
    if settings.init is None:
        return None
    path = resolve_model(settings.init, settings.effect, "local")
    network = model_info(path, settings.effect, "local").network
    wanted = {"depth": settings.depth, "width": settings.width, "max_width": settings.max_width}
    if network != wanted:
        has = ", ".join(f"{name.replace('_', ' ')} {value}" for name, value in sorted(network.items()))
        raise WiseError(f"--init {settings.init}: a network of {has}; give the same --depth, --width and --max-width")
    return path


def prepare_local(settings: LocalSettings, folder: Path, resume: bool) -> tuple[list[Pair], list[Pair]]:
    """Check the settings, the run folder and the pairs; the training and test pairs."""
    settings.check()
    check_run_folder(folder, resume)
    if resume:
        check_resumed(folder, settings, LOCAL_RESUMABLE)
    check_task_effect(settings)
    start_params(settings)
    init_model(settings)
    train = pair_files(settings.pairs, "train", settings.direction)
    test = pair_files(settings.pairs, "test", settings.direction)
    check_pairs(train)
    check_pairs(test)
    return train, test
