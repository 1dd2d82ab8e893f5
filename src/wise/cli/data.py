"""``wise data adaptive`` and ``wise data drawing``: synthetic paired data sets (the pairs
``wise train local`` learns from and ``wise bench pairs`` measures), for content-adaptive effects
and for image-to-image translation."""

from __future__ import annotations

import argparse
import os
import warnings
from pathlib import Path
from typing import TextIO

from wise.cli import args as types
from wise.cli.outputs import OutputFolder
from wise.cli.parser import add_pixel_limit, add_size, command, exit_code, top_command
from wise.errors import WiseError, WiseWarning
from wise.train.choices import ADAPTIVE_SPLITS, DESCRIPTION_FILE, MIN_CHANGE, TASK_FILE
from wise.train.tasks import TASKS

MAX_PAIRS = 1_000_000
"""Most pairs one command makes (a million pairs of 256 pixels take days and terabytes)."""
DEFAULT_SIZE = 256
"""pix2pix's crop size."""


def _check_folders(images: Path, output: Path, description: str) -> None:
    """The output folder is neither the photo folder nor inside it nor around it (pairs written
    among the photos would be read as photos, photos among the pairs replaced), and holds no
    pairs already (a set mixed of two runs would describe neither)."""
    photos, pairs = Path(os.path.realpath(images)), Path(os.path.realpath(output))
    if photos == pairs or photos in pairs.parents:
        raise WiseError(f"{output}: inside the photo folder --images {images}; write the pairs elsewhere")
    if pairs in photos.parents:
        raise WiseError(f"{output}: holds the photo folder --images {images}; write the pairs elsewhere")
    found = [name for name in (description, *ADAPTIVE_SPLITS) if (output / name).exists()]
    if found:
        raise WiseError(
            f"{output}: holds pairs already ({', '.join(found)}); choose another folder or remove them first"
        )


def run_adaptive(args: argparse.Namespace, out: TextIO) -> int:
    folder = _output_folder(args, TASK_FILE)
    from wise.train.adaptive import AdaptiveSettings, write_pairs  # PyTorch

    settings = AdaptiveSettings(
        task=args.task,
        effect=args.effect,
        preset=args.preset,
        count=args.count,
        size=args.size,
        test_share=args.test_share,
        seed=args.seed,
        min_change=args.min_change,
    )
    settings.resolve()
    photos = _photos(args, settings.size)
    with folder.guard():
        summary = write_pairs(args.output, settings, photos, out=out)
    return exit_code(summary["interrupted"])


def run_drawing(args: argparse.Namespace, out: TextIO) -> int:
    folder = _output_folder(args, DESCRIPTION_FILE)
    from wise.train.drawing_pairs import DrawingSettings, write_drawing_pairs  # PyTorch

    settings = DrawingSettings(count=args.count, size=args.size, test_share=args.test_share, seed=args.seed)
    settings.check()
    photos = _photos(args, settings.size)
    with folder.guard():
        summary = write_drawing_pairs(args.output, settings, photos, out=out)
    return exit_code(summary["interrupted"])


def _output_folder(args: argparse.Namespace, description: str) -> OutputFolder:
    """The checked output folder of a pairs command (checked before the heavy imports)."""
    images, output = Path(args.images), Path(args.output)
    if not images.is_dir():
        raise WiseError(f"--images {images}: not a directory of photos")
    folder = OutputFolder(output, (description,), {"--images": args.images})
    _check_folders(images, output, description)
    return folder


def _photos(args: argparse.Namespace, size: int) -> list:
    """The readable photos of ``--images`` for pairs of ``size`` pixels; warns of those skipped."""
    from wise.train.adaptive import load_photos

    photos, skipped = load_photos(Path(args.images), size)
    if skipped:
        warnings.warn(f"{args.images}: skipped {len(skipped)} unreadable or too small files", WiseWarning, stacklevel=2)
    return photos


def register(commands: argparse._SubParsersAction) -> None:
    data = top_command(commands, "data")
    kinds = data.add_subparsers(dest="kind", metavar="KIND", required=True, parser_class=type(data))
    parser = command(
        kinds,
        "adaptive",
        "make paired images whose targets change one parameter inside regions a rule finds in the photo",
    )
    rules = "; ".join(f"{name}: {task.description}" for name, task in TASKS.items())
    parser.add_argument("task", choices=tuple(TASKS), metavar="TASK", help=f"{', '.join(TASKS)} ({rules})")
    _add_photos(parser, "task.json and train/, test/ with A/, B/, regions/ and params/")
    parser.add_argument("--effect", default="xdog", metavar="EFFECT", help="effect name (default xdog)")
    parser.add_argument(
        "--preset",
        metavar="NAME",
        help="preset of the other parameters (default: the task's own, the half-toned pencil and sketch "
        "for details and background of xdog, else portrait for xdog and the first preset of other effects)",
    )
    _add_split(parser)
    parser.add_argument(
        "--min-change",
        type=types.finite_float(0.0, 1.0, below=True),
        default=MIN_CHANGE,
        metavar="D",
        help=f"leave out pairs whose target differs from the preset's rendering by less than D on average "
        f"(after 4 crops of the photo tried; default {MIN_CHANGE:g}, 0: keep all)",
    )
    add_pixel_limit(parser)
    parser.set_defaults(func=run_adaptive)

    drawing = command(
        kinds,
        "drawing",
        "make paired photos and drawings of a synthetic artist (thick outlines, hatching) that XDoG alone "
        "cannot draw, for developing image-to-image translation",
    )
    _add_photos(drawing, "drawing.json and train/, test/ with A/ and B/")
    _add_split(drawing)
    add_pixel_limit(drawing)
    drawing.set_defaults(func=run_drawing)


def _add_photos(parser: argparse.ArgumentParser, layout: str) -> None:
    parser.add_argument(
        "--images", required=True, metavar="DIR", help="folder of photos (searched recursively), at least 2"
    )
    parser.add_argument(
        "-o", "--output", required=True, metavar="PAIRS", help=f"folder of the pairs: {layout} (must hold no pairs)"
    )


def _add_split(parser: argparse.ArgumentParser) -> None:
    """How many square pairs, how large, and how the photos are split."""
    parser.add_argument(
        "--count",
        type=types.whole_number(2, MAX_PAIRS),
        default=200,
        metavar="N",
        help=f"pairs in all, 2 to {MAX_PAIRS:,} (default 200)",
    )
    add_size(parser, types.working_size, "the square pairs", default=DEFAULT_SIZE)
    parser.add_argument(
        "--test-share",
        type=types.open_share,
        default=0.2,
        metavar="S",
        help="share of the photos (not pairs) for the test split, above 0 and below 1 (default 0.2; "
        "at least one photo in each split)",
    )
    parser.add_argument(
        "--seed", type=types.seed, default=0, help="seed of the split and the crops, 0 to 2**63-1 (default 0)"
    )
