"""One training run of a global parameter prediction network into a folder (``wise train global``).

The run folder holds ``settings.json``, ``checkpoints/last.ckpt`` (Lightning's format, written
by this command and read back with ``weights_only``), ``logs/metrics.csv``, and at the end
``model.safetensors`` and ``report.html``. The same command runs on the CPU, one GPU or many
processes and nodes (DDP); mixed precision on GPUs.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import TextIO

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback
from lightning.pytorch.loggers import CSVLogger

from wise.errors import WiseError
from wise.interrupt import CtrlC, ctrl_c
from wise.io import atomic_path
from wise.ppn.modelfile import ModelInfo, save_model
from wise.train.data import ExampleDataset
from wise.train.module import ExampleData, GlobalPPN
from wise.train.report import write_training_report
from wise.train.settings import (
    CHECKPOINT,
    LOGS,
    MODEL_FILE,
    REPORT_FILE,
    SETTINGS_FILE,
    VALIDATION_EXAMPLES,
    TrainSettings,
    is_launched_rank,
    prepare,
)


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


def _datasets(
    settings: TrainSettings, photos: tuple[list[torch.Tensor], list[torch.Tensor]]
) -> tuple[ExampleDataset, ExampleDataset]:
    """The training and validation examples (taken from the cache where it has them)."""
    training_photos, validation_photos = photos
    common = {"sampling": settings.sampling, "render_size": settings.render_size, "window": settings.window}
    train_set = ExampleDataset(
        training_photos, settings.effect, settings.size, settings.examples, seed=settings.seed, **common,
        fresh=settings.fresh, procedural=settings.procedural, augmentation=settings.augmentation,
    )  # fmt: skip
    validation_set = ExampleDataset(
        validation_photos, settings.effect, settings.size, min(VALIDATION_EXAMPLES, settings.examples),
        seed=settings.seed + 1, **common,
    )  # fmt: skip
    if settings.cache is not None:
        for dataset in (train_set, validation_set):
            dataset.load_cache(settings.cache)
    return train_set, validation_set


def _trainer(settings: TrainSettings, folder: Path, callbacks: list[Callback]) -> L.Trainer:
    processes = settings.devices * settings.num_nodes
    steps_per_epoch = settings.examples // (settings.batch * processes)
    return L.Trainer(
        accelerator=settings.accelerator,
        devices=settings.devices,
        num_nodes=settings.num_nodes,
        strategy="ddp" if processes > 1 else "auto",
        precision=_precision(settings.accelerator),
        max_steps=settings.steps if settings.steps is not None else -1,
        max_epochs=settings.epochs if settings.epochs is not None else (-1 if settings.steps else 1),
        logger=CSVLogger(folder, name=LOGS, version=str(_log_part(folder))),
        callbacks=callbacks,
        default_root_dir=folder,
        enable_checkpointing=False,
        enable_model_summary=False,
        use_distributed_sampler=False,
        log_every_n_steps=max(1, min(10, steps_per_epoch)),
        val_check_interval=min(steps_per_epoch, settings.checkpoint_every),
        check_val_every_n_epoch=None if settings.steps else 1,
        num_sanity_val_steps=0,
    )


def train_global(
    settings: TrainSettings,
    run_dir: str,
    resume: bool = False,
    out: TextIO = sys.stdout,
    photos: tuple[list[torch.Tensor], list[torch.Tensor]] | None = None,
) -> dict:
    """Train, then write the model and the report into ``run_dir``; returns a summary
    (``interrupted`` when Ctrl-C ended it: the checkpoint and the model are still written).
    ``photos`` are those of :func:`prepare` when it was called already. A run resumed in the
    middle of an epoch continues with the next one."""
    folder = Path(run_dir)
    if photos is None:
        photos = prepare(settings, folder, resume)
    L.seed_everything(settings.seed, verbose=False)
    train_set, validation_set = _datasets(settings, photos)
    data = ExampleData(train_set, validation_set, settings.batch, settings.seed, workers=settings.workers)
    module = GlobalPPN(
        settings.effect,
        settings.architecture,
        settings.loss,
        settings.lr,
        settings.size,
        anneal=settings.anneal,
        lr_schedule=settings.lr_schedule,
    )
    if settings.backbone_weights is not None:
        _load_backbone(module.network, settings.architecture, settings.backbone_weights)
    folder.mkdir(parents=True, exist_ok=True)
    if not is_launched_rank():
        with atomic_path(folder / SETTINGS_FILE) as path:
            Path(path).write_text(json.dumps(dataclasses.asdict(settings), indent=2) + "\n")
    with ctrl_c(out) as interruption:
        interruption.hold()
        throughput = _Throughput(settings.batch)
        trainer = _trainer(
            settings, folder, [_Stopper(interruption, folder / CHECKPOINT, settings.checkpoint_every), throughput]
        )
        checkpoint = folder / CHECKPOINT if resume else None
        trainer.fit(module, datamodule=data, ckpt_path=checkpoint, weights_only=True if checkpoint else None)
        trainer.save_checkpoint(folder / CHECKPOINT, weights_only=False)
        summary = {
            "steps": trainer.global_step,
            "processes": trainer.world_size,
            "interrupted": interruption.received,
            **throughput.rates(trainer.world_size),
        }
        if trainer.is_global_zero:
            _write_results(settings, folder, module, (train_set, validation_set), summary, out)
    summary["interrupted"] = summary["interrupted"] or interruption.received
    return summary


def _write_results(
    settings: TrainSettings,
    folder: Path,
    module: GlobalPPN,
    datasets: tuple[ExampleDataset, ExampleDataset],
    summary: dict,
    out: TextIO,
) -> None:
    """The example cache, the model and the report of a finished or interrupted run."""
    if settings.cache is not None:
        for dataset in datasets:
            dataset.save_cache(settings.cache)
    shared = {**settings.shareable(), "steps_done": summary["steps"], "processes": summary["processes"]}
    info = ModelInfo(
        settings.effect, settings.architecture, module.effect.param_names, settings.size, settings.render_size, shared
    )
    save_model(folder / MODEL_FILE, module.network, info, half=settings.half)
    write_training_report(folder / REPORT_FILE, module, datasets[1], _log_files(folder), summary)
    print(
        f"{summary['steps']} steps; {summary['examples_per_second']:.1f} examples/s in all, "
        f"{summary['step_examples_per_second']:.1f} in the training steps; "
        f"model: {folder / MODEL_FILE}; report: {folder / REPORT_FILE}",
        file=out,
        flush=True,
    )


def _load_backbone(network: torch.nn.Module, architecture: str, path: str) -> None:
    from wise.ppn.weights import load_resnet50, load_vgg11

    if architecture == "resnet":
        load_resnet50(network, path)  # type: ignore[arg-type]
    elif architecture == "multifeature":
        load_vgg11(network, path)  # type: ignore[arg-type]
    else:
        raise WiseError(f"--backbone-weights: the {architecture!r} architecture has no ImageNet backbone")
