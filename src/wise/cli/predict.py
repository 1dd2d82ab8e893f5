"""``wise predict``: global parameters from a photo and an example (a network's prediction,
refined within a time budget), or parameter masks from the photo alone (a local model)."""

from __future__ import annotations

import argparse
from typing import TextIO

from wise.cli import args as types
from wise.cli.outputs import OutputFolder
from wise.cli.parser import add_device, add_pixel_limit, device, exit_code, top_command
from wise.effects.catalogue import NO_EFFECT, check_name
from wise.errors import WiseError
from wise.io import check_image_file
from wise.optimize.settings import DEFAULT_BUDGET, MODES


def run_predict(args: argparse.Namespace, out: TextIO) -> int:
    if args.effect == NO_EFFECT:
        if args.model is None:
            raise WiseError("the effect 'none' is a CNN alone: pass its --model (of 'wise train local none')")
    else:
        check_name(args.effect)
    for image in (args.content, args.target):
        if image is not None:
            check_image_file(image)
    from wise.ppn.modelfile import model_info, model_path
    from wise.predict import MASKS_FILE, PREDICTED_FILE, RESULT_FILES, STAGE_FILE, predict_files, predict_local_files

    path = model_path(args.model, args.effect)
    kind = model_info(path, args.effect).kind
    model = None if args.model is None else str(path)
    if kind == "local":
        if args.target is not None:
            raise WiseError(f"{args.model}: a local model paints the masks from the photo alone; leave out --target")
        files = (*RESULT_FILES, MASKS_FILE, STAGE_FILE)
        folder = OutputFolder(args.output, files, {"--content": args.content, "--model": model})
        with folder.guard():
            scores = predict_local_files(
                args.effect, args.content, args.output, args.model, device=device(args.device), out=out
            )
        return exit_code(bool(scores.get("interrupted")))
    if args.target is None:
        raise WiseError("--target is required: a global model re-creates a stylized example of the photo")
    files = (*RESULT_FILES, PREDICTED_FILE)
    inputs = {"--content": args.content, "--target": args.target, "--model": model}
    folder = OutputFolder(args.output, files, inputs)
    with folder.guard():
        scores = predict_files(
            args.effect,
            args.content,
            args.target,
            args.output,
            model=args.model,
            refine_budget=None if args.refine == 0 else args.budget,
            max_iterations=args.refine,
            refine_mode=args.mode,
            device=device(args.device),
            out=out,
        )
    return exit_code(bool(scores.get("interrupted")))


def register(commands: argparse._SubParsersAction) -> None:
    parser = top_command(commands, "predict")
    parser.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects'); none for a CNN-only model")
    parser.add_argument("--content", required=True, metavar="IMAGE", help="the photo")
    parser.add_argument(
        "--target", metavar="IMAGE", help="the stylized example of it (global models; a local model takes none)"
    )
    parser.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="folder for the results")
    parser.add_argument(
        "--model",
        metavar="FILE",
        help="a model of 'wise train global' or 'wise train local', or builtin:TASK for a built-in local model "
        "(default: the built-in global model)",
    )
    parser.add_argument(
        "--budget",
        type=types.positive_seconds,
        default=DEFAULT_BUDGET,
        metavar="SECONDS",
        help=f"time for refining the prediction by optimization (default {DEFAULT_BUDGET:g})",
    )
    parser.add_argument(
        "--refine",
        type=types.whole_number(0, types.MAX_ITERATIONS),
        metavar="N",
        help="at most N iterations of refinement (default: as many as --budget allows; 0: the network alone)",
    )
    parser.add_argument("--mode", choices=MODES, default="global", help="what --refine optimizes (default global)")
    add_device(parser)
    add_pixel_limit(parser)
    parser.set_defaults(func=run_predict)
