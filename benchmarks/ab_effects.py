"""A/B timing of the effects against an earlier commit, in one run on one machine.

Usage::

    python benchmarks/ab_effects.py --base de68e06 [--effects ...] [--cases 256x8 1024x1] [--rounds 2]

Checks the base commit out into a temporary worktree and times each case (forward+backward
with global parameters, ``bench_effects.py``'s ``run_case``) in a fresh process per case with
``PYTHONPATH`` pointing at the base's or this checkout's sources, alternating the two for
``--rounds`` rounds. Reports the best time and the largest peak RSS of each side and the
ratios (machines differ up to 3x in speed, so only the ratio in one run counts).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


def run(sources: Path, case: dict, env_extra: dict[str, str]) -> dict:
    env = {**os.environ, "PYTHONPATH": str(sources), **env_extra}
    out = subprocess.run(
        [sys.executable, str(HERE / "bench_effects.py"), "--case", json.dumps(case)],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", required=True, help="the commit to compare with")
    parser.add_argument("--effects", nargs="+", default=["xdog", "cartoon", "watercolor", "oilpaint"])
    parser.add_argument("--cases", nargs="+", default=["256x8", "1024x1"], help="SIZExBATCH")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--local", action="store_true", help="per-pixel masks instead of global values")
    parser.add_argument(
        "--mode", default="forward+backward", choices=["forward+backward", "forward", "render"], help="what is timed"
    )
    args = parser.parse_args()

    with tempfile.TemporaryDirectory(prefix="wise-ab-") as folder:
        base_tree = Path(folder) / "base"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(base_tree), args.base], check=True)
        try:
            sides = {"base": base_tree / "src", "this": ROOT / "src"}
            results: dict[tuple[str, str, str], list[dict]] = {}
            for _ in range(args.rounds):
                for effect in args.effects:
                    for spec in args.cases:
                        size, batch = (int(v) for v in spec.split("x"))
                        case = dict(
                            effect_name=effect,
                            size=size,
                            mode=args.mode,
                            local=args.local,
                            repeat=args.repeat,
                            kernel_size=3,
                            checkpoint=False,
                            batch=batch,
                        )
                        for side, sources in sides.items():
                            row = run(sources, case, {})
                            results.setdefault((effect, spec, side), []).append(row)
                            print(json.dumps({"side": side, **row}), file=sys.stderr, flush=True)
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base_tree)], check=False)

    print(f"{args.mode}:")
    print(f"| effect | size x batch | base ({args.base}) | this | speed-up | memory |")
    print("| --- | --- | --- | --- | --- | --- |")
    for effect in args.effects:
        for spec in args.cases:
            base_rows, this_rows = results[(effect, spec, "base")], results[(effect, spec, "this")]
            base_time = min(r["seconds"] for r in base_rows)
            this_time = min(r["seconds"] for r in this_rows)
            base_rss = max(r["peak_rss_gb"] for r in base_rows)
            this_rss = max(r["peak_rss_gb"] for r in this_rows)
            print(
                f"| {effect} | {spec.replace('x', '² x ')} | {base_time:.3f} s, {base_rss:.2f} GB | "
                f"{this_time:.3f} s, {this_rss:.2f} GB | ×{base_time / this_time:.2f} | ×{this_rss / base_rss:.2f} |"
            )


if __name__ == "__main__":
    main()
