"""A network's forward pass and a render, alone and beside busy processes.

Usage::

    python benchmarks/bench_busy.py [--busy 2] [--repeat 7] [--effects xdog cartoon]

Times, in this process, the built-in XDoG model's forward pass (photo and example at its working
size) and a 1-megapixel render of each effect (``wise.render.render``), first on a quiet machine,
then while ``--busy`` other processes each keep a core busy (plain Python loops, as another
program would), and prints the median of ``--repeat`` runs of each and the ratio. The process
uses the threads :mod:`wise.threads` gives it (``WISE_THREADS`` overrides).
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import contextlib
import multiprocessing
import statistics
import time
from typing import Callable, Iterator

import torch
import torch.nn.functional as F
from skimage import data

from wise.effects import create
from wise.ppn.predictor import Predictor
from wise.render import render


def _spin(stop) -> None:  # noqa: ANN001 (a multiprocessing event)
    while not stop.is_set():
        sum(range(10_000))


@contextlib.contextmanager
def busy(processes: int) -> Iterator[None]:
    """``processes`` other processes keeping a core busy each while the block runs."""
    stop = multiprocessing.Event()
    spinners = [multiprocessing.Process(target=_spin, args=(stop,), daemon=True) for _ in range(processes)]
    for spinner in spinners:
        spinner.start()
    try:
        time.sleep(0.5)
        yield
    finally:
        stop.set()
        for spinner in spinners:
            spinner.join()


def median_seconds(fn: Callable[[], object], repeat: int) -> float:
    fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def workloads(effects: list[str]) -> dict[str, Callable[[], object]]:
    photo = torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255.0
    megapixel = F.interpolate(photo, size=(1024, 1024), mode="bilinear", antialias=True)
    predictor = Predictor(None, "xdog")
    example = render(predictor.effect, photo, predictor.effect.preset("portrait")[None])
    jobs: dict[str, Callable[[], object]] = {"xdog network forward": lambda: predictor(photo, example)}
    for name in effects:
        effect = create(name)
        params = effect.default_params()[None]
        jobs[f"{name} render 1024²"] = lambda effect=effect, params=params: render(effect, megapixel, params)
    return jobs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--busy", type=int, default=2, help="busy processes beside the measured one")
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--effects", nargs="+", default=["xdog", "cartoon", "watercolor", "oilpaint"])
    args = parser.parse_args()
    jobs = workloads(args.effects)
    print(f"{torch.get_num_threads()} threads; {args.busy} busy processes beside")
    print("| work | quiet | busy | ratio |")
    print("| --- | --- | --- | --- |")
    for name, job in jobs.items():
        quiet = median_seconds(job, args.repeat)
        with busy(args.busy):
            loaded = median_seconds(job, args.repeat)
        print(f"| {name} | {quiet * 1000:.0f} ms | {loaded * 1000:.0f} ms | ×{loaded / quiet:.2f} |", flush=True)


if __name__ == "__main__":
    main()
