"""Running the command line inside the test process."""

from __future__ import annotations

import io
from contextlib import redirect_stdout

from wise.cli import main


def run_in_process(argv: list[str]) -> tuple[int, str]:
    """``wise ARGV`` in this process: its exit code and what it printed."""
    out = io.StringIO()
    with redirect_stdout(out):
        code = main(argv)
    return code, out.getvalue()
