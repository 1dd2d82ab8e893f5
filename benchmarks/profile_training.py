"""Where the time of one image-space training step goes, per effect and window size.

One step of ``wise train global`` with an image-space loss (``GlobalPPN._losses``, backward,
Adam) on a batch of random windows, and its parts timed on their own with the same batch:

- network: the prediction network's forward and backward (a parameter-space loss);
- truth render: the effect on the true parameters, without autograd (the loss's reference);
- effect forward / effect backward: the effect on the predicted parameters with autograd, and
  the backward from the loss to those parameters;
- optimizer: one Adam step;
- rest: the whole step minus those parts (Python, the loss, autograd bookkeeping);
- user / system: CPU seconds of the process per step (``getrusage``), over all threads.

Rendering the examples themselves (the data) is measured by ``bench_training.py``.

    python benchmarks/profile_training.py [--effects xdog ...] [--windows 64 128] [--batch 16]
"""

from __future__ import annotations

import argparse
import resource
import time
from typing import Callable

import torch

from wise import effects
from wise.train.losses import prediction_loss
from wise.train.module import GlobalPPN

EFFECTS = ("xdog", "cartoon", "watercolor", "oilpaint")
PARTS = ("network", "truth render", "effect forward", "effect backward", "optimizer")


def best_time(fn: Callable[[], None], repeat: int) -> float:
    fn()
    best = float("inf")
    for _ in range(repeat):
        began = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - began)
    return best


def profile(effect: str, window: int, args: argparse.Namespace) -> dict[str, float]:
    torch.manual_seed(0)
    module = GlobalPPN(effect, args.architecture, "image-l1", 1e-3, args.size)
    optimizer = module.configure_optimizers()
    count = len(effects.create(effect).param_specs)
    batch = {
        "photo": torch.rand(args.batch, 3, window, window),
        "example": torch.rand(args.batch, 3, window, window),
        "params": torch.rand(args.batch, count) - 0.5,
    }
    photo, truth = batch["photo"], batch["params"]

    def step() -> None:
        optimizer.zero_grad()
        module._losses(batch)[0].backward()
        optimizer.step()

    def network() -> None:
        optimizer.zero_grad()
        prediction_loss("param-l1", module.network(photo, batch["example"]), truth).backward()

    def truth_render() -> None:
        with torch.no_grad():
            module.effect(photo, truth, scale=module.scale)

    predicted = (torch.rand(args.batch, count) - 0.5).requires_grad_()

    def effect_forward() -> None:
        module.effect(photo, predicted, scale=module.scale)

    def effect_forward_backward() -> None:
        prediction_loss("image-l1", predicted, truth, module.effect, photo, batch["example"], module.scale).backward()

    usage = resource.getrusage(resource.RUSAGE_SELF)
    whole = best_time(step, args.repeat)
    after = resource.getrusage(resource.RUSAGE_SELF)
    runs = args.repeat + 1
    forward = best_time(effect_forward, args.repeat)
    parts = {
        "network": best_time(network, args.repeat),
        "truth render": best_time(truth_render, args.repeat),
        "effect forward": forward,
        "effect backward": best_time(effect_forward_backward, args.repeat) - forward,
        "optimizer": best_time(optimizer.step, args.repeat),
    }
    parts["rest"] = whole - sum(parts.values())
    parts["step"] = whole
    parts["user"] = (after.ru_utime - usage.ru_utime) / runs
    parts["system"] = (after.ru_stime - usage.ru_stime) / runs
    return parts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effects", nargs="+", default=list(EFFECTS))
    parser.add_argument("--windows", nargs="+", type=int, default=[64, 128])
    parser.add_argument("--size", type=int, default=512, help="short side of the pictures the windows are of")
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--architecture", default="simple")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(f"threads {torch.get_num_threads()}, batch {args.batch}, {args.architecture}, windows of {args.size}")
    columns = (*PARTS, "rest")
    print("| effect | window | step | examples/s | " + " | ".join(columns) + " | user | system |")
    print("| --- | --- | --- | --- |" + " --- |" * (len(columns) + 2))
    for effect in args.effects:
        for window in args.windows:
            parts = profile(effect, window, args)
            step = parts["step"]
            cells = [f"{parts[c] * 1000:.0f} ms ({100 * parts[c] / step:.0f} %)" for c in columns]
            cpu = [f"{parts['user']:.2f} s", f"{parts['system']:.2f} s"]
            head = [effect, str(window), f"{step * 1000:.0f} ms", f"{args.batch / step:.1f}"]
            print("| " + " | ".join(head + cells + cpu) + " |", flush=True)


if __name__ == "__main__":
    main()
