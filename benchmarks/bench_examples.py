"""Examples per second of image-space training, each example rendered once (a fresh stream).

Times what ``wise train global`` does per step in steady state, in one process: the batch of
examples made by the data set (the DataLoader's fetch, rendering included) and the training
step (the image-space loss, backward, Adam) on it. Written against the data set and module
interfaces shared by older versions, so that an A/B runs the same script with another
checkout first on ``PYTHONPATH``:

    PYTHONPATH=OLD/src python benchmarks/bench_examples.py --images photos/train --effects xdog
    python benchmarks/bench_examples.py --images photos/train --effects xdog

This script imports torch before wise, so OpenMP's waiting policy is what the environment says:
``wise train`` (which imports wise first) runs with ``OMP_WAIT_POLICY=PASSIVE``; set it for a
run to measure what the command does.

Dead-leaves pictures (where the version has them) are all made before the timing starts: a
run makes them once, in its first minutes.
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import inspect
import time

import torch
from torch.utils.data import DataLoader

from wise.train.data import ExampleDataset, photo_files, read_photos
from wise.train.module import GlobalPPN
from wise.train.sampler import GlobalBatchSampler

EFFECTS = ("xdog", "cartoon", "watercolor", "oilpaint")


def measure(effect: str, photos: list[torch.Tensor], args: argparse.Namespace) -> tuple[float, float, float]:
    """(examples/s in all, examples/s of the data alone, examples/s of the steps alone)."""
    length = (args.steps + 1) * args.batch
    options = {"render_size": args.size, "window": args.window, "seed": 0}
    accepted = inspect.signature(ExampleDataset).parameters
    options.update({k: v for k, v in (("procedural", args.procedural), ("augmentation", True)) if k in accepted})
    dataset = ExampleDataset(photos, effect, args.size, length, **options)
    if hasattr(dataset, "_procedural") and args.procedural > 0:
        for number in range(getattr(__import__("wise.train.data", fromlist=["x"]), "PROCEDURAL_PICTURES")):
            dataset._procedural(number)
    torch.manual_seed(0)
    module = GlobalPPN(effect, args.architecture, "image-l1", 1e-3, args.size)
    optimizer = module.configure_optimizers()
    loader = iter(DataLoader(dataset, batch_sampler=GlobalBatchSampler(length, args.batch, 1, 0, 0)))
    data_seconds = step_seconds = 0.0
    for number in range(args.steps + 1):
        began = time.perf_counter()
        batch = next(loader)
        fetched = time.perf_counter()
        optimizer.zero_grad()
        module._losses(batch)[0].backward()
        optimizer.step()
        if number > 0:  # the first step warms up
            data_seconds += fetched - began
            step_seconds += time.perf_counter() - fetched
    examples = args.steps * args.batch
    return examples / (data_seconds + step_seconds), examples / data_seconds, examples / step_seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", required=True)
    parser.add_argument("--effects", nargs="+", default=list(EFFECTS))
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--window", type=int, default=64)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--procedural", type=float, default=0.25)
    parser.add_argument("--architecture", default="simple")
    args = parser.parse_args()
    photos, _ = read_photos(photo_files(args.images), args.size, round(args.size / 0.6))
    print(f"threads {torch.get_num_threads()}, window {args.window} of {args.size}, batch {args.batch}")
    for effect in args.effects:
        rates = measure(effect, photos, args)
        print(f"{effect}: {rates[0]:.1f} examples/s in all ({rates[1]:.1f} data, {rates[2]:.1f} steps)", flush=True)


if __name__ == "__main__":
    main()
