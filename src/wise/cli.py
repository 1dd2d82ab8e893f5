"""The ``wise`` command: list effects and apply them to images.

Bad input (unknown names, malformed or out-of-range values, unreadable files,
unwritable outputs) prints one line ``wise: error: ...`` on stderr and exits
with code 2, leaving no output file behind.
"""

from __future__ import annotations

import argparse
import inspect
import math
import os
import sys
from pathlib import Path
from typing import NoReturn, Sequence, TextIO

import numpy as np
import torch

from wise import __version__, effects
from wise.editor.server import LOOPBACK, initial_session, serve
from wise.effects.base import Effect
from wise.errors import WiseError
from wise.gallery import make_sheet
from wise.io import WRITE_FORMATS, image_to_tensor, read_image, write_image
from wise.optimize.benchmark import recover as recover_parameters
from wise.optimize.parametric import LOSSES, MODES, PYRAMIDS, Settings
from wise.optimize.run import NST_METHODS
from wise.optimize.run import run as run_optimization
from wise.optimize.run import transfer as run_transfer
from wise.paramfile import load_params
from wise.render import render

PROG = "wise"
EXIT_USAGE = 2
OUTSIDE_NOTE = "outside the declared range; rendered as authored"


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are a single ``wise: error:`` line."""

    def error(self, message: str) -> NoReturn:
        hint = f" (see '{self.prog} --help')"
        self.exit(EXIT_USAGE, f"{PROG}: error: {_one_line(message)}{hint}\n")


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _fmt(value: float) -> str:
    return f"{value:.6g}"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``wise`` command."""
    parser = _Parser(
        prog=PROG, description="Whitebox image stylization: differentiable effects with editable parameters."
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    show = commands.add_parser("effects", help="list effects, their parameters and presets")
    show.add_argument("effect", nargs="?", metavar="EFFECT", help="show this effect only")
    show.set_defaults(func=_cmd_effects)

    apply = commands.add_parser("apply", help="stylize an image with an effect")
    apply.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    apply.add_argument("input", metavar="INPUT", help="input image (PNG, JPEG, WebP or TIFF)")
    apply.add_argument("-o", "--output", required=True, metavar="OUTPUT", help="output image (.png, .jpg or .jpeg)")
    apply.add_argument("--preset", metavar="NAME", help="start from this preset instead of the defaults")
    apply.add_argument("--params", metavar="FILE", help="start from a parameter file (global or local masks)")
    apply.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a parameter in real units (repeatable); with local masks it sets the whole mask",
    )
    apply.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="default: cuda if available")
    apply.add_argument("--kernel-size", type=int, metavar="D", help="filter samples per side (quality/speed)")
    apply.add_argument("--quality", type=int, default=95, metavar="Q", help="JPEG quality 1-100 (default 95)")
    apply.set_defaults(func=_cmd_apply)

    gallery = commands.add_parser("gallery", help="every effect and preset on one labelled contact sheet")
    gallery.add_argument("input", metavar="INPUT", help="input image (PNG, JPEG, WebP or TIFF)")
    gallery.add_argument("-o", "--output", required=True, metavar="SHEET", help="output sheet (.png or .jpg)")
    gallery.add_argument("--size", type=int, default=512, metavar="PX", help="short side of each cell (default 512)")
    gallery.add_argument("--effects", nargs="+", metavar="EFFECT", help="only these effects")
    gallery.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="default: cuda if available")
    gallery.set_defaults(func=_cmd_gallery)

    opt = commands.add_parser("optimize", help="optimize parameters so that an effect re-creates a target image")
    opt.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    opt.add_argument("--content", required=True, metavar="IMAGE", help="the photo to stylize")
    opt.add_argument("--target", required=True, metavar="IMAGE", help="the stylized reference to re-create")
    _add_optimization_options(opt)
    opt.set_defaults(func=_cmd_optimize)

    transfer = commands.add_parser("transfer", help="neural style transfer, then re-create it with an effect")
    transfer.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    transfer.add_argument("--content", required=True, metavar="IMAGE", help="the photo to stylize")
    style = transfer.add_mutually_exclusive_group(required=True)
    style.add_argument("--style", metavar="IMAGE", help="a style image (any painting or drawing)")
    style.add_argument("--builtin-style", type=int, metavar="K", help="one of the built-in styles, 0 to 25")
    transfer.add_argument(
        "--nst", choices=NST_METHODS, default="onnx", help="onnx networks (default) or gatys (needs VGG-19 weights)"
    )
    _add_optimization_options(transfer)
    transfer.set_defaults(func=_cmd_transfer)

    edit = commands.add_parser("edit", help="the web editor: paint parameter masks and see the result")
    edit.add_argument("image", nargs="?", metavar="IMAGE", help="content image to open")
    start = edit.add_mutually_exclusive_group()
    start.add_argument("--params", metavar="FILE", help="parameter file to edit (from wise optimize or the editor)")
    start.add_argument("--effect", metavar="EFFECT", help="start from this effect's global values")
    edit.add_argument("--preset", metavar="NAME", help="with --effect: start from this preset")
    edit.add_argument("--host", default=LOOPBACK, help=f"address to listen on (default {LOOPBACK}: this machine only)")
    edit.add_argument("--port", type=int, default=8000, help="port to listen on (default 8000)")
    edit.set_defaults(func=_cmd_edit)

    bench = commands.add_parser("bench", help="benchmarks")
    benches = bench.add_subparsers(dest="bench", metavar="BENCHMARK", required=True)
    recover = benches.add_parser("recover", help="recover random global parameters by optimization")
    recover.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects')")
    recover.add_argument("--images", required=True, metavar="DIR", help="folder of photos")
    recover.add_argument("--trials", type=int, default=10, metavar="N", help="number of trials (default 10)")
    recover.add_argument("--size", type=int, default=512, metavar="PX", help="short side of the photos (default 512)")
    recover.add_argument("--seed", type=int, default=0, help="seed of the random parameters")
    recover.add_argument("--iters", type=int, default=300, metavar="N", help="iterations per trial, all levels")
    recover.add_argument("--lr", type=float, default=0.1, help="learning rate of the coarsest level (default 0.1)")
    recover.add_argument("--loss", choices=LOSSES, default="l2", help="image loss (default l2)")
    recover.add_argument("--json", required=True, metavar="OUT", help="write the results here")
    recover.set_defaults(func=_cmd_bench_recover)
    return parser


def _add_optimization_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="folder for the results")
    parser.add_argument("--mode", choices=MODES, default="local", help="per-pixel masks (default) or global values")
    parser.add_argument("--iters", type=int, default=Settings.iterations, metavar="N", help="iterations")
    parser.add_argument("--lr", type=float, default=Settings.lr, help="Adam learning rate (default 0.1)")
    parser.add_argument(
        "--levels",
        type=int,
        choices=sorted(PYRAMIDS),
        default=Settings.levels,
        help="coarse-to-fine pyramid levels (default %(default)s; 1: every iteration at --size)",
    )
    parser.add_argument("--loss", choices=LOSSES, default="l1", help="image loss (default l1); nst needs VGG-19")
    parser.add_argument("--vgg-weights", metavar="FILE", help="VGG-19 weights (safetensors) for --loss nst")
    parser.add_argument("--tv", type=float, default=0.0, metavar="W", help="total-variation weight on the masks")
    parser.add_argument("--size", type=int, default=512, metavar="PX", help="short side of the working resolution")
    parser.add_argument("--init", metavar="PRESET|FILE", help="start from a preset or a params file (resume)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the effect's textures and of torch")
    parser.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="default: cuda if available")


def _effect_table(effect: Effect) -> list[str]:
    doc = inspect.getdoc(type(effect)) or ""
    title = doc.splitlines()[0] if doc else ""
    lines = [f"{effect.name}: {title}" if title else effect.name, "  parameters:"]
    rows = [
        (s.name, f"[{_fmt(s.min)}, {_fmt(s.max)}]", f"default {_fmt(s.default)}", s.description)
        for s in effect.param_specs
    ]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    for row in rows:
        cells = [row[i].ljust(widths[i]) for i in range(3)]
        lines.append(("    " + "  ".join(cells) + "  " + row[3]).rstrip())
    outside = False
    if effect.presets:
        lines.append("  presets:")
        width = max(len(n) for n in effect.presets)
        for name, preset in effect.presets.items():
            values = []
            for spec in effect.param_specs:
                value = float(preset.get(spec.name, spec.default))
                mark = "" if spec.in_range(value) else "*"
                outside = outside or bool(mark)
                values.append(f"{spec.name}={_fmt(value)}{mark}")
            lines.append(f"    {name.ljust(width)}  {' '.join(values)}")
    if outside:
        lines.append(f"  * {OUTSIDE_NOTE}")
    return lines


def _cmd_effects(args: argparse.Namespace, out: TextIO) -> int:
    names = [args.effect] if args.effect else effects.available()
    blocks = ["\n".join(_effect_table(effects.create(name))) for name in names]
    print("\n\n".join(blocks), file=out)
    return 0


def _device(name: str) -> torch.device:
    if name == "cuda" and not torch.cuda.is_available():
        raise WiseError("--device cuda: CUDA is not available; use --device cpu")
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def _parse_set(item: str, effect: Effect) -> tuple[int, float]:
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
        raise WiseError(f"--set {name}={text}: outside the range [{_fmt(spec.min)}, {_fmt(spec.max)}] of {name}")
    return effect.param_names.index(name), spec.to_normalized(value)


def _check_output(path: Path) -> None:
    if path.suffix.lower() not in WRITE_FORMATS:
        raise WiseError(
            f"{path}: cannot write {path.suffix or 'files without an extension'}; "
            f"supported extensions: {', '.join(WRITE_FORMATS)}"
        )
    if path.is_dir():
        raise WiseError(f"{path}: is a directory")
    directory = path.parent
    if not directory.is_dir():
        raise WiseError(f"{path}: the directory {directory} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise WiseError(f"{path}: the directory {directory} is not writable")


def _cmd_apply(args: argparse.Namespace, out: TextIO) -> int:
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
    for index, value in (_parse_set(item, effect) for item in args.set):
        params[:, index] = value
    if not 1 <= args.quality <= 100:
        raise WiseError(f"--quality must be from 1 to 100, got {args.quality}")
    output = Path(args.output)
    _check_output(output)
    device = _device(args.device)
    image = read_image(args.input)
    result = render(effect.to(device).eval(), image, params, device=device)
    write_image(result, output, quality=args.quality)
    return 0


def _cmd_gallery(args: argparse.Namespace, out: TextIO) -> int:
    if args.size < 16:
        raise WiseError(f"--size must be at least 16 pixels, got {args.size}")
    names = args.effects or effects.available()
    for name in names:
        effects.create(name)  # unknown names fail before any work
    output = Path(args.output)
    _check_output(output)
    device = _device(args.device)
    image = read_image(args.input)

    def report(effect: str, preset: str, seconds: float) -> None:
        print(f"{effect:10s} {preset:12s} {seconds:6.2f} s", file=out, flush=True)

    sheet = make_sheet(image, args.size, names, device, progress=report)
    write_image(image_to_tensor(np.asarray(sheet)), output)
    print(f"wrote {output}", file=out)
    return 0


def _optimization(args: argparse.Namespace, out: TextIO) -> tuple[Settings, dict[str, object]]:
    if args.size < 16:
        raise WiseError(f"--size must be at least 16 pixels, got {args.size}")
    if not args.lr > 0 or args.iters < 1:
        raise WiseError(f"--lr must be positive and --iters at least 1, got {args.lr} and {args.iters}")
    settings = Settings(
        mode=args.mode,
        iterations=args.iters,
        lr=args.lr,
        loss=args.loss,
        tv_weight=args.tv,
        vgg_weights=args.vgg_weights,
        levels=args.levels,
    )
    options = {"size": args.size, "init": args.init, "seed": args.seed, "device": _device(args.device), "out": out}
    return settings, options


def _cmd_optimize(args: argparse.Namespace, out: TextIO) -> int:
    settings, options = _optimization(args, out)
    run_optimization(args.effect, args.content, args.target, args.output, settings, **options)
    return 0


def _cmd_transfer(args: argparse.Namespace, out: TextIO) -> int:
    settings, options = _optimization(args, out)
    run_transfer(
        args.effect,
        args.content,
        args.output,
        settings,
        builtin_style=args.builtin_style,
        style_path=args.style,
        method=args.nst,
        **options,
    )
    return 0


def _cmd_edit(args: argparse.Namespace, out: TextIO) -> int:
    session = initial_session(args.image, args.params, args.effect, args.preset)
    serve(session, args.host, args.port, out)
    return 0


def _cmd_bench_recover(args: argparse.Namespace, out: TextIO) -> int:
    if args.size < 16:
        raise WiseError(f"--size must be at least 16 pixels, got {args.size}")
    if not args.lr > 0 or args.iters < 1:
        raise WiseError(f"--lr must be positive and --iters at least 1, got {args.lr} and {args.iters}")
    if Path(args.json).parent and not Path(args.json).parent.is_dir():
        raise WiseError(f"{args.json}: the directory {Path(args.json).parent} does not exist")
    recover_parameters(
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
    )
    return 0


def _error(message: str, err: TextIO) -> None:
    print(f"{PROG}: error: {_one_line(message)}", file=err)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``wise`` command with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:
        return e.code if isinstance(e.code, int) else (0 if e.code is None else EXIT_USAGE)
    try:
        return int(args.func(args, sys.stdout))
    except WiseError as e:
        _error(str(e), sys.stderr)
    except OSError as e:
        where = f"{e.filename}: " if e.filename else ""
        _error(f"{where}{e.strerror or e}", sys.stderr)
    except torch.cuda.OutOfMemoryError:
        _error("out of GPU memory; try --device cpu or a smaller image", sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
