"""Stylize many images: folders, data sets, videos, and past one machine on Ray.

- :mod:`wise.batch.look`: :class:`LookSpec` (what to render) and :class:`Look` (loaded once,
  renders one image); every result of ``wise apply`` comes from it.
- :mod:`wise.batch.inputs`: files, folders and glob patterns expanded to jobs.
- :mod:`wise.batch.run`: one process with reading and writing threads,
  resumable, faults reported per image; :mod:`wise.batch.api`: :func:`stylize`, the entry point.
- :mod:`wise.batch.video`: a video decoded, stylized and encoded frame by frame (PyAV).
- :mod:`wise.batch.distributed`: the same batch as a Ray Data pipeline (optional extra ``ray``).

Example::

    from wise.batch import stylize
    summary = stylize(["photos/"], "out/", "xdog", preset="portrait")
    print(summary.line())
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from wise.batch.api import stylize
    from wise.batch.inputs import Job, plan
    from wise.batch.look import Look, Rendered
    from wise.batch.run import Outcome, Summary
    from wise.batch.spec import LookSpec

_LAZY = {
    "stylize": "api",
    "Job": "inputs",
    "plan": "inputs",
    "Look": "look",
    "Rendered": "look",
    "LookSpec": "spec",
    "Outcome": "run",
    "Summary": "run",
}


def __getattr__(name: str) -> object:
    """The package's classes and functions, each module loaded on first use (the command line
    checks its arguments before PyTorch loads)."""
    if name in _LAZY:
        return getattr(importlib.import_module(f"wise.batch.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'wise.batch' has no attribute {name!r}")


__all__ = ["Job", "Look", "LookSpec", "Outcome", "Rendered", "Summary", "plan", "stylize"]
