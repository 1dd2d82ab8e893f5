"""Per-parameter recovery of the functional benchmark: how far each parameter ended from the truth.

Usage::

    python benchmarks/recovery_table.py BEFORE.json [AFTER.json ...]

Reads the JSON files ``wise bench recover ... --json`` writes and prints a Markdown table: for
each parameter, the mean absolute difference between the found and the true value as a share of
the parameter's range (0: found exactly, about 0.33: no better than a guess), one column per
file. Which parameters the gradient cannot find shows as the rows that stay high.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from wise import effects


def errors(path: Path) -> tuple[str, dict[str, float]]:
    results = json.loads(path.read_text())
    effect = effects.create(results["effect"])
    trials = results["trials"]
    table = {}
    for spec in effect.param_specs:
        gaps = [abs(t["found_params"][spec.name] - t["true_params"][spec.name]) / spec.span for t in trials]
        table[spec.name] = sum(gaps) / len(gaps)
    return results["effect"], table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("results", nargs="+", type=Path, help="JSON files of wise bench recover")
    args = parser.parse_args()
    columns = [errors(path) for path in args.results]
    if len({effect for effect, _ in columns}) > 1:
        parser.error("the files are of different effects: give the files of one effect")
    names = list(columns[0][1])
    print("| parameter | " + " | ".join(f"{path.name}" for path in args.results) + " |")
    print("| --- |" + " --- |" * len(columns))
    for name in names:
        cells = [f"{table[name]:.3f}" if name in table else "—" for _, table in columns]
        print(f"| {name} | " + " | ".join(cells) + " |")
    means = []
    for path in args.results:
        results = json.loads(path.read_text())
        means.append(f"{results['mean_ssim']:.4f} / {results['mean_psnr']:.2f} dB")
    print("| mean SSIM / PSNR | " + " | ".join(means) + " |")


if __name__ == "__main__":
    main()
