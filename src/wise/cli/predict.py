"""``wise predict``: global parameters from a photo and an example: a network's prediction,
refined within a time budget."""

from __future__ import annotations

import argparse
from typing import TextIO

from wise import effects
from wise.cli import args as types
from wise.cli.outputs import OutputFolder
from wise.cli.parser import add_device, add_pixel_limit, command, device, exit_code
from wise.optimize.parametric import MODES
from wise.optimize.refine import DEFAULT_BUDGET
from wise.ppn.modelfile import resolve_model
from wise.predict import PREDICTED_FILE, RESULT_FILES, predict_files


def run_predict(args: argparse.Namespace, out: TextIO) -> int:
    effects.create(args.effect)
    resolve_model(args.model, args.effect)
    files = (*RESULT_FILES, PREDICTED_FILE)
    inputs = {"--content": args.content, "--target": args.target, "--model": args.model}
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
    parser = command(commands, "predict", "predict the global parameters that re-create an example")
    parser.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    parser.add_argument("--content", required=True, metavar="IMAGE", help="the photo")
    parser.add_argument("--target", required=True, metavar="IMAGE", help="the stylized example of it")
    parser.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="folder for the results")
    parser.add_argument("--model", metavar="FILE", help="a model of 'wise train global' (default: the built-in one)")
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
