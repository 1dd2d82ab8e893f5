"""``wise bench``: benchmarks (``recover``: the functional benchmark of the supplement;
``ppn``: global prediction; ``pairs``: local models on paired images)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, TextIO

from wise.cli import args as types
from wise.cli.outputs import output_file
from wise.cli.parser import add_device, add_pixel_limit, add_size, command, device, exit_code, top_command
from wise.effects.catalogue import NO_EFFECT, check_name
from wise.errors import WiseError
from wise.io import images_in
from wise.optimize.settings import DEFAULT_BUDGET, INIT_PPN, RECOVER_ITERATIONS, parse_init

if TYPE_CHECKING:
    from wise.train.evaluate import PerceptualMetrics

IMAGE_LOSSES = ("l1", "l2")
"""The losses the crop iterations take."""


def run_recover(args: argparse.Namespace, out: TextIO) -> int:
    check_name(args.effect)
    init_kind, model = parse_init(args.init)
    photos = images_in(args.images)
    from wise.optimize.benchmark import recover  # PyTorch
    from wise.ppn.modelfile import resolve_model

    if init_kind == INIT_PPN:
        resolve_model(model, args.effect, "global")
    inputs = {f"photo {path.name}": path for path in photos}
    output_file(args.json, {**inputs, "--init": model}, (".json",))
    result = recover(
        args.effect,
        args.images,
        args.trials,
        args.size,
        args.seed,
        args.iters,
        lr=args.lr,
        loss=args.loss,
        json_path=args.json,
        out=out,
        init=args.init,
        anneal=args.anneal,
    )
    return exit_code(result["interrupted"])


def run_ppn(args: argparse.Namespace, out: TextIO) -> int:
    check_name(args.effect)
    photos = images_in(args.images)
    from wise.optimize.ppn_benchmark import bench_ppn  # PyTorch
    from wise.ppn.modelfile import resolve_model

    resolve_model(args.model, args.effect, "global")
    inputs = {f"photo {path.name}": path for path in photos}
    output_file(args.json, {**inputs, "--model": args.model}, (".json",))
    result = bench_ppn(
        args.effect, args.images, args.model, args.trials, args.size, args.seed, args.json, device(args.device), out,
        refine_budget=args.refine, examples=args.examples,
    )  # fmt: skip
    return exit_code(result["interrupted"])


def _pairs_effect(args: argparse.Namespace) -> str:
    """The effect of ``--model``: named by the file, else by ``--effect`` or the pairs' task."""
    if args.effect == NO_EFFECT:
        return NO_EFFECT
    if args.effect is not None:
        check_name(args.effect)
        return args.effect
    from wise.ppn.modelfile import model_info  # PyTorch
    from wise.train.evaluate import pairs_task

    if not str(args.model).startswith("builtin:"):
        return model_info(args.model).effect
    task_effect = pairs_task(args.pairs).get("effect")
    if task_effect is None:
        raise WiseError(f"--model {args.model}: name the effect of the built-in model with --effect")
    return str(task_effect)


def _check_perceptual(args: argparse.Namespace) -> None:
    if (args.alexnet_weights or args.lpips_weights) and not args.lpips:
        raise WiseError("--alexnet-weights and --lpips-weights are for --lpips; add --lpips")
    if args.inception_weights and not args.fid:
        raise WiseError("--inception-weights is for --fid; add --fid")


def _perceptual(args: argparse.Namespace) -> PerceptualMetrics | None:
    """The networks of ``--fid`` and ``--lpips``, loaded from the user's weight files (refused
    before any work when a file is missing or wrong)."""
    if not (args.fid or args.lpips):
        return None
    from wise.fidelity import load_inception, load_lpips
    from wise.train.evaluate import PerceptualMetrics

    return PerceptualMetrics(
        inception=load_inception(args.inception_weights) if args.fid else None,
        lpips=load_lpips(args.alexnet_weights, args.lpips_weights) if args.lpips else None,
    )


def run_pairs(args: argparse.Namespace, out: TextIO) -> int:
    _check_perceptual(args)
    effect = _pairs_effect(args)
    from wise.ppn.modelfile import resolve_model  # PyTorch
    from wise.train.evaluate import bench_pairs, read_pairs

    path = resolve_model(args.model, effect, "local")
    pairs, _ = read_pairs(args.pairs)
    inputs = {f"pair {pair.name}": pair.photo for pair in pairs}
    output_file(args.json, {**inputs, "--model": path}, (".json",))
    if args.html is not None:
        output_file(args.html, {**inputs, "--model": path, "--json": args.json}, (".html",))
    perceptual = _perceptual(args)
    result = bench_pairs(
        args.model, effect, args.pairs, args.json, device(args.device), out, html_path=args.html, perceptual=perceptual
    )
    return exit_code(result["interrupted"])


def register(commands: argparse._SubParsersAction) -> None:
    bench = top_command(commands, "bench")
    benches = bench.add_subparsers(dest="bench", metavar="BENCHMARK", required=True, parser_class=type(bench))
    recover_parser = command(benches, "recover", "recover random global parameters by optimization")
    recover_parser.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    recover_parser.add_argument("--images", required=True, metavar="DIR", help="folder of photos")
    recover_parser.add_argument(
        "--trials", type=types.trials, default=10, metavar="N", help="number of trials (default 10)"
    )
    add_size(recover_parser, types.working_size, "the photos")
    recover_parser.add_argument("--seed", type=types.seed, default=0, help="seed of the random parameters")
    recover_parser.add_argument(
        "--iters",
        type=types.iterations,
        default=RECOVER_ITERATIONS,
        metavar="N",
        help=f"iterations per trial, all levels (default {RECOVER_ITERATIONS})",
    )
    recover_parser.add_argument(
        "--lr", type=types.positive_rate, default=0.1, help="learning rate of the coarsest level (default 0.1)"
    )
    recover_parser.add_argument("--loss", choices=IMAGE_LOSSES, default="l2", help="image loss (default l2)")
    recover_parser.add_argument("--json", required=True, metavar="OUT", help="write the results here (.json)")
    recover_parser.add_argument(
        "--init",
        default="defaults",
        metavar="defaults|ppn[:MODEL]",
        help="start from the defaults, or from the parameters a model predicts (default: defaults)",
    )
    recover_parser.add_argument(
        "--anneal",
        type=types.share,
        default=0.0,
        metavar="T",
        help="smooth the look's steps at temperature T (0-1) at first, sharpening them over the coarsest level",
    )
    add_pixel_limit(recover_parser)
    recover_parser.set_defaults(func=run_recover)

    ppn_parser = command(benches, "ppn", "predict random global parameters with a trained model")
    ppn_parser.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    ppn_parser.add_argument("--images", required=True, metavar="DIR", help="folder of photos")
    ppn_parser.add_argument(
        "--model", metavar="FILE", help="a model of 'wise train global' (default: the built-in one)"
    )
    ppn_parser.add_argument(
        "--trials", type=types.trials, default=20, metavar="N", help="number of trials (default 20)"
    )
    add_size(ppn_parser, types.working_size, "the photos")
    ppn_parser.add_argument("--seed", type=types.seed, default=0, help="seed of the random parameters")
    ppn_parser.add_argument("--json", required=True, metavar="OUT", help="write the results here (.json)")
    ppn_parser.add_argument(
        "--refine",
        type=types.positive_seconds,
        metavar="SECONDS",
        help=f"also refine each prediction for SECONDS as 'wise predict' does (its default: {DEFAULT_BUDGET:g})",
    )
    ppn_parser.add_argument(
        "--examples",
        choices=("random", "presets", "both"),
        default="both",
        help="examples with random parameters, made from the presets with one to three parameters moved "
        "far (as users make them), or both (default)",
    )
    add_device(ppn_parser)
    add_pixel_limit(ppn_parser)
    ppn_parser.set_defaults(func=run_ppn)

    pairs_parser = command(benches, "pairs", "measure a local model on paired images against their targets")
    pairs_parser.add_argument(
        "--model", required=True, metavar="FILE", help="a model of 'wise train local', or builtin:TASK"
    )
    pairs_parser.add_argument(
        "--pairs",
        required=True,
        metavar="DIR",
        help="a folder with A/ and B/ (and regions/ for adaptive tasks), or a pairs folder (its test/ is measured)",
    )
    pairs_parser.add_argument("--json", required=True, metavar="OUT", help="write the results here (.json)")
    pairs_parser.add_argument(
        "--html",
        metavar="PAGE",
        help="also write a results page (.html): photo, effect stage, result, ground truth and masks of the first "
        "pairs",
    )
    perceptual = pairs_parser.add_argument_group(
        "perceptual metrics (weights are never downloaded: pass safetensors files or place them in ~/.cache/wise)"
    )
    perceptual.add_argument("--fid", action="store_true", help="FID of the results against the targets")
    perceptual.add_argument(
        "--inception-weights",
        metavar="FILE",
        help="pytorch-fid's Inception weights (pt_inception-2015-12-05) as safetensors",
    )
    perceptual.add_argument("--lpips", action="store_true", help="LPIPS (AlexNet, v0.1) of each result and target")
    perceptual.add_argument("--alexnet-weights", metavar="FILE", help="torchvision's AlexNet weights as safetensors")
    perceptual.add_argument(
        "--lpips-weights", metavar="FILE", help="the LPIPS linear layers (alex.pth of lpips v0.1) as safetensors"
    )
    pairs_parser.add_argument(
        "--effect", help="the effect of a built-in model (default: the pairs' task's); a model file names its own"
    )
    add_device(pairs_parser)
    add_pixel_limit(pairs_parser)
    pairs_parser.set_defaults(func=run_pairs)
