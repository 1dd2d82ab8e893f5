"""Pieces every training command shares: the fit itself (:func:`fit_run`), stopping on Ctrl-C
with a checkpoint, examples per second, the numbered CSV log parts of a resumable run, and the
precision of the device."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback
from lightning.pytorch.loggers import CSVLogger

from wise.interrupt import CtrlC, ctrl_c
from wise.train.settings import CHECKPOINT, LOGS


class Stopper(Callback):
    """Ends training at the next step after Ctrl-C (on every process at once), and writes the
    checkpoint every ``every`` steps. A module with ``optimizers`` optimizers stepped by hand
    advances Lightning's step count by that many per training step."""

    def __init__(self, interruption: CtrlC, checkpoint: Path, every: int, optimizers: int = 1) -> None:
        self.interruption, self.checkpoint, self.every = interruption, checkpoint, every
        self.optimizers = optimizers

    def on_train_batch_end(self, trainer: L.Trainer, *args: object) -> None:
        if trainer.strategy.reduce_boolean_decision(self.interruption.received, all=False):
            trainer.should_stop = True
        elif (trainer.global_step // self.optimizers) % self.every == 0:
            trainer.save_checkpoint(self.checkpoint, weights_only=False)


class Throughput(Callback):
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


def log_files(folder: Path) -> list[Path]:
    parts = [p for p in (folder / LOGS).glob("*") if p.name.isdigit()]
    return [p / "metrics.csv" for p in sorted(parts, key=lambda p: int(p.name))]


def log_part(folder: Path) -> int:
    """The number of the log part of a new start (an earlier start's log is kept)."""
    files = log_files(folder)
    return int(files[-1].parent.name) + 1 if files else 0


def precision(accelerator: str) -> str:
    uses_gpu = accelerator in ("gpu", "cuda") or (accelerator == "auto" and torch.cuda.is_available())
    return "16-mixed" if uses_gpu else "32-true"


def trainer_options(
    folder: Path, callbacks: list[Callback], settings: object, per_process: int, partial_backward: bool = False
) -> dict:
    """The ``L.Trainer`` options every run shares: the settings' devices, nodes and precision,
    the numbered CSV log part of ``folder``, no Lightning checkpoints or summaries (the runs
    write their own), and validation every ``checkpoint_every`` steps or epoch of
    ``per_process`` steps, whichever comes first. ``partial_backward``: some backward passes
    reach only part of the model (a GAN's generator and discriminator steps), which DDP must
    be told."""
    processes = settings.devices * settings.num_nodes  # type: ignore[attr-defined]
    return {
        "accelerator": settings.accelerator,  # type: ignore[attr-defined]
        "devices": settings.devices,  # type: ignore[attr-defined]
        "num_nodes": settings.num_nodes,  # type: ignore[attr-defined]
        "strategy": ("ddp_find_unused_parameters_true" if partial_backward else "ddp") if processes > 1 else "auto",
        "precision": precision(settings.accelerator),  # type: ignore[attr-defined]
        "logger": CSVLogger(folder, name=LOGS, version=str(log_part(folder))),
        "callbacks": callbacks,
        "default_root_dir": folder,
        "enable_checkpointing": False,
        "enable_model_summary": False,
        "log_every_n_steps": max(1, min(10, per_process)),
        "val_check_interval": min(per_process, settings.checkpoint_every),  # type: ignore[attr-defined]
        "num_sanity_val_steps": 0,
    }


def fit_run(
    module: L.LightningModule,
    data: L.LightningDataModule,
    folder: Path,
    make_trainer: Callable[[list[Callback]], L.Trainer],
    write_results: Callable[[dict], None],
    batch: int,
    checkpoint_every: int,
    resume: bool,
    out: TextIO,
    optimizers: int = 1,
) -> dict:
    """Fit ``module`` (from the run's checkpoint when ``resume``), keep the checkpoint, and let
    process 0 ``write_results(summary)``; Ctrl-C stops at the next step and the results are
    still written. The summary: training steps, processes, ``interrupted`` and examples per
    second (:class:`Throughput`). ``make_trainer`` gets the callbacks the trainer must run."""
    checkpoint = folder / CHECKPOINT
    with ctrl_c(out) as interruption:
        interruption.hold()
        throughput = Throughput(batch)
        trainer = make_trainer([Stopper(interruption, checkpoint, checkpoint_every, optimizers), throughput])
        trainer.fit(
            module, datamodule=data, ckpt_path=checkpoint if resume else None, weights_only=True if resume else None
        )
        trainer.save_checkpoint(checkpoint, weights_only=False)
        summary = {
            "steps": trainer.global_step // optimizers,
            "processes": trainer.world_size,
            "interrupted": interruption.received,
            **throughput.rates(trainer.world_size),
        }
        if trainer.is_global_zero:
            write_results(summary)
    summary["interrupted"] = summary["interrupted"] or interruption.received
    return summary
