"""What a prediction network's error on each parameter costs in the look.

On the trials of ``wise bench ppn`` (the same seeded references), for each parameter:

- *gain if true*: the SSIM gained when the network's answer takes the true value of that
  parameter alone (negative where the network's other errors had compensated for it);
- *loss if only this wrong*: the SSIM lost when the true parameters take the network's value of
  that parameter alone.

    python benchmarks/ppn_parameter_costs.py cartoon --images photos/eval --trials 18 \
        [--model runs/cartoon/model.safetensors] [--json costs.json]
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import json
from pathlib import Path

import torch

from wise import effects, metrics
from wise.io import images_in, read_image
from wise.optimize.trials import content_at, random_reference
from wise.ppn.predictor import Predictor


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("effect")
    parser.add_argument("--images", required=True, help="folder of held-out photos")
    parser.add_argument("--trials", type=int, default=18)
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", default=None, help="model file (default: the built-in one)")
    parser.add_argument("--json", default=None, help="write the per-trial figures here")
    args = parser.parse_args()

    effect = effects.create(args.effect)
    predictor = Predictor(args.model, args.effect)
    photos = images_in(args.images)
    generator = torch.Generator().manual_seed(args.seed)
    names = effect.param_names
    gains, losses, networks, rows = torch.zeros(len(names)), torch.zeros(len(names)), [], []

    def ssim(content: torch.Tensor, example: torch.Tensor, params: torch.Tensor) -> float:
        with torch.no_grad():
            return metrics.ssim(effect(content, params).clamp(0.0, 1.0), example)

    for trial in range(args.trials):
        path = photos[trial % len(photos)]
        content = content_at(read_image(path), args.size)
        truth, example = random_reference(effect, content, generator)
        predicted = predictor(content, example)
        network = ssim(content, example, predicted)
        networks.append(network)
        row: dict = {"trial": trial, "image": path.name, "ssim": network, "params": {}}
        for index, name in enumerate(names):
            corrected, spoiled = predicted.clone(), truth.clone()
            corrected[0, index], spoiled[0, index] = truth[0, index], predicted[0, index]
            gain, loss = ssim(content, example, corrected) - network, 1.0 - ssim(content, example, spoiled)
            gains[index] += gain
            losses[index] += loss
            row["params"][name] = {"gain": gain, "loss": loss, "error": float(predicted[0, index] - truth[0, index])}
        rows.append(row)
        print(f"trial {trial} ({path.name}): network SSIM {network:.4f}", flush=True)

    print(f"\nmean network SSIM {sum(networks) / len(networks):.4f} over {args.trials} trials\n")
    print("| parameter | gain if true | loss if only this wrong |\n| --- | --- | --- |")
    for index, name in enumerate(names):
        print(f"| {name} | {gains[index] / args.trials:+.4f} | {losses[index] / args.trials:.4f} |")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
