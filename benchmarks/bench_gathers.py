"""Hardware gathers against LLVM's scalar loads, in one process, the two alternating.

Usage::

    python benchmarks/bench_gathers.py [--cases 1024x1 256x8] [--rounds 4] [--backward]

Renders every effect's defaults on the astronaut (``wise.render.render``; with ``--backward``
one forward and backward of the effect as training runs it) with the kernels compiled both ways
(``wise.filters.fused._target``), switching before every repeat so that both see the same load,
and prints each one's best time and the ratio. Both kinds of kernels are compiled before timing.
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import time

import torch
import torch.nn.functional as F
from skimage import data

from wise.effects import create
from wise.filters.fused._drjit import llvm_backend
from wise.filters.fused._target import current, set_hardware_gathers
from wise.render import render


def astronaut(size: int, batch: int) -> torch.Tensor:
    image = torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255.0
    return F.interpolate(image, size=(size, size), mode="bilinear", antialias=True).expand(batch, -1, -1, -1)


def timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--effects", nargs="+", default=["xdog", "cartoon", "watercolor", "oilpaint"])
    parser.add_argument("--cases", nargs="+", default=["1024x1"], help="SIZExBATCH")
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--backward", action="store_true", help="forward and backward instead of the render")
    args = parser.parse_args()
    if not llvm_backend():
        raise SystemExit("the Dr.Jit kernels do not run here: nothing to compare")
    target = current()
    print(f"CPU {target.cpu}, {target.vector_width} lanes, {torch.get_num_threads()} threads")
    print("| effect | picture | scalar loads | hardware gathers | speed-up |")
    print("| --- | --- | --- | --- | --- |")
    for case in args.cases:
        size, batch = (int(n) for n in case.split("x"))
        image = astronaut(size, batch)
        for name in args.effects:
            effect = create(name)
            params = effect.default_params().expand(batch, -1).clone()

            def once() -> None:
                if args.backward:
                    p = params.clone().requires_grad_(True)
                    effect(image, p).mean().backward()
                else:
                    render(effect, image, params)

            best = {False: float("inf"), True: float("inf")}
            for round_ in range(args.rounds + 1):  # round 0 compiles
                for hardware in (False, True):
                    set_hardware_gathers(hardware)
                    seconds = timed(once)
                    if round_:
                        best[hardware] = min(best[hardware], seconds)
            print(
                f"| {name} | {size}²×{batch} | {best[False] * 1000:.0f} ms | {best[True] * 1000:.0f} ms | "
                f"×{best[False] / best[True]:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
