"""How often the closed-form reading gets a cartoon's bin count right.

Usage::

    python benchmarks/bench_bins.py PHOTOS_DIR [--trials 60] [--size 256] [--seed 0] [--json F]

Each trial takes the next photo of the folder (cycling; every third trial a generated dead-leaves
picture instead), draws random cartoon parameters as the functional benchmark does
(:func:`wise.optimize.trials.random_reference`), sets ``bins`` uniformly in [2, 16], renders the
example and reads the steps off it from the default parameters (the estimate alone, no descent:
:func:`wise.optimize.inversion.read_steps`). Prints each trial and the share of trials whose
bin count is within 0.25 of the truth, overall and by the true softness.

Whether a count can be read at all depends on the ramps: wide ones (high ``softness``) make the
quantizer nearly the identity, and every count renders almost the same picture. So each trial also
renders the truth with the count :data:`NEIGHBOUR` away (either side, the other parameters true):
where that render is within :data:`INDISTINCT_DB` of the example, the count does not show, and
the share is reported separately for the trials where it does. ``read dB`` is the render with the
count read (the other parameters true) against the example: how much a wrong count costs the look.
"""

from __future__ import annotations

import wise  # noqa: F401  (before torch, as the command line: OpenMP waits without spinning)

# isort: split
import argparse
import json
import time
from pathlib import Path

import torch

from wise import effects
from wise.effects.base import Effect
from wise.io import images_in, read_image
from wise.metrics import psnr
from wise.optimize.inversion import read_steps
from wise.optimize.trials import content_at
from wise.train.procedural import dead_leaves

TOLERANCE = 0.25
NEIGHBOUR = 0.3
INDISTINCT_DB = 40.0
"""PSNR above which two renders count as the same picture (an RMS difference under 1 %)."""


def render_psnr(
    effect: Effect, content: torch.Tensor, truth: torch.Tensor, example: torch.Tensor, bins: float
) -> float:
    """PSNR of the example against the truth rendered with ``bins`` (clamped to the parameter's range)."""
    spec = effect.spec("bins")
    params = truth.clone()
    params[0, effect.param_names.index("bins")] = spec.to_normalized(min(max(bins, spec.min), spec.max))
    with torch.no_grad():
        return min(psnr(effect(content, params), example), 99.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("photos", help="folder of photos")
    parser.add_argument("--trials", type=int, default=60)
    parser.add_argument("--size", type=int, default=256, help="short side of the examples (default 256)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--others",
        choices=("random", "default"),
        default="random",
        help="the other parameters: drawn at random (default) or at their defaults; softness is drawn either way",
    )
    parser.add_argument("--json", type=Path, help="write the trials as JSON")
    args = parser.parse_args()

    effect = effects.create("cartoon").eval()
    photos = images_in(args.photos)
    generator = torch.Generator().manual_seed(args.seed)
    index = effect.param_names.index("bins")
    spec = effect.spec("bins")
    rows = []
    print("| trial | picture | true bins | softness | read bins | clear | within 0.25 | neighbour dB | read dB |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for trial in range(args.trials):
        if trial % 3 == 2:
            name, content = "dead leaves", dead_leaves(args.size, generator)
        else:
            photo = photos[(trial - trial // 3) % len(photos)]
            name, content = photo.stem[:24], content_at(read_image(photo), args.size)
        truth = torch.rand(1, len(effect.param_specs), generator=generator) - 0.5
        if args.others == "default":
            softness = truth[0, effect.param_names.index("softness")].clone()
            truth = effect.default_params().reshape(1, -1).clone()
            truth[0, effect.param_names.index("softness")] = softness
        bins = 2.0 + 14.0 * float(torch.rand(1, generator=generator))
        truth[0, index] = spec.to_normalized(bins)
        with torch.no_grad():
            example = effect(content, truth)
        start = time.perf_counter()
        found, held = read_steps(effect, content, example, effect.default_params().reshape(1, -1))
        seconds = time.perf_counter() - start
        real = effect.params_to_dict(found[0])
        softness = effect.params_to_dict(truth[0])["softness"]
        hit = abs(real["bins"] - bins) <= TOLERANCE
        neighbour = max(render_psnr(effect, content, truth, example, bins + d) for d in (-NEIGHBOUR, NEIGHBOUR))
        read = render_psnr(effect, content, truth, example, real["bins"])
        rows.append(
            {
                "picture": name,
                "bins": bins,
                "softness": softness,
                "read": real["bins"],
                "clear": bool(held),
                "hit": hit,
                "neighbour_db": neighbour,
                "read_db": read,
            }
        )
        print(
            f"| {trial} | {name} | {bins:.2f} | {softness:.2f} | {real['bins']:.2f} | {bool(held)} | {hit} |"
            f" {neighbour:.1f} | {read:.1f} |  ({seconds:.1f} s)",
            flush=True,
        )
    share = sum(r["hit"] for r in rows) / len(rows)
    print(f"\nwithin {TOLERANCE} of the true bin count: {share:.1%} of {len(rows)} trials")
    for low, high in ((0.0, 0.25), (0.25, 0.5), (0.5, 0.75), (0.75, 1.01)):
        group = [r for r in rows if low <= r["softness"] < high]
        if group:
            hits = sum(r["hit"] for r in group) / len(group)
            print(f"  softness {low:.2f}–{min(high, 1.0):.2f}: {hits:.1%} of {len(group)}")
    shown = [r for r in rows if r["neighbour_db"] < INDISTINCT_DB]
    if shown:
        hits = sum(r["hit"] for r in shown) / len(shown)
        print(
            f"where the count shows (a count {NEIGHBOUR} away renders under {INDISTINCT_DB:.0f} dB): "
            f"{hits:.1%} of {len(shown)} trials"
        )
    costly = [r for r in rows if not r["hit"] and r["read_db"] < INDISTINCT_DB]
    print(f"counts read wrongly that change the look (read dB under {INDISTINCT_DB:.0f}): {len(costly)} of {len(rows)}")
    if args.json:
        args.json.write_text(json.dumps({"share": share, "trials": rows}, indent=1))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
