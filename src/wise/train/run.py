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
from pathlib import Path
from typing import TextIO

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback

from wise.errors import WiseError
from wise.io import atomic_path
from wise.ppn.modelfile import ModelInfo, save_model
from wise.train.data import ExampleDataset
from wise.train.engine import fit_run, log_files, trainer_options
from wise.train.module import ExampleData, GlobalPPN
from wise.train.report import write_training_report
from wise.train.settings import (
    MODEL_FILE,
    REPORT_FILE,
    SETTINGS_FILE,
    VALIDATION_EXAMPLES,
    TrainSettings,
    is_launched_rank,
    prepare,
)


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
    steps_per_epoch = settings.examples // (settings.batch * settings.devices * settings.num_nodes)
    return L.Trainer(
        max_steps=settings.steps if settings.steps is not None else -1,
        max_epochs=settings.epochs if settings.epochs is not None else (-1 if settings.steps else 1),
        use_distributed_sampler=False,
        check_val_every_n_epoch=None if settings.steps else 1,
        **trainer_options(folder, callbacks, settings, steps_per_epoch),
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
        soft_gradients=settings.soft_gradients,
        param_weight=settings.param_weight,
        lr_schedule=settings.lr_schedule,
    )
    if settings.backbone_weights is not None:
        _load_backbone(module.network, settings.architecture, settings.backbone_weights)
    folder.mkdir(parents=True, exist_ok=True)
    if not is_launched_rank():
        with atomic_path(folder / SETTINGS_FILE) as path:
            Path(path).write_text(json.dumps(dataclasses.asdict(settings), indent=2) + "\n")
    return fit_run(
        module,
        data,
        folder,
        lambda callbacks: _trainer(settings, folder, callbacks),
        lambda summary: _write_results(settings, folder, module, (train_set, validation_set), summary, out),
        settings.batch,
        settings.checkpoint_every,
        resume,
        out,
    )


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
    write_training_report(folder / REPORT_FILE, module, datasets[1], log_files(folder), summary)
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
