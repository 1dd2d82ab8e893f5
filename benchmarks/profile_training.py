"""Where the time of one training step goes, per effect and window size, and where the time
of one effect forward and backward goes, by kind of operation.

One step of ``wise train global`` with an image-space loss (``GlobalPPN._losses``, backward,
Adam) on a batch of random windows, and its parts timed on their own with the same batch:

- data: rendering the batch's examples without autograd, as the data set does (redraws of
  blank examples not counted; ``bench_examples.py`` measures the data set itself);
- network: the prediction network's forward and backward (a parameter-space loss, whose
  step is this and the optimizer);
- effect forward / effect backward: the effect on the predicted parameters with autograd, and
  the backward from the loss to those parameters;
- optimizer: one Adam step;
- rest: the step minus those parts (Python, the loss, autograd bookkeeping);
- user / system: CPU seconds of the process per step (``getrusage``), over all threads.

``--whole 256 1024`` also profiles the effect's forward and backward on one picture of each
size with the PyTorch profiler and groups the operators' own CPU time: sampling
(``grid_sampler_2d`` and its backward), pointwise arithmetic, exponentials and other
transcendental functions, convolutions, reductions, copies and allocation, custom backward
bodies (Python), and the rest.

    python benchmarks/profile_training.py [--effects xdog ...] [--windows 64 128] [--batch 16] [--whole 256 1024]
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import resource
import time
from typing import Callable

import torch

from wise import effects
from wise.train.losses import prediction_loss
from wise.train.module import GlobalPPN

EFFECTS = ("xdog", "cartoon", "watercolor", "oilpaint")
PARTS = ("data", "network", "effect forward", "effect backward", "optimizer")
KINDS = {
    "sampling": ("grid_sampler",),
    "pointwise": ("mul", "add", "sub", "div", "addcmul", "where", "neg", "rsub", "clamp", "maximum", "minimum",
                  "abs", "sign", "lerp", "square", "pow", "sqrt", "rsqrt", "reciprocal", "hypot", "fill_", "zero_",
                  "threshold", "relu", "gt", "lt", "ge", "le", "eq", "ne", "floor", "round", "ceil", "frac"),
    "transcendental": ("exp", "tanh", "log", "sin", "cos", "atan2", "softplus", "sigmoid", "erf"),
    "convolution": ("conv", "mkldnn", "linear", "addmm", "mm", "bmm", "pool"),
    "reduction": ("sum", "mean", "max", "min", "amax", "amin", "std", "var", "norm", "argmax"),
    "copies and allocation": ("copy_", "to_copy", "_to_copy", "empty", "zeros", "ones", "cat", "stack", "pad",
                              "contiguous", "clone", "expand", "narrow", "slice", "select", "view", "reshape",
                              "permute", "flip", "index", "gather", "scatter", "replication", "constant_pad"),
}  # fmt: skip
"""Operator kinds by the words in their names (the first kind that matches takes an operator)."""


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
    batch["target"] = batch["example"]
    photo, truth = batch["photo"], batch["params"]

    def step() -> None:
        optimizer.zero_grad()
        module._losses(batch)[0].backward()
        optimizer.step()

    def network() -> None:
        optimizer.zero_grad()
        prediction_loss("param-l1", module.network(photo, batch["example"]), truth).backward()

    def data() -> None:
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
        "data": best_time(data, args.repeat),
        "effect forward": forward,
        "effect backward": best_time(effect_forward_backward, args.repeat) - forward,
        "optimizer": best_time(optimizer.step, args.repeat),
    }
    parts["rest"] = whole - sum(value for key, value in parts.items() if key != "data")
    parts["step"] = whole
    parts["user"] = (after.ru_utime - usage.ru_utime) / runs
    parts["system"] = (after.ru_stime - usage.ru_stime) / runs
    return parts


def kind_of(name: str) -> str:
    operator = name.removeprefix("aten::")
    if not name.startswith("aten::"):
        return "custom backward bodies" if "Backward" in name else "other"
    for kind, words in KINDS.items():
        if any(operator == word or operator.startswith(word) for word in words):
            return kind
    return "other"


def profile_whole(effect_name: str, side: int) -> tuple[float, dict[str, float]]:
    """Seconds of one forward and backward at ``side``², and the operators' own CPU seconds by kind."""
    effect = effects.create(effect_name).requires_grad_(False)
    torch.manual_seed(0)
    image = torch.rand(1, 3, side, side)
    params = (torch.rand(1, len(effect.param_specs)) - 0.5).requires_grad_()

    def run() -> None:
        params.grad = None
        effect(image, params).mean().backward()

    run()
    began = time.perf_counter()
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as profiler:
        run()
    seconds = time.perf_counter() - began
    kinds: dict[str, float] = {}
    for event in profiler.key_averages():
        kind = kind_of(event.key)
        kinds[kind] = kinds.get(kind, 0.0) + event.self_cpu_time_total / 1e6
    return seconds, kinds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effects", nargs="+", default=list(EFFECTS))
    parser.add_argument("--windows", nargs="+", type=int, default=[64, 128])
    parser.add_argument("--size", type=int, default=512, help="short side of the pictures the windows are of")
    parser.add_argument("--batch", type=int, default=16)
    parser.add_argument("--architecture", default="simple")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--whole", nargs="*", type=int, default=[], help="also profile whole pictures of these sides")
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
    if args.whole:
        names = (*KINDS, "custom backward bodies", "other")
        print("\n| effect | picture | forward + backward (profiled) | " + " | ".join(names) + " |")
        print("| --- | --- | --- |" + " --- |" * len(names))
        for effect in args.effects:
            for side in args.whole:
                seconds, kinds = profile_whole(effect, side)
                total = sum(kinds.values())
                cells = [f"{100 * kinds.get(name, 0.0) / total:.0f} %" for name in names]
                print(f"| {effect} | {side}² | {seconds:.2f} s | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
