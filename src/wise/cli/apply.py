"""``wise apply`` and ``wise gallery``: render effects on images."""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import TextIO

from wise.batch.inputs import PARAMS_SUFFIX, Job, is_batch, is_video, plan
from wise.batch.spec import LookSpec
from wise.cli import args as types
from wise.cli.effects import fmt
from wise.cli.outputs import OutputFolder, output_file
from wise.cli.parser import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    PROG,
    add_device,
    add_pixel_limit,
    add_size,
    device,
    top_command,
)
from wise.effects.catalogue import NAMES, NO_EFFECT, Entry, check_name, entry
from wise.errors import WiseError, size_text
from wise.files import MAX_PARAMS_BYTES, PARAMS_WHAT, regular_file
from wise.io import WRITE_FORMATS, check_image_file


def parse_set(item: str, effect: Entry | None) -> tuple[str, float]:
    """``NAME=VALUE`` in real units, checked against ``effect``: (name, value)."""
    name, sep, text = item.partition("=")
    name, text = name.strip(), text.strip()
    if effect is None:
        raise WiseError("--set: the effect 'none' has no parameters")
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
    return name, value


def _look(args: argparse.Namespace) -> LookSpec:
    """The look of the command line, its names and numbers checked and its parameter file found
    (files are read by :class:`~wise.batch.look.Look`)."""
    if args.params and args.preset:
        raise WiseError("--params and --preset cannot be combined; edit the file's values with --set instead")
    effect = None if args.effect == NO_EFFECT else entry(args.effect)
    if effect is not None and args.preset is not None:
        effect.check_preset(args.preset)
    settings = tuple(parse_set(item, effect) for item in args.set)
    if args.params:
        regular_file(args.params, PARAMS_WHAT, MAX_PARAMS_BYTES)
    return LookSpec(
        args.effect, preset=args.preset, params=args.params, settings=settings, model=args.model,
        kernel_size=args.kernel_size,
    )  # fmt: skip


def _on_device(spec: LookSpec, args: argparse.Namespace) -> LookSpec:
    """``spec`` on the device of ``--device`` (which loads PyTorch: once the inputs are checked)."""
    return dataclasses.replace(spec, device=_device_name(args))


def _device_name(args: argparse.Namespace) -> str:
    """``--device``; with ``--ray``, ``cuda`` names the actors' device, which this machine may lack."""
    if args.ray and args.device == "cuda":
        return "cuda"
    return str(device(args.device))


def run_apply(args: argparse.Namespace, out: TextIO) -> int:
    if args.ray_address and not args.ray:
        raise WiseError("--ray-address is where --ray renders; add --ray, or leave the address out")
    spec = _look(args)
    if len(args.inputs) == 1 and is_video(args.inputs[0]) and not Path(args.inputs[0]).is_dir():
        return _apply_video(args, spec, out)
    if is_batch(args.inputs):
        return _apply_batch(args, spec, out)
    return _apply_one(args, spec, out)


def _refuse_video_options(args: argparse.Namespace) -> None:
    for option, given in (("--crf", args.crf), ("--codec", args.codec)):
        if given is not None:
            raise WiseError(f"{option} is for a video input; leave it out for images")


def _apply_one(args: argparse.Namespace, spec: LookSpec, out: TextIO) -> int:
    """One image to one file, as every image of a batch; says what it wrote unless ``--quiet``."""
    began = time.perf_counter()
    _refuse_video_options(args)
    if args.format is not None:
        raise WiseError(f"--format is for a folder of results; {args.output}'s own extension chooses its format")
    inputs = {"image": args.inputs[0], "--params": args.params, "--model": args.model}
    output = output_file(args.output, inputs, WRITE_FORMATS)
    params_file = output.with_suffix(PARAMS_SUFFIX) if args.save_params else None
    if params_file is not None:
        output_file(params_file, inputs, (PARAMS_SUFFIX,))
    check_image_file(args.inputs[0])
    from wise.batch.look import Look
    from wise.batch.run import write
    from wise.io import read_image

    look = Look(_on_device(spec, args))
    rendered = look.render(read_image(args.inputs[0]))
    write(Job(Path(args.inputs[0]), output, params_file), rendered, look, args.quality)
    if not args.quiet:
        height, width = rendered.image.shape[-2:]
        also = f" and {params_file}" if params_file is not None else ""
        seconds = time.perf_counter() - began
        print(f"wrote {output}{also} ({size_text(width, height)}, {seconds:.1f} s)", file=out, flush=True)
    return 0


def _apply_batch(args: argparse.Namespace, spec: LookSpec, out: TextIO) -> int:
    """Many images into the folder OUT, resumable; exit 1 when an image failed."""
    _refuse_video_options(args)
    jobs = plan(args.inputs, args.output, args.format or "png", args.save_params)
    if Path(args.output).suffix.lower() in WRITE_FORMATS and not Path(args.output).is_dir():
        raise WiseError(f"{args.output}: several images are written to a folder; give a folder name, not an image file")
    OutputFolder(args.output, (), {}).check()
    sources = {str(job.source.resolve()) for job in jobs}
    if args.log is not None:
        output_file(args.log, {"--log": None})
        if str(Path(args.log).resolve()) in sources:
            raise WiseError(f"{args.log}: is one of the input images; write the log to another file")
    from wise.batch.look import Look
    from wise.batch.run import JsonLog, run_jobs

    journal = JsonLog(args.log)
    try:
        if args.ray:
            from wise.batch.distributed import require_ray, run_on_ray

            require_ray()
            summary = run_on_ray(
                _on_device(spec, args), jobs, address=args.ray_address, gpus_per_worker=args.ray_gpus_per_worker,
                quality=args.quality, overwrite=args.overwrite, log=journal, progress=_progress_shown(),
            )  # fmt: skip
            for failure in summary.failed:
                print(f"{PROG}: failed: {failure.error}", file=sys.stderr)
        else:
            summary = run_jobs(
                Look(_on_device(spec, args)), jobs, workers=args.workers, quality=args.quality,
                overwrite=args.overwrite, log=journal, progress=_progress_shown(),
                report=lambda o: print(f"{PROG}: failed: {o.error}", file=sys.stderr),
            )  # fmt: skip
    finally:
        journal.close()
    print(summary.line(), file=out, flush=True)
    if summary.interrupted:
        return EXIT_INTERRUPTED
    return EXIT_FAILURE if summary.failed else 0


def _apply_video(args: argparse.Namespace, spec: LookSpec, out: TextIO) -> int:
    """A video decoded, stylized and encoded frame by frame."""
    from wise.batch.video import VIDEO_OUTPUT_SUFFIXES, check_video_output, probe, stylize_video

    for option, given in (("--ray", args.ray), ("--save-params", args.save_params), ("--format", args.format)):
        if given:
            raise WiseError(f"{option} is for images; a video is stylized frame by frame into one video file")
    from wise.batch.look import Look

    check_video_output(args.output, args.codec, crf=args.crf)
    output = output_file(args.output, {"video": args.inputs[0], "--params": args.params, "--model": args.model},
                         VIDEO_OUTPUT_SUFFIXES)  # fmt: skip
    info = probe(args.inputs[0])
    look = Look(_on_device(spec, args))
    result = stylize_video(
        look, Path(args.inputs[0]), output, crf=args.crf, codec=args.codec,
        temporal_smoothing=args.temporal_smoothing, progress=_progress_shown(),
    )  # fmt: skip
    if result.interrupted:
        return EXIT_INTERRUPTED
    rate = result.frames / result.seconds if result.seconds > 0 else 0.0
    print(f"{result.frames} frames of {info.width}x{info.height} in {result.seconds:.1f} s ({rate:.2f} frames/s): "
          f"{output}", file=out)  # fmt: skip
    return 0


def _progress_shown() -> bool:
    return sys.stderr.isatty()


def run_gallery(args: argparse.Namespace, out: TextIO) -> int:
    names = args.effects or sorted(NAMES)
    for name in names:
        check_name(name)  # unknown names fail before any work
    output = output_file(args.output, {"image": args.input}, WRITE_FORMATS)
    check_image_file(args.input)
    import numpy as np

    from wise.gallery import make_sheet
    from wise.io import image_to_tensor, read_image, write_image

    target_device = device(args.device)
    image = read_image(args.input)

    def report(effect: str, preset: str, seconds: float) -> None:
        print(f"{effect:10s} {preset:12s} {seconds:6.2f} s", file=out, flush=True)

    sheet = make_sheet(image, args.size, names, target_device, progress=report)
    write_image(image_to_tensor(np.asarray(sheet)), output)
    print(f"wrote {output}", file=out)
    return 0


def register(commands: argparse._SubParsersAction) -> None:
    apply = top_command(commands, "apply")
    apply.add_argument("effect", metavar="EFFECT", help="effect name (see 'wise effects'); none for a CNN-only model")
    apply.add_argument(
        "inputs",
        nargs="+",
        metavar="INPUT",
        help="images (PNG, JPEG, WebP, TIFF), folders (searched recursively), quoted glob patterns, "
        "or one video (mp4, mov, mkv, webm)",
    )
    apply.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUT",
        help="the result: an image file (.png, .jpg) for one image; a folder for several images, a folder "
        "or a pattern (each result keeps its path relative to its input folder); a video file for a video",
    )
    apply.add_argument("--preset", metavar="NAME", help="start from this preset instead of the defaults")
    apply.add_argument("--params", metavar="FILE", help="start from a parameter file (global or local masks)")
    apply.add_argument(
        "--model",
        metavar="FILE",
        help="a local model (file or builtin:TASK): it paints each image's masks as 'wise predict' does; "
        "a model with a CNN after the effect renders with --params/--preset when given, else with its own masks",
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
    apply.add_argument(
        "--save-params",
        action="store_true",
        help="also write each result's parameters (masks) next to it as NAME.safetensors, editable later",
    )
    apply.add_argument("--quiet", action="store_true", help="print nothing for a single image that was written")
    add_pixel_limit(apply)
    many = apply.add_argument_group("many images")
    many.add_argument("--format", choices=("png", "jpg"), help="format of the results in a folder (default png)")
    many.add_argument(
        "--workers", type=types.whole_number(1, 64), default=2, metavar="N",
        help="threads that read images ahead of the render and write results behind it (default 2)",
    )  # fmt: skip
    many.add_argument("--overwrite", action="store_true", help="render again the images whose results exist")
    many.add_argument("--log", metavar="FILE", help="write one JSON line per input (input, output, status, error)")
    many.add_argument("--ray", action="store_true", help="render on a Ray cluster (needs: pip install 'wise[ray]')")
    many.add_argument(
        "--ray-address", metavar="ADDR", help="the cluster to join, e.g. HOST:6379 (default: a local Ray instance)"
    )
    many.add_argument(
        "--ray-gpus-per-worker", type=types.finite_float(0.0, 16.0), default=0.0, metavar="G",
        help="GPUs for each rendering actor (default 0; 1 with --device cuda)",
    )  # fmt: skip
    video = apply.add_argument_group("video")
    video.add_argument("--crf", type=types.whole_number(0, 63), metavar="N", help="encoder quality (lower is better)")
    video.add_argument("--codec", metavar="NAME", help="video encoder (default libx264; libvpx-vp9 for .webm)")
    video.add_argument(
        "--temporal-smoothing", type=types.finite_float(0.0, 1.0, below=True), default=0.3, metavar="A",
        help="with a local model, each frame's masks are A times the last frame's plus (1 - A) times its own "
        "(default 0.3; 0 switches it off)",
    )  # fmt: skip
    apply.set_defaults(func=run_apply)

    gallery = top_command(commands, "gallery")
    gallery.add_argument("input", metavar="INPUT", help="input image (PNG, JPEG, WebP or TIFF)")
    gallery.add_argument("-o", "--output", required=True, metavar="SHEET", help="output sheet (.png or .jpg)")
    add_size(gallery, types.cell_size, "each cell")
    gallery.add_argument("--effects", nargs="+", metavar="EFFECT", help="only these effects")
    add_device(gallery)
    add_pixel_limit(gallery)
    gallery.set_defaults(func=run_gallery)
