"""Time and peak memory of the effects, forward and forward+backward.

Each case runs in a fresh process so that its peak RSS is its own. Usage::

    python benchmarks/bench_effects.py                    # xdog at 512 and 1024
    python benchmarks/bench_effects.py --sizes 1024 --effects xdog --repeat 3 --markdown

The image is ``skimage.data.astronaut()`` resized to a square; parameters are the
effect's defaults, global ``(B, P)`` or as local masks ``(B, P, 64, 64)``.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time


def run_case(
    effect_name: str,
    size: int,
    mode: str,
    local: bool,
    repeat: int,
    kernel_size: int,
    checkpoint: bool,
    batch: int = 1,
) -> dict:
    import torch
    import torch.nn.functional as F
    from skimage import data

    import wise
    import wise.render

    torch.manual_seed(0)
    photo = torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255.0
    image = F.interpolate(photo, size=(size, size), mode="bilinear", align_corners=False)
    image = image.expand(batch, -1, -1, -1).contiguous()
    effect = wise.effects.create(effect_name, kernel_size=kernel_size, checkpoint=checkpoint)
    base = effect.default_params()[None].expand(batch, -1)
    params = base[:, :, None, None].expand(-1, -1, 64, 64).clone() if local else base.clone()

    def once() -> None:
        if mode == "forward":
            with torch.no_grad():
                effect(image, params)
        elif mode == "render":  # the path of `wise apply`, video and the editor
            wise.render.render(effect, image, params)
        else:
            p = params.clone().requires_grad_()
            out = effect(image, p)
            out.mean().backward()

    once()  # warm-up
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        once()
        times.append(time.perf_counter() - start)
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {
        "effect": effect_name,
        "size": size,
        "batch": batch,
        "mode": mode,
        "params": "local" if local else "global",
        "seconds": min(times),
        "peak_rss_gb": peak_kb / 1024**2,
        "threads": torch.get_num_threads(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--effects", nargs="+", default=["xdog"])
    parser.add_argument("--sizes", nargs="+", type=int, default=[512, 1024])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--batch", type=int, default=1, help="pictures per call (the same photo repeated)")
    parser.add_argument("--kernel-size", type=int, default=3)
    parser.add_argument("--checkpoint", action="store_true")
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table")
    parser.add_argument("--case", help=argparse.SUPPRESS)
    args = parser.parse_args()

    if args.case:
        print(json.dumps(run_case(**json.loads(args.case))))
        return

    rows = []
    for effect_name in args.effects:
        for size in args.sizes:
            for mode, local in (("forward", False), ("forward+backward", False), ("forward+backward", True)):
                case = dict(
                    effect_name=effect_name,
                    size=size,
                    mode=mode,
                    local=local,
                    repeat=args.repeat,
                    kernel_size=args.kernel_size,
                    checkpoint=args.checkpoint,
                    batch=args.batch,
                )
                out = subprocess.run(
                    [sys.executable, __file__, "--case", json.dumps(case)], capture_output=True, text=True, check=True
                )
                row = json.loads(out.stdout.strip().splitlines()[-1])
                rows.append(row)
                if not args.markdown:
                    print(json.dumps(row), flush=True)
    if args.markdown:
        print("| effect | size | pass | parameters | time | peak RSS |")
        print("| --- | --- | --- | --- | --- | --- |")
        for r in rows:
            cells = [r["effect"], f"{r['size']}²", r["mode"], r["params"], f"{r['seconds']:.2f} s"]
            print("| " + " | ".join(cells + [f"{r['peak_rss_gb']:.2f} GB"]) + " |")


if __name__ == "__main__":
    main()
