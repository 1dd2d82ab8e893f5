"""Training throughput of global parameter prediction: examples per second.

Two figures per configuration, measured separately because training renders each example
once and reuses it in later epochs:

- rendering: examples made per second (a window of ``--window`` network pixels rendered as a
  tile of a ``--render-size`` picture, redraws of blank examples included);
- steps: examples per second through the network's forward and backward pass and the
  optimizer, with the loss (image-space losses render the effect twice more per example).

    python benchmarks/bench_training.py --images photos/ [--device cuda] [--markdown]
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import time

import torch

from wise import effects
from wise.train.data import ExampleDataset, photo_files, read_photos
from wise.train.module import GlobalPPN

EFFECTS = ("xdog", "cartoon", "watercolor", "oilpaint")
ARCHITECTURES = ("simple", "resnet", "multifeature")
LOSSES = ("param-l1", "image-l1")


def rendering_rate(photos: list[torch.Tensor], effect: str, args: argparse.Namespace) -> float:
    dataset = ExampleDataset(photos, effect, args.size, args.examples, render_size=args.render_size, window=args.window)
    dataset[0]
    began = time.perf_counter()
    for index in range(1, args.examples):
        dataset[index]
    return (args.examples - 1) / (time.perf_counter() - began)


def step_rate(effect: str, architecture: str, loss: str, args: argparse.Namespace) -> float:
    module = GlobalPPN(effect, architecture, loss, 1e-3, args.size).to(args.device)
    optimizer = module.configure_optimizers()
    count = len(effects.create(effect).param_specs)
    batch = {
        "photo": torch.rand(args.batch, 3, args.window, args.window, device=args.device),
        "example": torch.rand(args.batch, 3, args.window, args.window, device=args.device),
        "target": torch.rand(args.batch, 3, args.window, args.window, device=args.device),
        "params": torch.rand(args.batch, count, device=args.device) - 0.5,
    }

    def step() -> None:
        optimizer.zero_grad()
        module._losses(batch)[0].backward()
        optimizer.step()

    step()
    if args.device == "cuda":
        torch.cuda.synchronize()
    began = time.perf_counter()
    for _ in range(args.steps):
        step()
    if args.device == "cuda":
        torch.cuda.synchronize()
    return args.steps * args.batch / (time.perf_counter() - began)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", required=True)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--render-size", type=int, default=512)
    parser.add_argument("--window", type=int, default=64)
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--examples", type=int, default=33)
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--effects", nargs="+", default=list(EFFECTS))
    parser.add_argument("--architectures", nargs="+", default=list(ARCHITECTURES))
    args = parser.parse_args()
    photos, _ = read_photos(photo_files(args.images), args.size, round(args.render_size / 0.6))
    print(f"threads {torch.get_num_threads()}, device {args.device}, window {args.window} of {args.size}")
    print(
        "| effect | rendering (examples/s) | "
        + " | ".join(f"{a} {loss}" for a in args.architectures for loss in LOSSES)
    )
    print("| --- | --- |" + " --- |" * (len(args.architectures) * len(LOSSES)))
    for effect in args.effects:
        cells = [f"{rendering_rate(photos, effect, args):.1f}"]
        for architecture in args.architectures:
            for loss in LOSSES:
                cells.append(f"{step_rate(effect, architecture, loss, args):.1f}")
        print(f"| {effect} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
