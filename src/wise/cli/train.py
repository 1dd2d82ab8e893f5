"""``wise train global``: train a global parameter prediction network on a folder of photos.

Lightning is imported only when a run starts, so other commands start quickly.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import TextIO

import torch

from wise import effects
from wise.cli import args as types
from wise.cli.outputs import OutputFolder
from wise.cli.parser import add_pixel_limit, command, exit_code
from wise.errors import WiseError
from wise.ppn import ARCHITECTURES
from wise.train.data import MIXTURE_PRESET_SHARE, PROCEDURAL_SHARE, SAMPLINGS
from wise.train.losses import LOSSES
from wise.train.settings import TrainSettings, prepare

ACCELERATORS = ("auto", "cpu", "gpu", "cuda", "mps")
RUN_FILES = ("model.safetensors", "report.html", "settings.json")
DEFAULT_STEPS = 1000
DEFAULT_WINDOW = 128
"""Training windows of the whole picture's pixels (rendering, the cost of training, grows with their area)."""


def _check_accelerator(name: str) -> None:
    if name in ("gpu", "cuda") and not torch.cuda.is_available():
        raise WiseError(f"--accelerator {name}: CUDA is not available here; use --accelerator cpu")
    if name == "mps" and not torch.backends.mps.is_available():
        raise WiseError("--accelerator mps: MPS is not available here; use --accelerator cpu")


def run_train_global(args: argparse.Namespace, out: TextIO) -> int:
    effects.create(args.effect)
    _check_accelerator(args.accelerator)
    for option, folder in (("--images", args.images), ("--val-images", args.val_images)):
        if folder is not None and not Path(folder).is_dir():
            raise WiseError(f"{option} {folder}: not a directory of photos")
    if args.backbone_weights is not None and args.arch in ("simple", "stats"):
        raise WiseError(
            f"--backbone-weights: the {args.arch!r} architecture has no ImageNet backbone; use resnet or multifeature"
        )
    run_folder = OutputFolder(args.output, RUN_FILES, {"--backbone-weights": args.backbone_weights})
    if args.cache is not None:
        if not args.fixed:
            raise WiseError("--cache keeps a fixed set of examples; pass --fixed too, or leave --cache out")
        OutputFolder(args.cache, (), {})
    settings = TrainSettings(
        effect=args.effect,
        images=args.images,
        architecture=args.arch,
        loss=args.loss,
        size=args.size,
        render_size=args.render_size,
        window=args.window if args.window is not None else min(DEFAULT_WINDOW, args.size),
        batch=args.batch,
        steps=None if args.epochs is not None else (args.steps or DEFAULT_STEPS),
        epochs=args.epochs,
        examples=args.examples,
        lr=args.lr,
        sampling=args.sampling,
        fresh=not args.fixed,
        procedural=args.procedural,
        augmentation=not args.no_augment,
        anneal=args.anneal,
        workers=args.workers,
        lr_schedule=args.lr_schedule,
        val_images=args.val_images,
        accelerator=args.accelerator,
        devices=args.devices,
        num_nodes=args.num_nodes,
        seed=args.seed,
        half=args.half,
        checkpoint_every=args.checkpoint_every,
        backbone_weights=args.backbone_weights,
        cache=args.cache,
    )
    photos = prepare(settings, Path(args.output), args.resume)
    from wise.train.run import train_global  # Lightning

    for name in ("lightning.pytorch", "lightning.fabric"):
        logging.getLogger(name).setLevel(logging.WARNING)
    with run_folder.guard():
        summary = train_global(settings, args.output, resume=args.resume, out=out, photos=photos)
    return exit_code(summary["interrupted"])


def register(commands: argparse._SubParsersAction) -> None:
    train = command(commands, "train", "train parameter prediction networks", writes=False)
    kinds = train.add_subparsers(dest="kind", metavar="KIND", required=True, parser_class=type(train))
    parser = command(kinds, "global", "train a network that predicts an effect's global parameters from an example")
    parser.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    parser.add_argument(
        "--images", required=True, metavar="DIR", help="folder of training photos (searched recursively)"
    )
    parser.add_argument("-o", "--output", required=True, metavar="RUNDIR", help="folder of the run")
    parser.add_argument("--arch", choices=tuple(ARCHITECTURES), default="simple", help="network (default simple)")
    parser.add_argument("--loss", choices=LOSSES, default="image-l1", help="loss (default image-l1)")
    parser.add_argument(
        "--size", type=types.working_size, default=512, metavar="PX", help="the network's input size (default 512)"
    )
    parser.add_argument(
        "--render-size",
        type=types.working_size,
        default=512,
        metavar="PX",
        help="the size examples are rendered at before they are reduced to --size (default 512)",
    )
    parser.add_argument(
        "--window",
        type=types.whole_number(8, types.MAX_WORKING_SIZE),
        metavar="PX",
        help=f"side of the training windows at --size (default {DEFAULT_WINDOW}; rendering costs its square)",
    )
    parser.add_argument("--batch", type=types.batch, default=16, metavar="B", help="examples per step and process (16)")
    length = parser.add_mutually_exclusive_group()
    length.add_argument("--steps", type=types.iterations, metavar="N", help=f"training steps (default {DEFAULT_STEPS})")
    length.add_argument("--epochs", type=types.iterations, metavar="N", help="passes over the examples instead")
    parser.add_argument(
        "--examples", type=types.examples, default=2000, metavar="N", help="examples per epoch (default 2000)"
    )
    parser.add_argument("--lr", type=types.positive_rate, default=1e-3, help="Adam learning rate (default 0.001)")
    parser.add_argument(
        "--lr-schedule",
        choices=("constant", "cosine"),
        default="constant",
        help="constant, or cosine: falling to 5%% of --lr at the last step (default constant)",
    )
    parser.add_argument(
        "--sampling",
        choices=SAMPLINGS,
        default="uniform",
        help=f"random parameters: uniform, near presets, or a mixture ({MIXTURE_PRESET_SHARE:.0%}% near presets)",
    )
    parser.add_argument(
        "--fixed",
        action="store_true",
        help="train on one fixed set of --examples rendered once (default: fresh examples every epoch)",
    )
    parser.add_argument(
        "--procedural",
        type=types.share,
        default=PROCEDURAL_SHARE,
        metavar="SHARE",
        help=f"share of training examples on dead-leaves pictures instead of photos (default {PROCEDURAL_SHARE})",
    )
    parser.add_argument(
        "--anneal",
        type=types.share,
        default=0.0,
        metavar="T",
        help="smooth the effect's steps (XDoG threshold, quantization) at temperature T (0-1) at first, "
        "sharpening them by the middle of the run (default 0: never)",
    )
    parser.add_argument(
        "--workers",
        type=types.whole_number(0, 64),
        default=0,
        metavar="N",
        help="processes that render the examples while the steps run (default 0: the training process)",
    )
    parser.add_argument(
        "--no-augment", action="store_true", help="no flips, turns or tone jitter of the training pictures"
    )
    parser.add_argument("--val-images", metavar="DIR", help="validation photos (default: 15%% of --images held out)")
    parser.add_argument("--accelerator", choices=ACCELERATORS, default="auto", help="Lightning accelerator")
    parser.add_argument("--devices", type=types.processes, default=1, metavar="N", help="devices (processes) per node")
    parser.add_argument("--num-nodes", type=types.processes, default=1, metavar="N", help="nodes (default 1)")
    parser.add_argument("--resume", action="store_true", help="continue the run in RUNDIR from its checkpoint")
    parser.add_argument(
        "--seed", type=types.training_seed, default=0, help="seed of the data and weights, 0 to 2**32-1"
    )
    parser.add_argument("--half", action="store_true", help="store the model's weights as float16")
    parser.add_argument(
        "--checkpoint-every", type=types.iterations, default=200, metavar="N", help="steps between checkpoints (200)"
    )
    parser.add_argument("--backbone-weights", metavar="FILE", help="ImageNet weights of the backbone (safetensors)")
    parser.add_argument(
        "--cache",
        metavar="DIR",
        help="keep the rendered examples of a --fixed set here for later runs with the same settings and photos",
    )
    add_pixel_limit(parser)
    parser.set_defaults(func=run_train_global)
