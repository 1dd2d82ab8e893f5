"""The oriented bilateral pass and the line-integral smoothing, timed through their public
functions (``bilateral_pass``, ``flow_smoothing``): forward (no autograd) and forward + backward,
at 1024² and 256² x 8, best of 4 after a warm-up, on the sources first on ``PYTHONPATH``.

Usage::

    PYTHONPATH=src python benchmarks/engines/bench_taps.py            # this tree
    PYTHONPATH=/path/to/other/src python benchmarks/engines/bench_taps.py

Prints one JSON line of milliseconds. The inputs are seeded: a smoothed random image of Lab-like
range and a smooth random direction field.
"""

from __future__ import annotations

import json
import time

import torch
import torch.nn.functional as F

from wise.filters.bilateral import bilateral_pass
from wise.filters.dog import flow_smoothing


def best_of(run, repeat: int = 4) -> float:
    run()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return round(min(times) * 1000, 1)


def main() -> None:
    torch.set_num_threads(2)
    results: dict[str, float] = {}
    for batch, size in ((1, 1024), (8, 256)):
        generator = torch.Generator().manual_seed(0)
        image = F.avg_pool2d(torch.rand(batch, 3, size, size, generator=generator) * 100, 5, 1, 2)
        angle = F.avg_pool2d(torch.rand(batch, 1, size, size, generator=generator), 9, 1, 4) * 30
        direction = torch.cat((angle.cos(), angle.sin()), dim=1)
        filters = {
            "bilateral": lambda x: bilateral_pass(x, direction, 2.0, 5.0, samples=3),
            "smoothing": lambda x: flow_smoothing(x, direction, 4.0),
        }
        for name, apply in filters.items():

            def forward(apply=apply) -> None:
                with torch.no_grad():
                    apply(image)

            def forward_backward(apply=apply) -> None:
                picture = image.clone().requires_grad_()
                apply(picture).square().mean().backward()

            case = f"{name} {size}x{batch}"
            results[f"{case} forward"] = best_of(forward)
            results[f"{case} forward+backward"] = best_of(forward_backward)
    print(json.dumps(results))


if __name__ == "__main__":
    main()
