"""Gradients of the image loss far from the truth, with the look's steps sharp and smoothed.

For each effect and parameter listed, seeded photos (``skimage.data`` astronaut, chelsea and
coffee at ``--size``) render a target with the parameter at ``--truth`` (normalized, the
others at the defaults); the parameter then starts at each of ``--starts`` and the L1 loss's
gradient with respect to it is taken at every step temperature of ``--temperatures``
(:func:`wise.filters.smoothing.smoothed_steps`). Printed: mean loss and mean gradient over
the photos; a negative gradient points the descent up towards a larger truth, a positive one
down towards a smaller truth.

    python benchmarks/bench_smoothing.py [--size 256]
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse

import torch
import torch.nn.functional as F
from skimage import data

from wise import effects
from wise.filters.smoothing import smoothed_steps

CASES = (("xdog", "blackness"), ("cartoon", "blackness"), ("cartoon", "bins"))


def photos(size: int) -> list[torch.Tensor]:
    pictures = []
    for name in ("astronaut", "chelsea", "coffee"):
        photo = torch.from_numpy(getattr(data, name)()).permute(2, 0, 1)[None].float() / 255.0
        factor = size / min(photo.shape[-2:])
        shape = (round(photo.shape[-2] * factor), round(photo.shape[-1] * factor))
        pictures.append(F.interpolate(photo, size=shape, mode="area"))
    return pictures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--truth", type=float, default=0.3)
    parser.add_argument("--starts", type=float, nargs="+", default=[-0.45, 0.45])
    parser.add_argument("--temperatures", type=float, nargs="+", default=[0.0, 0.25, 0.5, 1.0])
    args = parser.parse_args()
    pictures = photos(args.size)
    print("| effect | parameter | start | truth | " + " | ".join(f"T={t:g}" for t in args.temperatures) + " |")
    print("| --- | --- | --- | --- |" + " --- |" * len(args.temperatures))
    for name, parameter in CASES:
        effect = effects.create(name)
        index = effect.param_names.index(parameter)
        truth = effect.default_params().reshape(1, -1).clone()
        truth[0, index] = args.truth
        with torch.no_grad():
            targets = [effect(photo, truth) for photo in pictures]
        for start in args.starts:
            if (start - args.truth) * (start - args.truth) < 1e-6:
                continue
            cells = []
            for temperature in args.temperatures:
                losses, gradients = [], []
                for photo, target in zip(pictures, targets):
                    params = truth.clone()
                    params[0, index] = start
                    params.requires_grad_()
                    with smoothed_steps(temperature):
                        loss = (effect(photo, params) - target).abs().mean()
                    loss.backward()
                    assert params.grad is not None
                    losses.append(float(loss.detach()))
                    gradients.append(float(params.grad[0, index]))
                mean_gradient = sum(gradients) / len(gradients)
                cells.append(f"{mean_gradient:+.3f} (loss {sum(losses) / len(losses):.3f})")
            head = f"| {name} | {parameter} | {start:+.2f} | {args.truth:+.2f} | "
            print(head + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
