"""The argument parser of every command: one-line usage errors, shared options."""

from __future__ import annotations

import argparse
import os
from typing import TYPE_CHECKING, NoReturn

from wise.cli import args as types
from wise.cli.outputs import OVERWRITE_RULE
from wise.errors import WiseError
from wise.io import DEFAULT_MAX_PIXELS, MAX_PIXELS_ENV

if TYPE_CHECKING:
    import torch

PROG = "wise"
EXIT_USAGE = 2
EXIT_FAILURE = 1
EXIT_INTERRUPTED = 130
DEVICES = ("auto", "cpu", "cuda")

COMMANDS: dict[str, tuple[str, str, bool]] = {
    "effects": ("effects", "list effects, their parameters and presets", False),
    "apply": ("apply", "stylize images, folders of images or a video with an effect", True),
    "gallery": ("apply", "every effect and preset on one labelled contact sheet", True),
    "optimize": ("optimize", "optimize parameters so that an effect re-creates a target image", True),
    "transfer": ("optimize", "neural style transfer, then re-create it with an effect", True),
    "predict": (
        "predict",
        "predict the global parameters that re-create an example, or paint parameter masks with a local model",
        True,
    ),
    "train": ("train", "train parameter prediction networks", False),
    "data": ("data", "make data sets", False),
    "edit": ("edit", "the web editor: paint parameter masks and see the result", False),
    "bench": ("bench", "benchmarks", False),
}
"""Every command: the module of :mod:`wise.cli` that defines its arguments, its one-line help and
whether it writes files. A command's module is imported only when the command runs, so that
``wise --help`` and the refusals of bad arguments come back before PyTorch loads."""


def one_line(text: object) -> str:
    return " ".join(str(text).split())


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are a single ``wise: error:`` line (exit code 2)."""

    def error(self, message: str) -> NoReturn:
        hint = f" (see '{self.prog} --help')"
        self.exit(EXIT_USAGE, f"{PROG}: error: {one_line(message)}{hint}\n")


def top_command(commands: argparse._SubParsersAction, name: str) -> argparse.ArgumentParser:
    """The command ``name`` of :data:`COMMANDS`, with its help."""
    _, help, writes = COMMANDS[name]
    return command(commands, name, help, writes)


def command(commands: argparse._SubParsersAction, name: str, help: str, writes: bool = True) -> argparse.ArgumentParser:
    """A sub-command; those that write files state the overwrite rule in their help."""
    return commands.add_parser(
        name, help=help, description=help[:1].upper() + help[1:] + ".", epilog=OVERWRITE_RULE if writes else None
    )


def exit_code(interrupted: bool) -> int:
    """A command's exit code once its results are written: 130 when Ctrl-C stopped it."""
    return EXIT_INTERRUPTED if interrupted else 0


def add_device(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--device", choices=DEVICES, default="auto", help="default: cuda if available")


def add_size(parser: argparse.ArgumentParser, parse: types.WholeNumber, what: str, default: int = 512) -> None:
    """``--size PX``: a short side in pixels, within the bounds of ``parse``."""
    parser.add_argument(
        "--size",
        type=parse,
        default=default,
        metavar="PX",
        help=f"short side of {what}, {parse.minimum} to {parse.maximum} (default {default})",
    )


def add_pixel_limit(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--max-pixels",
        type=types.pixel_limit,
        metavar="N",
        help=f"refuse images with more pixels (default {DEFAULT_MAX_PIXELS:,}, or ${MAX_PIXELS_ENV})",
    )


def device(name: str) -> torch.device:
    """``--device``: cuda, cpu, or auto (cuda when available). Loads PyTorch: call it once the
    arguments are checked."""
    import torch

    if name == "cuda" and not torch.cuda.is_available():
        raise WiseError("--device cuda: CUDA is not available; use --device cpu")
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def apply_pixel_limit(namespace: argparse.Namespace) -> str | None:
    """Make ``--max-pixels`` the process's limit; returns the previous value of the variable."""
    previous = os.environ.get(MAX_PIXELS_ENV)
    limit = getattr(namespace, "max_pixels", None)
    if limit is not None:
        os.environ[MAX_PIXELS_ENV] = str(limit)
    return previous
