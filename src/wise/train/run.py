"""``wise train global``: one training run of a global parameter prediction network into a folder.

The run folder holds ``settings.json``, ``checkpoints/last.ckpt`` (Lightning's format, written
by this command and read back with ``weights_only``), ``logs/metrics.csv``, and at the end
``model.safetensors`` and ``report.html``. The same command runs on the CPU, one GPU or many
processes and nodes (DDP); mixed precision on GPUs.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback
from lightning.pytorch.loggers import CSVLogger

from wise import effects, ppn
from wise.errors import WiseError
from wise.interrupt import CtrlC, ctrl_c
from wise.io import atomic_path
from wise.ppn.modelfile import ModelInfo, save_model
from wise.train.data import (
    SAMPLINGS,
    SCALE_RANGE,
    ExampleDataset,
    checked_photos,
    photo_files,
    read_photos,
    split_files,
)
from wise.train.losses import LOSSES
from wise.train.module import ExampleData, GlobalPPN
from wise.train.report import write_training_report

CHECKPOINT = Path("checkpoints") / "last.ckpt"
SETTINGS_FILE = "settings.json"
MODEL_FILE = "model.safetensors"
REPORT_FILE = "report.html"
LOGS = "logs"
"""Lightning's CSV logs, one numbered part per start of the run (``logs/<n>/metrics.csv``)."""
VALIDATION_SHARE = 0.15
"""Share of the photos held out for validation when no ``--val-images`` are given."""
VALIDATION_EXAMPLES = 64
RESUMABLE = ("effect", "architecture", "loss", "size", "render_size", "batch", "examples", "sampling", "seed")
"""Settings a resumed run must share with the run it continues."""


@dataclass
class TrainSettings:
    """Everything a training run is made of (``settings.json`` and the model's metadata)."""

    effect: str
    images: str
    architecture: str = "simple"
    loss: str = "param-l1"
    size: int = 128
    render_size: int = 512
    batch: int = 16
    steps: int | None = None
    epochs: int | None = None
    examples: int = 2000
    lr: float = 1e-3
    sampling: str = "uniform"
    val_images: str | None = None
    accelerator: str = "auto"
    devices: int = 1
    num_nodes: int = 1
    seed: int = 0
    half: bool = False
    checkpoint_every: int = 200
    backbone_weights: str | None = None

    def check(self) -> None:
        effects.create(self.effect)
        if self.architecture not in ppn.ARCHITECTURES:
            raise WiseError(f"unknown architecture {self.architecture!r}; use one of {', '.join(ppn.ARCHITECTURES)}")
        if self.loss not in LOSSES:
            raise WiseError(f"unknown loss {self.loss!r}; use one of {', '.join(LOSSES)}")
        if self.sampling not in SAMPLINGS:
            raise WiseError(f"unknown sampling {self.sampling!r}; use one of {', '.join(SAMPLINGS)}")
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


def _check_resumed(folder: Path, settings: TrainSettings) -> None:
    try:
        before = json.loads((folder / SETTINGS_FILE).read_text())
    except (OSError, ValueError):
        raise WiseError(f"{folder}: {SETTINGS_FILE} is missing or unreadable; cannot resume this run") from None
    now = dataclasses.asdict(settings)
    changed = [key for key in RESUMABLE if before.get(key) != now.get(key)]
    if changed:
        listed = ", ".join(f"{key} {before.get(key)!r} -> {now.get(key)!r}" for key in changed)
        raise WiseError(f"{folder}: --resume with other settings than the run ({listed}); repeat its settings")


class _Stopper(Callback):
    """Ends training at the next step after Ctrl-C (on every process at once), and writes the
    checkpoint every ``every`` steps."""

    def __init__(self, interruption: CtrlC, checkpoint: Path, every: int) -> None:
        self.interruption, self.checkpoint, self.every = interruption, checkpoint, every

    def on_train_batch_end(self, trainer: L.Trainer, *args: object) -> None:
        if trainer.strategy.reduce_boolean_decision(self.interruption.received, all=False):
            trainer.should_stop = True
        elif trainer.global_step % self.every == 0:
            trainer.save_checkpoint(self.checkpoint, weights_only=False)


class _Throughput(Callback):
    """Examples per second of all processes together: over the whole run (rendering the
    examples and validation included), and over the training steps alone."""

    def __init__(self, batch: int) -> None:
        self.batch, self.steps, self.step_seconds = batch, 0, 0.0
        self._began = self._step_began = self._ended = 0.0

    def on_train_start(self, *args: object) -> None:
        self._began = time.perf_counter()

    def on_train_end(self, *args: object) -> None:
        self._ended = time.perf_counter()

    def on_train_batch_start(self, *args: object) -> None:
        self._step_began = time.perf_counter()

    def on_train_batch_end(self, *args: object) -> None:
        self.step_seconds += time.perf_counter() - self._step_began
        self.steps += 1

    def rates(self, world: int) -> dict[str, float]:
        examples = self.steps * self.batch * world
        wall = (self._ended or time.perf_counter()) - self._began
        return {
            "examples_per_second": round(examples / wall, 2) if wall > 0 else 0.0,
            "step_examples_per_second": round(examples / self.step_seconds, 2) if self.step_seconds else 0.0,
        }


def _log_files(folder: Path) -> list[Path]:
    parts = [p for p in (folder / LOGS).glob("*") if p.name.isdigit()]
    return [p / "metrics.csv" for p in sorted(parts, key=lambda p: int(p.name))]


def _log_part(folder: Path) -> int:
    """The number of the log part of a new start (an earlier start's log is kept)."""
    files = _log_files(folder)
    return int(files[-1].parent.name) + 1 if files else 0


def _precision(accelerator: str) -> str:
    uses_gpu = accelerator in ("gpu", "cuda") or (accelerator == "auto" and torch.cuda.is_available())
    return "16-mixed" if uses_gpu else "32-true"


def _photos(settings: TrainSettings) -> tuple[list[torch.Tensor], list[torch.Tensor], list[str]]:
    """Training and validation photos (disjoint), and notes on skipped files."""
    files = photo_files(settings.images)
    if settings.val_images is not None:
        validation_files = photo_files(settings.val_images)
        shared = {p.resolve() for p in files} & {p.resolve() for p in validation_files}
        if shared:
            raise WiseError(
                f"{settings.val_images}: {len(shared)} validation photos are also training photos "
                f"(e.g. {sorted(shared)[0].name}); keep the folders apart"
            )
        training_files = files
    else:
        training_files, validation_files = split_files(files, VALIDATION_SHARE, settings.seed)
    largest = math.ceil(settings.render_size / SCALE_RANGE[0])
    training, note = checked_photos(settings.images, training_files, settings.size, largest)
    validation, skipped = read_photos(validation_files, settings.size, largest)
    if not validation:
        where = settings.val_images or settings.images
        raise WiseError(f"{where}: no readable validation photos of at least {settings.size} pixels a side")
    notes = [note] if note else []
    if skipped and settings.val_images is not None:
        notes.append(f"{settings.val_images}: skipped {len(skipped)} unreadable or too small files")
    return training, validation, notes


def train_global(settings: TrainSettings, run_dir: str, resume: bool = False, out: TextIO = sys.stdout) -> dict:
    """Train, then write the model and the report into ``run_dir``; returns a summary
    (``interrupted`` when Ctrl-C ended it: the checkpoint and the model are still written)."""
    settings.check()
    folder = Path(run_dir)
    check_run_folder(folder, resume)
    if resume:
        _check_resumed(folder, settings)
    training_photos, validation_photos, notes = _photos(settings)
    for note in notes:
        warnings.warn(note, stacklevel=2)
    L.seed_everything(settings.seed, verbose=False)
    train_set = ExampleDataset(
        training_photos,
        settings.effect,
        settings.size,
        settings.examples,
        settings.sampling,
        settings.seed,
        settings.render_size,
    )
    validation_examples = min(VALIDATION_EXAMPLES, settings.examples)
    validation_set = ExampleDataset(
        validation_photos,
        settings.effect,
        settings.size,
        validation_examples,
        settings.sampling,
        settings.seed + 1,
        settings.render_size,
    )
    data = ExampleData(train_set, validation_set, settings.batch, settings.seed)
    module = GlobalPPN(settings.effect, settings.architecture, settings.loss, settings.lr)
    if settings.backbone_weights is not None:
        _load_backbone(module.network, settings.architecture, settings.backbone_weights)
    folder.mkdir(parents=True, exist_ok=True)
    if not is_launched_rank():
        with atomic_path(folder / SETTINGS_FILE) as path:
            Path(path).write_text(json.dumps(dataclasses.asdict(settings), indent=2) + "\n")
    steps_per_epoch = settings.examples // (settings.batch * settings.devices * settings.num_nodes)
    with ctrl_c(out) as interruption:
        interruption.hold()
        stopper = _Stopper(interruption, folder / CHECKPOINT, settings.checkpoint_every)
        throughput = _Throughput(settings.batch)
        trainer = L.Trainer(
            accelerator=settings.accelerator,
            devices=settings.devices,
            num_nodes=settings.num_nodes,
            strategy="ddp" if settings.devices * settings.num_nodes > 1 else "auto",
            precision=_precision(settings.accelerator),
            max_steps=settings.steps if settings.steps is not None else -1,
            max_epochs=settings.epochs if settings.epochs is not None else (-1 if settings.steps else 1),
            logger=CSVLogger(folder, name="logs", version=str(_log_part(folder))),
            callbacks=[stopper, throughput],
            default_root_dir=folder,
            enable_checkpointing=False,
            enable_model_summary=False,
            use_distributed_sampler=False,
            log_every_n_steps=max(1, min(10, steps_per_epoch)),
            val_check_interval=min(steps_per_epoch, max(1, settings.checkpoint_every)),
            check_val_every_n_epoch=None if settings.steps else 1,
            num_sanity_val_steps=0,
        )
        ckpt = folder / CHECKPOINT if resume else None
        trainer.fit(module, datamodule=data, ckpt_path=ckpt, weights_only=True if ckpt else None)
        trainer.save_checkpoint(folder / CHECKPOINT, weights_only=False)
        summary = {
            "steps": trainer.global_step,
            "interrupted": interruption.received,
            **throughput.rates(trainer.world_size),
        }
        if trainer.is_global_zero:
            info = ModelInfo(
                effect=settings.effect,
                architecture=settings.architecture,
                parameters=module.effect.param_names,
                size=settings.size,
                render_size=settings.render_size,
                settings={**dataclasses.asdict(settings), "steps_done": trainer.global_step},
            )
            save_model(folder / MODEL_FILE, module.network, info, half=settings.half)
            write_training_report(folder / REPORT_FILE, module, validation_set, _log_files(folder), summary)
            print(
                f"{trainer.global_step} steps, {summary['examples_per_second']:.1f} examples/s; "
                f"model: {folder / MODEL_FILE}; report: {folder / REPORT_FILE}",
                file=out,
                flush=True,
            )
    summary["interrupted"] = summary["interrupted"] or interruption.received
    return summary


def _load_backbone(network: torch.nn.Module, architecture: str, path: str) -> None:
    from wise.ppn.weights import load_resnet50, load_vgg11

    if architecture == "resnet":
        load_resnet50(network, path)  # type: ignore[arg-type]
    elif architecture == "multifeature":
        load_vgg11(network, path)  # type: ignore[arg-type]
    else:
        raise WiseError(f"--backbone-weights: the {architecture!r} architecture has no ImageNet backbone")
