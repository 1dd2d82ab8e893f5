"""The ``wise`` command: one module per command group, shared argument types and output checks.

Bad input (unknown names, malformed or out-of-range values, unreadable files, unusable
outputs) is refused before any work with one line ``wise: error: ...`` on stderr and exit
code 2, leaving no file or folder behind. Ctrl-C stops a command with exit code 130; what it
has written by then is complete. Warnings meant for the user are one ``wise: warning:`` line;
warnings of the libraries underneath are not shown.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings
from typing import Sequence, TextIO

from wise import __version__
from wise.cli import args as types
from wise.cli.parser import (
    COMMANDS,
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    PROG,
    Parser,
    apply_pixel_limit,
    one_line,
)
from wise.errors import WiseError, WiseWarning
from wise.io import MAX_PIXELS_ENV
from wise.notices import announce_compilation
from wise.threads import THREADS_VARIABLE, thread_count, use_threads


def build_parser(chosen: str | None = None) -> argparse.ArgumentParser:
    """The argument parser of the ``wise`` command. Only the module of the ``chosen`` command is
    imported, and only its commands get their arguments; the others are listed with their help
    (see :data:`~wise.cli.parser.COMMANDS`)."""
    parser = Parser(
        prog=PROG, description="Whitebox image stylization: differentiable effects with editable parameters."
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    parser.add_argument(
        "--threads",
        type=types.thread_count,
        metavar="N",
        help=f"threads to compute on (default: the cores this process may use, or ${THREADS_VARIABLE})",
    )
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    wanted = COMMANDS[chosen][0] if chosen in COMMANDS else None
    for name, (module, help, _) in COMMANDS.items():
        if module != wanted:
            commands.add_parser(name, help=help, add_help=False)
        elif name not in commands.choices:
            importlib.import_module(f"wise.cli.{module}").register(commands)
    return parser


def chosen_command(argv: Sequence[str]) -> str | None:
    """The command named in ``argv``: its first word that is neither an option of the ``wise``
    command nor the value of ``--threads``."""
    words = iter(argv)
    for word in words:
        if word == "--threads":
            next(words, None)
        elif not word.startswith("-"):
            return word
    return None


def _error(message: str, err: TextIO) -> None:
    print(f"{PROG}: error: {one_line(message)}", file=err, flush=True)


def _show_warning(err: TextIO):
    def show(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001 (warnings' hook)
        print(f"{PROG}: warning: {one_line(message)}", file=err, flush=True)

    return show


OUT_OF_MEMORY = "out of memory; try --device cpu, a smaller image or a smaller --size"


def _out_of_device_memory(error: RuntimeError) -> bool:
    torch = sys.modules.get("torch")  # loaded by any command that can run out of GPU memory
    return torch is not None and isinstance(error, torch.cuda.OutOfMemoryError)


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
    except MemoryError:
        _error(OUT_OF_MEMORY, err)
        return EXIT_FAILURE
    except RuntimeError as e:
        if not _out_of_device_memory(e):
            raise
        _error(OUT_OF_MEMORY, err)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=err, flush=True)
        return EXIT_INTERRUPTED
    return EXIT_USAGE


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``wise`` command with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(chosen_command(argv))
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:
        return e.code if isinstance(e.code, int) else (0 if e.code is None else EXIT_USAGE)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    try:
        if args.threads is not None:
            use_threads(args.threads)
        else:
            thread_count()  # a bad $WISE_THREADS is refused before any work
    except WiseError as e:
        _error(str(e), sys.stderr)
        return EXIT_USAGE
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
