"""The ``wise`` command: one module per command group, shared argument types and output checks.

Bad input (unknown names, malformed or out-of-range values, unreadable files, unusable
outputs) is refused before any work with one line ``wise: error: ...`` on stderr and exit
code 2, leaving no file or folder behind. Ctrl-C stops a command with exit code 130; what it
has written by then is complete. Warnings meant for the user are one ``wise: warning:`` line;
warnings of the libraries underneath are not shown.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from typing import Sequence, TextIO

import torch

from wise import __version__
from wise.cli import apply, bench, data, edit, effects, optimize, predict, train
from wise.cli.parser import EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_USAGE, PROG, Parser, apply_pixel_limit, one_line
from wise.errors import WiseError, WiseWarning
from wise.filters.fused import announce_compilation
from wise.io import MAX_PIXELS_ENV

COMMAND_GROUPS = (effects, apply, optimize, predict, train, data, edit, bench)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``wise`` command."""
    parser = Parser(
        prog=PROG, description="Whitebox image stylization: differentiable effects with editable parameters."
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for group in COMMAND_GROUPS:
        group.register(commands)
    return parser


def _error(message: str, err: TextIO) -> None:
    print(f"{PROG}: error: {one_line(message)}", file=err, flush=True)


def _show_warning(err: TextIO):
    def show(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001 (warnings' hook)
        print(f"{PROG}: warning: {one_line(message)}", file=err, flush=True)

    return show


def _run(args: argparse.Namespace, out: TextIO, err: TextIO) -> int:
    try:
        code = int(args.func(args, out))
        if code == EXIT_INTERRUPTED:  # stopped by Ctrl-C, its results written
            print(f"{PROG}: interrupted", file=err, flush=True)
        return code
    except WiseError as e:
        _error(str(e), err)
    except OSError as e:
        where = f"{e.filename}: " if e.filename else ""
        _error(f"{where}{e.strerror or e}", err)
    except (torch.cuda.OutOfMemoryError, MemoryError):
        _error("out of memory; try --device cpu, a smaller image or a smaller --size", err)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=err, flush=True)
        return EXIT_INTERRUPTED
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``wise`` command with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:
        return e.code if isinstance(e.code, int) else (0 if e.code is None else EXIT_USAGE)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    previous_limit = apply_pixel_limit(args)
    announce_compilation(lambda line: print(f"{PROG}: {line}", file=sys.stderr, flush=True))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            warnings.simplefilter("always", WiseWarning)
            warnings.showwarning = _show_warning(sys.stderr)
            return _run(args, sys.stdout, sys.stderr)
    finally:
        if previous_limit is None:
            os.environ.pop(MAX_PIXELS_ENV, None)
        else:
            os.environ[MAX_PIXELS_ENV] = previous_limit


if __name__ == "__main__":
    sys.exit(main())
