"""``wise train global``: train a global parameter prediction network on a folder of photos.
``wise train local``: train a local one (parameter masks from the photo) on paired images.

Lightning is imported only when a run starts, so other commands start quickly.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import TextIO

from wise.cli import args as types
from wise.cli.outputs import OutputFolder
from wise.cli.parser import add_pixel_limit, command, exit_code, top_command
from wise.effects.catalogue import NO_EFFECT, check_name
from wise.errors import WiseError
from wise.ppn.choices import ARCHITECTURE_NAMES, NO_POST, POST_KINDS, POST_WIDTH, PPN_KINDS
from wise.train.choices import (
    DIRECTIONS,
    GAN_LOSSES,
    LOSSES,
    LR_SCHEDULES,
    MIXTURE_PRESET_SHARE,
    PROCEDURAL_SHARE,
    SAMPLINGS,
)

ACCELERATORS = ("auto", "cpu", "gpu", "cuda", "mps")
RUN_FILES = ("model.safetensors", "report.html", "settings.json")
DEFAULT_STEPS = 1000
DEFAULT_WINDOW = 128
"""Training windows of the whole picture's pixels (rendering, the cost of training, grows with their area)."""


def _check_accelerator(name: str) -> None:
    if name not in ("gpu", "cuda", "mps"):
        return
    import torch

    if name in ("gpu", "cuda") and not torch.cuda.is_available():
        raise WiseError(f"--accelerator {name}: CUDA is not available here; use --accelerator cpu")
    if name == "mps" and not torch.backends.mps.is_available():
        raise WiseError("--accelerator mps: MPS is not available here; use --accelerator cpu")


def _engine_settings(args: argparse.Namespace) -> dict:
    """The settings of the options both kinds of training share (:func:`_add_engine`, ``--anneal``)."""
    names = (
        "anneal",
        "soft_gradients",
        "workers",
        "accelerator",
        "devices",
        "num_nodes",
        "seed",
        "half",
        "checkpoint_every",
    )
    return {name: getattr(args, name) for name in names}


def run_train_global(args: argparse.Namespace, out: TextIO) -> int:
    check_name(args.effect)
    _check_accelerator(args.accelerator)
    for option, folder in (("--images", args.images), ("--val-images", args.val_images)):
        if folder is not None and not Path(folder).is_dir():
            raise WiseError(f"{option} {folder}: not a directory of photos")
    if args.backbone_weights is not None and args.arch in ("simple", "stats", "tone"):
        raise WiseError(
            f"--backbone-weights: the {args.arch!r} architecture has no ImageNet backbone; use resnet or multifeature"
        )
    run_folder = OutputFolder(args.output, RUN_FILES, {"--backbone-weights": args.backbone_weights})
    if args.cache is not None:
        if not args.fixed:
            raise WiseError("--cache keeps a fixed set of examples; pass --fixed too, or leave --cache out")
        OutputFolder(args.cache, (), {})
    from wise.train.settings import TrainSettings, prepare  # PyTorch

    settings = TrainSettings(
        effect=args.effect,
        images=args.images,
        architecture=args.arch,
        loss=args.loss,
        param_weight=args.param_weight,
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
        lr_schedule=args.lr_schedule,
        val_images=args.val_images,
        backbone_weights=args.backbone_weights,
        cache=args.cache,
        **_engine_settings(args),
    )
    photos = prepare(settings, Path(args.output), args.resume)
    from wise.train.run import train_global  # Lightning

    _quiet_lightning()
    with run_folder.guard():
        summary = train_global(settings, args.output, resume=args.resume, out=out, photos=photos)
    return exit_code(summary["interrupted"])


def _quiet_lightning() -> None:
    for name in ("lightning.pytorch", "lightning.fabric"):
        logging.getLogger(name).setLevel(logging.WARNING)


def run_train_local(args: argparse.Namespace, out: TextIO) -> int:
    if args.effect != NO_EFFECT:
        check_name(args.effect)
    _check_accelerator(args.accelerator)
    if not Path(args.pairs).is_dir():
        raise WiseError(f"--pairs {args.pairs}: not a directory of pairs (train/ and test/)")
    run_folder = OutputFolder(args.output, RUN_FILES, {})
    from wise.train.local_settings import LocalSettings, prepare_local  # PyTorch

    settings = LocalSettings(
        effect=args.effect,
        pairs=args.pairs,
        start=args.start,
        init=args.init,
        depth=args.depth,
        width=args.width,
        max_width=args.max_width,
        discriminator_width=args.discriminator_width,
        gan_loss=args.gan_loss,
        gan_weight=args.gan_weight,
        l1_weight=args.l1_weight,
        tv_weight=args.tv_weight,
        preset_weight=args.preset_weight,
        lr=args.lr,
        lr_schedule=args.lr_schedule,
        batch=args.batch,
        steps=None if args.epochs is not None else (args.steps or DEFAULT_STEPS),
        epochs=args.epochs,
        load_size=args.load_size,
        crop_size=args.crop_size,
        flip=not args.no_flip,
        direction=args.direction,
        post=args.post,
        post_width=args.post_width,
        ppn=args.ppn,
        dropout=args.dropout,
        **_engine_settings(args),
    )
    pairs = prepare_local(settings, Path(args.output), args.resume)
    from wise.train.local_run import train_local  # Lightning

    _quiet_lightning()
    with run_folder.guard():
        summary = train_local(settings, args.output, resume=args.resume, out=out, pairs=pairs)
    return exit_code(summary["interrupted"])


def _add_length(parser: argparse.ArgumentParser) -> None:
    length = parser.add_mutually_exclusive_group()
    length.add_argument("--steps", type=types.iterations, metavar="N", help=f"training steps (default {DEFAULT_STEPS})")
    length.add_argument("--epochs", type=types.iterations, metavar="N", help="passes over the training data instead")


def _add_engine(parser: argparse.ArgumentParser) -> None:
    """Where and how a run trains, and how it is resumed: the options both kinds share."""
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
    parser.add_argument(
        "--workers",
        type=types.whole_number(0, 64),
        default=0,
        metavar="N",
        help="processes that prepare the training data while the steps run (default 0: the training process)",
    )


def _add_anneal(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--anneal",
        type=types.share,
        default=0.0,
        metavar="T",
        help="smooth the effect's steps (XDoG threshold, quantization) at temperature T (0-1) at first, "
        "sharpening them by the middle of the run (default 0: never)",
    )
    parser.add_argument(
        "--soft-gradients",
        type=types.share,
        default=0.0,
        metavar="S",
        help="render the effect's steps exactly but pass their gradients through a ramp widened by S (0-1), "
        "so that pixels on the flat side of the XDoG threshold still move the masks (default 0: exact gradients)",
    )


def _register_local(kinds: argparse._SubParsersAction) -> None:
    parser = command(
        kinds, "local", "train a network that paints an effect's parameter masks from the photo (paired images)"
    )
    parser.add_argument(
        "effect", metavar="EFFECT", help="effect name (see 'wise effects'), or none for a CNN alone (with --post)"
    )
    parser.add_argument(
        "--pairs",
        required=True,
        metavar="DIR",
        help="paired images: DIR/train and DIR/test, each with A/ (photos) and B/ (targets) or side-by-side AB images",
    )
    parser.add_argument("-o", "--output", required=True, metavar="RUNDIR", help="folder of the run")
    parser.add_argument(
        "--start", metavar="PRESET", help="preset the untrained network paints (default: the pairs' task preset)"
    )
    parser.add_argument(
        "--init",
        metavar="MODEL",
        help="start from the weights of a local model of the effect (file or builtin:TASK) to fine-tune it",
    )
    network = parser.add_argument_group("networks")
    network.add_argument("--depth", type=types.whole_number(2, 9), default=6, help="U-Net levels (default 6)")
    network.add_argument(
        "--width", type=types.whole_number(1, 512), default=16, help="channels of its first level (16)"
    )
    network.add_argument(
        "--max-width", type=types.whole_number(1, 1024), default=64, help="most channels of a level (64)"
    )
    network.add_argument(
        "--ppn",
        choices=PPN_KINDS,
        default="local",
        help="local: a U-Net paints the parameter masks (default); preset: the effect runs at the start preset",
    )
    network.add_argument(
        "--post",
        choices=POST_KINDS,
        default=NO_POST,
        help="CNN after the effect (image-to-image translation): resnet (Johnson et al.), unet (pix2pix); default none",
    )
    network.add_argument(
        "--post-width",
        type=types.whole_number(1, 512),
        default=POST_WIDTH,
        metavar="N",
        help=f"channels of the CNN's first layer (pix2pix: {POST_WIDTH})",
    )
    network.add_argument("--dropout", action="store_true", help="pix2pix's dropout in the CNN while training")
    network.add_argument(
        "--discriminator-width",
        type=types.whole_number(1, 512),
        default=64,
        metavar="N",
        help="channels of the PatchGAN's first layer (pix2pix: 64)",
    )
    losses = parser.add_argument_group("loss: α·GAN + β·L1 + γ·TV(masks) + δ·|masks - preset|")
    losses.add_argument("--gan-loss", choices=GAN_LOSSES, default="vanilla", help="GAN loss (default vanilla)")
    losses.add_argument(
        "--gan-weight", type=types.weight, default=1.0, metavar="α", help="0 trains without a discriminator (1)"
    )
    losses.add_argument("--l1-weight", type=types.weight, default=100.0, metavar="β", help="L1 to the targets (100)")
    losses.add_argument(
        "--tv-weight", type=types.weight, default=1.0, metavar="γ", help="total variation of the masks (1)"
    )
    losses.add_argument(
        "--preset-weight",
        type=types.weight,
        default=0.0,
        metavar="δ",
        help="L1 of the masks to the start preset: they depart from it only where the targets need it (0)",
    )
    parser.add_argument("--lr", type=types.positive_rate, default=2e-4, help="Adam learning rate (default 0.0002)")
    parser.add_argument(
        "--lr-schedule",
        choices=LR_SCHEDULES,
        default="linear",
        help="linear: constant, then falling to 0 over the second half (pix2pix; default); constant; cosine",
    )
    parser.add_argument("--batch", type=types.batch, default=1, metavar="B", help="pairs per step and process (1)")
    _add_length(parser)
    parser.add_argument(
        "--load-size",
        type=types.working_size,
        default=286,
        metavar="PX",
        help="short side the pairs are resized to before cropping (default 286)",
    )
    parser.add_argument(
        "--crop-size", type=types.working_size, default=256, metavar="PX", help="side of the random crops (256)"
    )
    parser.add_argument("--no-flip", action="store_true", help="no random horizontal flips")
    parser.add_argument(
        "--direction", choices=DIRECTIONS, default="AtoB", help="AtoB: A is the photo (default); BtoA swaps"
    )
    _add_anneal(parser)
    _add_engine(parser)
    add_pixel_limit(parser)
    parser.set_defaults(func=run_train_local)


def register(commands: argparse._SubParsersAction) -> None:
    train = top_command(commands, "train")
    kinds = train.add_subparsers(dest="kind", metavar="KIND", required=True, parser_class=type(train))
    _register_local(kinds)
    parser = command(kinds, "global", "train a network that predicts an effect's global parameters from an example")
    parser.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    parser.add_argument(
        "--images", required=True, metavar="DIR", help="folder of training photos (searched recursively)"
    )
    parser.add_argument("-o", "--output", required=True, metavar="RUNDIR", help="folder of the run")
    parser.add_argument("--arch", choices=ARCHITECTURE_NAMES, default="simple", help="network (default simple)")
    parser.add_argument("--loss", choices=LOSSES, default="image-l1", help="loss (default image-l1)")
    parser.add_argument(
        "--param-weight",
        type=types.weight,
        default=0.0,
        metavar="W",
        help="add W times the parameter L1 to an image-space loss, for parameters the look leaves ambiguous "
        "(default 0)",
    )
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
    _add_length(parser)
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
    _add_anneal(parser)
    parser.add_argument(
        "--no-augment", action="store_true", help="no flips, turns or tone jitter of the training pictures"
    )
    parser.add_argument("--val-images", metavar="DIR", help="validation photos (default: 15%% of --images held out)")
    _add_engine(parser)
    parser.add_argument("--backbone-weights", metavar="FILE", help="ImageNet weights of the backbone (safetensors)")
    parser.add_argument(
        "--cache",
        metavar="DIR",
        help="keep the rendered examples of a --fixed set here for later runs with the same settings and photos",
    )
    add_pixel_limit(parser)
    parser.set_defaults(func=run_train_global)
