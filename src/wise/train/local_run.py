"""One training run of a local parameter prediction network into a folder (``wise train local``).

The run folder holds what a ``wise train global`` run holds (``settings.json``,
``checkpoints/last.ckpt``, ``logs/<n>/metrics.csv``, ``model.safetensors`` and
``report.html``), on the same engine: CPU, one GPU, or many processes and nodes (DDP).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path
from typing import TextIO

import lightning as L

from wise.io import atomic_path
from wise.ppn.modelfile import BUILTIN_PREFIX, ModelInfo, load_model, save_model
from wise.ppn.translation import ARCHITECTURE as TRANSLATOR
from wise.ppn.translation import translator_options
from wise.train.engine import fit_run, log_files, trainer_options
from wise.train.local import LocalGAN, PairData
from wise.train.local_report import write_local_report
from wise.train.local_settings import LocalSettings, init_model, prepare_local, read_task, start_params
from wise.train.pairs import Pair, PairDataset
from wise.train.settings import MODEL_FILE, REPORT_FILE, SETTINGS_FILE, is_launched_rank

VALIDATION_PAIRS = 16
"""Test pairs the validation loss is measured on, spread evenly over the test pairs (which come
several to a photo)."""


def _module(settings: LocalSettings) -> LocalGAN:
    module = LocalGAN(
        settings.effect,
        start_params(settings).tolist(),
        {"depth": settings.depth, "width": settings.width, "max_width": settings.max_width},
        gan_loss=settings.gan_loss,
        gan_weight=settings.gan_weight,
        l1_weight=settings.l1_weight,
        tv_weight=settings.tv_weight,
        preset_weight=settings.preset_weight,
        lr=settings.lr,
        lr_schedule=settings.lr_schedule,
        discriminator_width=settings.discriminator_width,
        anneal=settings.anneal,
        soft_gradients=settings.soft_gradients,
        post=settings.post,
        post_width=settings.post_width,
        ppn_kind=settings.ppn,
        dropout=settings.dropout,
    )
    init = init_model(settings)
    if init is not None:
        network, _ = load_model(init, settings.effect, "local")
        module.generator.load_state_dict(network.state_dict())
    return module


def _trainer(settings: LocalSettings, folder: Path, callbacks: list, batches_per_epoch: int, optimizers: int):
    per_process = max(1, batches_per_epoch // (settings.devices * settings.num_nodes))
    return L.Trainer(
        # Lightning counts a step per optimizer step; the generator and discriminator make two.
        max_steps=settings.steps * optimizers if settings.steps is not None else -1,
        max_epochs=settings.epochs if settings.epochs is not None else -1,
        check_val_every_n_epoch=1,
        reload_dataloaders_every_n_epochs=1,
        **trainer_options(folder, callbacks, settings, per_process, partial_backward=optimizers > 1),
    )


def train_local(
    settings: LocalSettings,
    run_dir: str,
    resume: bool = False,
    out: TextIO = sys.stdout,
    pairs: tuple[list[Pair], list[Pair]] | None = None,
) -> dict:
    """Train, then write the model and the report into ``run_dir``; returns a summary
    (``interrupted`` when Ctrl-C ended it: the checkpoint and the model are still written).
    ``pairs`` are those of :func:`prepare_local` when it was called already."""
    folder = Path(run_dir)
    if pairs is None:
        pairs = prepare_local(settings, folder, resume)
    L.seed_everything(settings.seed, verbose=False)
    train_pairs, test_pairs = pairs
    jitter = {"load_size": settings.load_size, "crop_size": settings.crop_size, "direction": settings.direction}
    train_set = PairDataset(train_pairs, flip=settings.flip, seed=settings.seed, **jitter)
    every = max(1, len(test_pairs) // VALIDATION_PAIRS)
    shown = test_pairs[::every][:VALIDATION_PAIRS]
    test_set = PairDataset(shown, None, None, flip=False, direction=settings.direction)
    data = PairData(train_set, test_set, settings.batch, workers=settings.workers)
    module = _module(settings)
    optimizers = 2 if module.discriminator is not None else 1
    folder.mkdir(parents=True, exist_ok=True)
    if not is_launched_rank():
        with atomic_path(folder / SETTINGS_FILE) as path:
            Path(path).write_text(json.dumps(dataclasses.asdict(settings), indent=2) + "\n")
    batches = max(1, len(train_set) // settings.batch)
    return fit_run(
        module,
        data,
        folder,
        lambda callbacks: _trainer(settings, folder, callbacks, batches, optimizers),
        lambda summary: _write_results(settings, folder, module, test_set, summary, out),
        settings.batch,
        settings.checkpoint_every,
        resume,
        out,
        optimizers,
    )


def _model_name(model: str | None) -> str | None:
    """``--init`` as a model file records it: a built-in name, or a file's name (no folders of
    this machine)."""
    if model is None or model.startswith(BUILTIN_PREFIX):
        return model
    return Path(model).name


def _write_results(
    settings: LocalSettings, folder: Path, module: LocalGAN, test_set: PairDataset, summary: dict, out: TextIO
) -> None:
    shared = {
        **dataclasses.asdict(settings),
        "pairs": Path(settings.pairs).name,
        "init": _model_name(settings.init),
        "task": read_task(settings.pairs).get("task"),
        "steps_done": summary["steps"],
        "processes": summary["processes"],
    }
    network: dict = {"depth": settings.depth, "width": settings.width, "max_width": settings.max_width}
    saved, architecture = module.generator, "unet"
    if settings.translates:
        saved, architecture = module.network, TRANSLATOR
        network = translator_options(settings.ppn, settings.post, settings.post_width, settings.dropout, **network)
    parameters = module.effect.param_names if module.effect is not None else []
    info = ModelInfo(
        settings.effect,
        architecture,
        parameters,
        settings.load_size,
        settings.load_size,
        shared,
        kind="local",
        network=network,
    )
    save_model(folder / MODEL_FILE, saved, info, half=settings.half)
    write_local_report(folder / REPORT_FILE, module, test_set, log_files(folder), summary, read_task(settings.pairs))
    print(
        f"{summary['steps']} steps; {summary['examples_per_second']:.1f} examples/s in all, "
        f"{summary['step_examples_per_second']:.1f} in the training steps; "
        f"model: {folder / MODEL_FILE}; report: {folder / REPORT_FILE}",
        file=out,
        flush=True,
    )
