"""Compile the fused CPU kernels of every effect ahead of use: ``python -m wise.effects.compile``.

The kernels (:mod:`wise.filters.fused`) compile on their first call and are cached on disk, so
only the first process pays. This runs each effect's forward and backward pass once on a
thumbnail, with global values and with per-pixel masks, and renders it at the reference size
(where some filters take more samples than on a thumbnail), for the given dtypes; each dtype in
a process of its own, all at once, so that the compilations share the cores. A new picture size
compiles nothing more for rendering. ``make install`` runs it; useful too in a container image
and before timing anything. When every dtype is done it leaves
:func:`wise.filters.fused.warm_marker`, so that commands do not announce a compilation.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

import torch

from wise import effects
from wise.filters import fused
from wise.filters._checks import REFERENCE_SHORT_SIDE

DTYPES = {"float32": torch.float32, "float64": torch.float64}
_WORKER_VARIABLE = "WISE_COMPILE_WORKER"
"""Set for the one-dtype processes that a run for several dtypes starts: they print nothing."""


def compile_kernels(dtype: torch.dtype = torch.float32, size: int = 48) -> None:
    """One forward and backward pass of every effect on a ``size`` x ``size`` thumbnail in
    ``dtype``, with global values and with masks, and a render at the reference size."""
    from wise.render import render

    image = torch.rand(1, 3, size, size, dtype=dtype)
    side = int(REFERENCE_SHORT_SIDE)
    reference = torch.rand(1, 3, side, side, dtype=dtype)
    for name in effects.available():
        effect = effects.create(name).to(dtype)
        start = effect.default_params()[None].to(dtype)
        for params in (start, start[:, :, None, None].expand(-1, -1, size // 4, size // 4)):
            with torch.no_grad():  # rendering (wise apply, the editor) takes kernels of its own
                effect(image, params)
                render(effect, reference, params)
            params = params.clone().requires_grad_(True)
            picture = image.clone().requires_grad_(True)
            effect(picture, params).mean().backward()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m wise.effects.compile", description=__doc__.splitlines()[0])
    # no `choices`: Python 3.11's argparse checks an empty or default list against them as one value
    parser.add_argument("dtypes", nargs="*", metavar="DTYPE", help=f"{' or '.join(sorted(DTYPES))} (default: float32)")
    args = parser.parse_args(argv)
    args.dtypes = args.dtypes or ["float32"]
    unknown = [name for name in args.dtypes if name not in DTYPES]
    if unknown:
        parser.error(f"unknown dtype {unknown[0]!r}; use {' or '.join(sorted(DTYPES))}")
    if not fused.enabled(torch.zeros(1)):
        print("the fused kernels are off here: nothing to compile")
        return 0
    began = time.perf_counter()
    worker = os.environ.get(_WORKER_VARIABLE) == "1"
    if not worker:
        print(
            f"compiling the CPU kernels of every effect for {', '.join(args.dtypes)} "
            "(about 15 s on two cores, once: they are cached on disk)",
            flush=True,
        )
    if len(args.dtypes) == 1:
        compile_kernels(DTYPES[args.dtypes[0]])
    else:
        env = {**os.environ, _WORKER_VARIABLE: "1"}
        command = [sys.executable, "-m", "wise.effects.compile"]
        workers = [subprocess.Popen([*command, name], env=env) for name in args.dtypes]
        if any(worker.wait() != 0 for worker in workers):
            return 1
    if worker:
        return 0
    if "float32" in args.dtypes:  # the dtype of every command
        marker = fused.warm_marker()
        marker.parent.mkdir(parents=True, exist_ok=True)
        marker.touch()
    print(f"kernels compiled for {', '.join(args.dtypes)} in {time.perf_counter() - began:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
