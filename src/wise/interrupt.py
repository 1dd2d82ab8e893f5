"""Ctrl-C for long commands: the first one stops the work, the files that follow stay whole.

A long command stops at the first Ctrl-C and writes what it has reached; a second Ctrl-C
while those files are written must not leave some of them missing. Inside :func:`ctrl_c`
the first SIGINT raises ``KeyboardInterrupt`` as usual (the work loops catch it and return
the state reached); every later one, and any after :meth:`CtrlC.hold`, is only recorded.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator, TextIO


class CtrlC:
    """What the handler of :func:`ctrl_c` has seen."""

    def __init__(self, out: TextIO | None) -> None:
        self.received = False
        self._holding = False
        self._noted = False
        self._out = out

    def hold(self) -> None:
        """From now on Ctrl-C is only recorded (the results are being written)."""
        self._holding = True

    def handle(self, signum: int, frame: object) -> None:
        if self._holding or self.received:
            self.received = True
            if not self._noted and self._out is not None:
                print("finishing the files being written; they will be complete", file=self._out, flush=True)
            self._noted = True
            return
        self.received = True
        raise KeyboardInterrupt


@contextlib.contextmanager
def ctrl_c(out: TextIO | None = None) -> Iterator[CtrlC]:
    """Install the handler of :class:`CtrlC` for the block (the main thread only; elsewhere
    Python delivers no signals and the block runs as it is). ``out`` gets one line when a
    Ctrl-C is held, so the user knows the command is finishing."""
    state = CtrlC(out)
    if threading.current_thread() is not threading.main_thread():
        yield state
        return
    previous = signal.signal(signal.SIGINT, state.handle)
    try:
        yield state
    finally:
        signal.signal(signal.SIGINT, previous)
