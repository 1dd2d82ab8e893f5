"""Examples per second of one training step of each image-to-image variant (``wise train local
--post``), to plan a time budget: generator forward and backward (L1 + GAN), discriminator on
real and fake. Usage: ``python benchmarks/translation_step.py [--size 256] [--batch 2]
[--post-width 16] [--discriminator-width 16] [--steps 5]``."""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import time

import torch

from wise import effects
from wise.ppn.translation import build_translator, translator_options
from wise.train.discriminator import PatchDiscriminator, adversarial_loss

VARIANTS = {
    "CNN only (ResNet)": ("none", "local", "resnet"),
    "CNN only (U-Net)": ("none", "local", "unet"),
    "preset + XDoG + ResNet": ("xdog", "preset", "resnet"),
    "PPN + XDoG + ResNet": ("xdog", "local", "resnet"),
    "PPN + XDoG": ("xdog", "local", "none"),
}


def step_seconds(effect: str, ppn: str, post: str, args: argparse.Namespace) -> float:
    torch.manual_seed(0)
    start = effects.create("xdog").preset("portrait") if effect == "xdog" else None
    network = build_translator(effect, translator_options(ppn, post, args.post_width), start)
    discriminator = PatchDiscriminator(args.discriminator_width)
    photo = torch.rand(args.batch, 3, args.size, args.size)
    target = torch.rand(args.batch, 3, args.size, args.size)
    times = []
    for _ in range(args.steps + 1):
        began = time.perf_counter()
        made = network(photo)
        loss_d = adversarial_loss("vanilla", discriminator(photo, target), True) + adversarial_loss(
            "vanilla", discriminator(photo, made.detach()), False
        )
        loss_d.backward()
        loss_g = 100 * (made - target).abs().mean() + adversarial_loss("vanilla", discriminator(photo, made), True)
        loss_g.backward()
        times.append(time.perf_counter() - began)
    return sum(times[1:]) / args.steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--batch", type=int, default=2)
    parser.add_argument("--post-width", type=int, default=16)
    parser.add_argument("--discriminator-width", type=int, default=16)
    parser.add_argument("--steps", type=int, default=5)
    args = parser.parse_args()
    print(f"threads {torch.get_num_threads()}, {args.size} px, batch {args.batch}, CNN width {args.post_width}")
    for name, (effect, ppn, post) in VARIANTS.items():
        seconds = step_seconds(effect, ppn, post, args)
        print(f"{name:24s} {seconds:6.3f} s/step  {args.batch / seconds:6.2f} examples/s", flush=True)


if __name__ == "__main__":
    main()
