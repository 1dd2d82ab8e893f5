"""Time and peak memory of ``wise apply`` at high resolution with masks made at 512².

Usage::

    python benchmarks/bench_highres.py IMAGE [--size 4096] [--effects ...]

For each effect, writes a parameter file with local masks at 512x512 (the first preset
plus a smooth variation), then runs ``wise apply`` on IMAGE resized to SIZE x SIZE in a
fresh process and reports its wall time and peak RSS.
"""

from __future__ import annotations

import wise  # before torch, as the command line: OpenMP waits without spinning

# isort: split
import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch
import torch.nn.functional as F

from wise.io import read_image, write_image
from wise.paramfile import save_params

MASK_SIZE = 512


def smooth_variation(channels: int, seed: int) -> torch.Tensor:
    coarse = torch.rand(1, channels, 8, 8, generator=torch.Generator().manual_seed(seed)) - 0.5
    return 0.3 * F.interpolate(coarse, size=(MASK_SIZE, MASK_SIZE), mode="bicubic", align_corners=False)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("image", type=Path)
    parser.add_argument("--size", type=int, default=4096)
    parser.add_argument("--effects", nargs="+", default=wise.effects.available())
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="wise-highres-"))
    source = work / "input.png"
    image = F.interpolate(read_image(args.image), size=(args.size, args.size), mode="bicubic", align_corners=False)
    write_image(image.clamp(0, 1), source)
    print("| effect | size | masks | time | peak RSS |")
    print("| --- | --- | --- | --- | --- |")
    for name in args.effects:
        effect = wise.effects.create(name)
        base = effect.preset(next(iter(effect.presets)))
        masks = (base[None, :, None, None] + smooth_variation(len(base), seed=1)).clamp(-0.5, 0.5)
        params_path = work / f"{name}.safetensors"
        save_params(params_path, effect, masks)
        command = [
            sys.executable,
            "-m",
            "wise",
            "apply",
            name,
            str(source),
            "--params",
            str(params_path),
            "-o",
            str(work / f"{name}.png"),
        ]
        start = time.perf_counter()
        child = subprocess.Popen(command)
        _, status, usage = os.wait4(child.pid, 0)
        seconds = time.perf_counter() - start
        if status != 0:
            raise SystemExit(f"wise apply {name} failed with status {status}")
        peak_gb = usage.ru_maxrss / 1024**2
        print(f"| {name} | {args.size}² | {MASK_SIZE}² | {seconds:.1f} s | {peak_gb:.2f} GB |", flush=True)


if __name__ == "__main__":
    main()
