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

from wise.batch.api import stylize
from wise.batch.inputs import Job, plan
from wise.batch.look import Look, LookSpec, Rendered
from wise.batch.run import Outcome, Summary

__all__ = ["Job", "Look", "LookSpec", "Outcome", "Rendered", "Summary", "plan", "stylize"]
