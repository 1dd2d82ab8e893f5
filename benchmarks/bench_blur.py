"""The fixed Gaussian blur: banded matrix products against the depthwise convolution.

Usage::

    python benchmarks/bench_blur.py [--repeat 5]

Times one axis of the blur (forward, and the adjoint of backward) for each axis, picture size
and sigma, best of ``--repeat``, on this process's threads; the convolution is the reference
the tests compare with (``wise.filters.gaussian._correlate_axis``).
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import time

import torch

from wise.filters.banded import correlate_axis, correlate_axis_adjoint
from wise.filters.gaussian import _correlate_axis, _fixed_kernel

CASES = [
    ((1, 3, 1024, 1024), 8.0),
    ((1, 3, 1024, 1024), 2.0),
    ((1, 1, 1024, 1024), 1.0),
    ((8, 3, 256, 256), 2.0),
    ((1, 3, 2048, 2048), 4.0),
]


def best(fn, repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times) * 1000.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(
        "| picture | sigma | taps | axis | convolution | banded | speed-up | adjoint: convolution | banded | speed-up |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for shape, sigma in CASES:
        image = torch.rand(shape)
        kernel = _fixed_kernel(sigma, image)
        for axis in (3, 2):
            conv = best(lambda: _correlate_axis(image, kernel, axis, "replicate"), args.repeat)
            band = best(lambda: correlate_axis(image, kernel, axis), args.repeat)
            conv_adjoint = best(lambda: _correlate_axis(image, kernel, axis, "constant"), args.repeat)
            band_adjoint = best(lambda: correlate_axis_adjoint(image, kernel, axis), args.repeat)
            picture = "×".join(str(n) for n in shape)
            print(
                f"| {picture} | {sigma} | {kernel.numel()} | {'xy'[3 - axis]} | {conv:.1f} ms | {band:.1f} ms | "
                f"×{conv / band:.1f} | {conv_adjoint:.1f} ms | {band_adjoint:.1f} ms | "
                f"×{conv_adjoint / band_adjoint:.1f} |"
            )


if __name__ == "__main__":
    main()
