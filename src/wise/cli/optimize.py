"""``wise optimize`` and ``wise transfer``: parametric style transfer into a results folder."""

from __future__ import annotations

import argparse
from typing import TextIO

from wise.cli import args as types
from wise.cli.outputs import OutputFolder
from wise.cli.parser import add_device, add_pixel_limit, add_size, device, exit_code, top_command
from wise.effects.catalogue import check_name, entry
from wise.files import MAX_PARAMS_BYTES, PARAMS_WHAT, regular_file
from wise.io import check_image_file
from wise.optimize.settings import (
    LOSSES,
    MASK_SOFT_GRADIENTS,
    MODES,
    NST_METHODS,
    PYRAMIDS,
    RESULT_FILES,
    TARGET_FILE,
    Settings,
    init_is_file,
)


def _settings(args: argparse.Namespace) -> Settings:
    return Settings(
        mode=args.mode,
        iterations=args.iters,
        lr=args.lr,
        loss=args.loss,
        tv_weight=args.tv,
        vgg_weights=args.vgg_weights,
        levels=args.levels,
        soft_gradients=args.soft_gradients,
    )


def _options(args: argparse.Namespace, out: TextIO) -> dict[str, object]:
    return {"size": args.size, "init": args.init, "seed": args.seed, "device": device(args.device), "out": out}


def _init_input(args: argparse.Namespace) -> str | None:
    return args.init if args.init is not None and init_is_file(args.init) else None


def _check_inputs(args: argparse.Namespace, images: tuple[str | None, ...]) -> None:
    """The images and ``--init`` as the run will find them (before PyTorch loads)."""
    for image in images:
        if image is not None:
            check_image_file(image)
    if args.init is not None:
        if init_is_file(args.init):
            regular_file(args.init, PARAMS_WHAT, MAX_PARAMS_BYTES)
        else:
            entry(args.effect).check_preset(args.init)


def run_optimize(args: argparse.Namespace, out: TextIO) -> int:
    check_name(args.effect)
    settings = _settings(args)
    inputs = {"--content": args.content, "--target": args.target, "--init": _init_input(args)}
    folder = OutputFolder(args.output, RESULT_FILES, inputs)
    _check_inputs(args, (args.content, args.target))
    from wise.optimize.run import run as run_optimization

    options = _options(args, out)
    with folder.guard():
        outcome = run_optimization(args.effect, args.content, args.target, args.output, settings, **options)
    return exit_code(outcome.interrupted)


def run_transfer_command(args: argparse.Namespace, out: TextIO) -> int:
    check_name(args.effect)
    settings = _settings(args)
    inputs = {"--content": args.content, "--style": args.style, "--init": _init_input(args)}
    folder = OutputFolder(args.output, (*RESULT_FILES, TARGET_FILE), inputs)
    _check_inputs(args, (args.content, args.style))
    from wise.optimize.run import transfer as run_transfer

    options = _options(args, out)
    with folder.guard():
        outcome = run_transfer(
            args.effect,
            args.content,
            args.output,
            settings,
            builtin_style=args.builtin_style,
            style_path=args.style,
            method=args.nst,
            **options,
        )
    return exit_code(outcome.interrupted)


def _add_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="folder for the results")
    parser.add_argument("--mode", choices=MODES, default="local", help="per-pixel masks (default) or global values")
    parser.add_argument(
        "--iters",
        type=types.iterations,
        default=Settings.iterations,
        metavar="N",
        help=f"iterations over all levels, 1 to {types.MAX_ITERATIONS:,} (default %(default)s)",
    )
    parser.add_argument("--lr", type=types.positive_rate, default=Settings.lr, help="Adam learning rate (default 0.1)")
    parser.add_argument(
        "--levels",
        type=int,
        choices=sorted(PYRAMIDS),
        default=Settings.levels,
        help="coarse-to-fine pyramid levels (default %(default)s; 1: every iteration at --size)",
    )
    parser.add_argument(
        "--loss",
        choices=LOSSES,
        default=Settings.loss,
        help="image loss (default l1-lab: L1 in RGB plus half of L1 in CIE Lab); nst needs VGG-19",
    )
    parser.add_argument("--vgg-weights", metavar="FILE", help="VGG-19 weights (safetensors) for --loss nst")
    parser.add_argument(
        "--soft-gradients",
        type=types.share,
        metavar="S",
        help="render the effect's steps exactly but pass their gradients through a ramp widened by S (0-1), "
        f"so that masks can take away ink the target lacks (default {MASK_SOFT_GRADIENTS} with --mode local, "
        "0 with global)",
    )
    parser.add_argument(
        "--tv", type=types.weight, default=0.0, metavar="W", help="total-variation weight on the masks (at least 0)"
    )
    add_size(parser, types.working_size, "the working resolution")
    parser.add_argument("--init", metavar="PRESET|FILE", help="start from a preset or a params file (resume)")
    parser.add_argument(
        "--seed", type=types.seed, default=0, help="seed of the effect's textures and of torch, 0 to 2**63-1"
    )
    add_device(parser)
    add_pixel_limit(parser)


def register(commands: argparse._SubParsersAction) -> None:
    opt = top_command(commands, "optimize")
    opt.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    opt.add_argument("--content", required=True, metavar="IMAGE", help="the photo to stylize")
    opt.add_argument("--target", required=True, metavar="IMAGE", help="the stylized reference to re-create")
    _add_options(opt)
    opt.set_defaults(func=run_optimize)

    transfer = top_command(commands, "transfer")
    transfer.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    transfer.add_argument("--content", required=True, metavar="IMAGE", help="the photo to stylize")
    style = transfer.add_mutually_exclusive_group(required=True)
    style.add_argument("--style", metavar="IMAGE", help="a style image (any painting or drawing)")
    style.add_argument(
        "--builtin-style", type=types.whole_number(0, 10_000), metavar="K", help="one of the built-in styles, 0 to 25"
    )
    transfer.add_argument(
        "--nst", choices=NST_METHODS, default="onnx", help="onnx networks (default) or gatys (needs VGG-19 weights)"
    )
    _add_options(transfer)
    transfer.set_defaults(func=run_transfer_command)
