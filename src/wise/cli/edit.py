"""``wise edit``: the local web editor."""

from __future__ import annotations

import argparse
from typing import TextIO

from wise.cli import args as types
from wise.cli.parser import add_pixel_limit, top_command
from wise.editor.addresses import LOOPBACK
from wise.editor.start import check_start


def run(args: argparse.Namespace, out: TextIO) -> int:
    check_start(args.image, args.params, args.effect, args.preset, args.model)
    from wise.editor.server import initial_session, serve

    session = initial_session(args.image, args.params, args.effect, args.preset, args.model)
    serve(session, args.host, args.port, out)
    return 0


def register(commands: argparse._SubParsersAction) -> None:
    edit = top_command(commands, "edit")
    edit.add_argument("image", nargs="?", metavar="IMAGE", help="content image to open")
    start = edit.add_mutually_exclusive_group()
    start.add_argument("--params", metavar="FILE", help="parameter file to edit (from wise optimize or the editor)")
    start.add_argument("--effect", metavar="EFFECT", help="start from this effect's global values")
    edit.add_argument("--preset", metavar="NAME", help="with --effect: start from this preset")
    edit.add_argument(
        "--model",
        metavar="FILE",
        help="with --params: a model of 'wise train local --post' whose CNN draws the result from the effect's "
        "output (at the model's working size)",
    )
    edit.add_argument(
        "--host",
        default=LOOPBACK,
        help=f"address to listen on (default {LOOPBACK}: this machine only; any other address needs the access "
        "token in the URL printed at start)",
    )
    edit.add_argument("--port", type=types.port, default=8000, help="port to listen on, 1 to 65535 (default 8000)")
    add_pixel_limit(edit)
    edit.set_defaults(func=run)
