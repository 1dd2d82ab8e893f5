"""Notices a long step gives before it starts, routed to whoever shows them (the command line
prints them on stderr). Free of numerical libraries, so a command installs its printer before
PyTorch loads."""

from __future__ import annotations

from typing import Callable

_compilation: Callable[[str], None] | None = None


def announce_compilation(print_line: Callable[[str], None]) -> None:
    """Have ``print_line`` called once with the compilation notice when this process first uses a
    fused kernel while the kernels of this version have not been compiled ahead (see
    :func:`wise.filters.fused.warm_marker`), so that a command does not wait silently."""
    global _compilation
    _compilation = print_line


def take_compilation_announcer() -> Callable[[str], None] | None:
    """The printer installed by :func:`announce_compilation`, handed out once."""
    global _compilation
    printer, _compilation = _compilation, None
    return printer
