"""``wise apply`` and ``wise gallery``: render effects on images."""

from __future__ import annotations

import argparse
import math
from typing import TextIO

import numpy as np

from wise import effects
from wise.cli import args as types
from wise.cli.effects import fmt
from wise.cli.outputs import output_file
from wise.cli.parser import add_device, add_pixel_limit, add_size, command, device
from wise.effects.base import Effect
from wise.errors import WiseError
from wise.gallery import make_sheet
from wise.io import WRITE_FORMATS, image_to_tensor, read_image, write_image
from wise.paramfile import load_params
from wise.ppn.predictor import LocalPredictor
from wise.render import render


def parse_set(item: str, effect: Effect) -> tuple[int, float]:
    """``NAME=VALUE`` in real units to (parameter index, normalized value)."""
    name, sep, text = item.partition("=")
    name, text = name.strip(), text.strip()
    if not sep or not name or not text:
        raise WiseError(f"--set {item!r}: expected NAME=VALUE, e.g. --set {effect.param_names[0]}=0")
    spec = effect.spec(name)
    try:
        value = float(text)
    except ValueError:
        raise WiseError(f"--set {name}={text}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise WiseError(f"--set {name}={text}: the value must be a finite number")
    if not spec.in_range(value):
        raise WiseError(f"--set {name}={text}: outside the range [{fmt(spec.min)}, {fmt(spec.max)}] of {name}")
    return effect.param_names.index(name), spec.to_normalized(value)


def run_apply(args: argparse.Namespace, out: TextIO) -> int:
    if args.params and args.preset:
        raise WiseError("--params and --preset cannot be combined; edit the file's values with --set instead")
    options: dict[str, object] = {}
    if args.kernel_size is not None:
        options["kernel_size"] = args.kernel_size
    effect = effects.create(args.effect, **options)
    if args.params:
        params = load_params(args.params, effect)
    elif args.preset:
        params = effect.preset(args.preset).unsqueeze(0)
    else:
        params = effect.default_params().unsqueeze(0)
    params = params.clone()
    for index, value in (parse_set(item, effect) for item in args.set):
        params[:, index] = value
    output = output_file(
        args.output, {"image": args.input, "--params": args.params, "--model": args.model}, WRITE_FORMATS
    )
    target_device = device(args.device)
    translator = _translator(args, target_device)
    image = read_image(args.input)
    if translator is not None:
        result = translator.finish(image, params).result
    else:
        result = render(effect.to(target_device).eval(), image, params, device=target_device)
    write_image(result, output, quality=args.quality)
    return 0


def _translator(args: argparse.Namespace, target_device: str) -> LocalPredictor | None:
    """The model of ``--model``: a translator of the effect with a CNN after it."""
    if args.model is None:
        return None
    predictor = LocalPredictor(args.model, args.effect, target_device)
    if not predictor.translates or predictor.network.post is None:
        raise WiseError(
            f"--model {args.model}: not a model with a CNN after the effect; apply its masks with --params alone"
        )
    return predictor


def run_gallery(args: argparse.Namespace, out: TextIO) -> int:
    names = args.effects or effects.available()
    for name in names:
        effects.create(name)  # unknown names fail before any work
    output = output_file(args.output, {"image": args.input}, WRITE_FORMATS)
    target_device = device(args.device)
    image = read_image(args.input)

    def report(effect: str, preset: str, seconds: float) -> None:
        print(f"{effect:10s} {preset:12s} {seconds:6.2f} s", file=out, flush=True)

    sheet = make_sheet(image, args.size, names, target_device, progress=report)
    write_image(image_to_tensor(np.asarray(sheet)), output)
    print(f"wrote {output}", file=out)
    return 0


def register(commands: argparse._SubParsersAction) -> None:
    apply = command(commands, "apply", "stylize an image with an effect")
    apply.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    apply.add_argument("input", metavar="INPUT", help="input image (PNG, JPEG, WebP or TIFF)")
    apply.add_argument("-o", "--output", required=True, metavar="OUTPUT", help="output image (.png, .jpg or .jpeg)")
    apply.add_argument("--preset", metavar="NAME", help="start from this preset instead of the defaults")
    apply.add_argument("--params", metavar="FILE", help="start from a parameter file (global or local masks)")
    apply.add_argument(
        "--model",
        metavar="FILE",
        help="a model of 'wise train local --post': run its CNN after the effect (at the model's working size), "
        "e.g. on masks it painted and you edited",
    )
    apply.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a parameter in real units (repeatable); with local masks it sets the whole mask",
    )
    add_device(apply)
    apply.add_argument(
        "--kernel-size",
        type=types.kernel_size,
        metavar="D",
        help=f"filter samples per side, 1 to {types.MAX_KERNEL_SIZE} (quality/speed)",
    )
    apply.add_argument("--quality", type=types.quality, default=95, metavar="Q", help="JPEG quality 1-100 (default 95)")
    add_pixel_limit(apply)
    apply.set_defaults(func=run_apply)

    gallery = command(commands, "gallery", "every effect and preset on one labelled contact sheet")
    gallery.add_argument("input", metavar="INPUT", help="input image (PNG, JPEG, WebP or TIFF)")
    gallery.add_argument("-o", "--output", required=True, metavar="SHEET", help="output sheet (.png or .jpg)")
    add_size(gallery, types.cell_size, "each cell")
    gallery.add_argument("--effects", nargs="+", metavar="EFFECT", help="only these effects")
    add_device(gallery)
    add_pixel_limit(gallery)
    gallery.set_defaults(func=run_gallery)
