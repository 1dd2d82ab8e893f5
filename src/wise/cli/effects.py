"""``wise effects``: every effect, its parameters (range, default) and presets."""

from __future__ import annotations

import argparse
from typing import TextIO

from wise.cli.parser import top_command
from wise.effects.catalogue import NAMES, Entry, check_name, entry

OUTSIDE_NOTE = "outside the declared range; rendered as authored"


def fmt(value: float) -> str:
    return f"{value:.6g}"


def effect_table(effect: Entry) -> list[str]:
    """The lines ``wise effects NAME`` prints for ``effect``."""
    lines = [f"{effect.name}: {effect.summary}" if effect.summary else effect.name, "  parameters:"]
    rows = [
        (s.name, f"[{fmt(s.min)}, {fmt(s.max)}]", f"default {fmt(s.default)}", s.description)
        for s in effect.param_specs
    ]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    for row in rows:
        cells = [row[i].ljust(widths[i]) for i in range(3)]
        lines.append(("    " + "  ".join(cells) + "  " + row[3]).rstrip())
    outside = False
    if effect.presets:
        lines.append("  presets:")
        width = max(len(n) for n in effect.presets)
        for name, preset in effect.presets.items():
            values = []
            for spec in effect.param_specs:
                value = float(preset.get(spec.name, spec.default))
                mark = "" if spec.in_range(value) else "*"
                outside = outside or bool(mark)
                values.append(f"{spec.name}={fmt(value)}{mark}")
            lines.append(f"    {name.ljust(width)}  {' '.join(values)}")
    if outside:
        lines.append(f"  * {OUTSIDE_NOTE}")
    return lines


def _readme_number(value: float) -> str:
    return fmt(value).replace("-", "\N{MINUS SIGN}")


def markdown_table(effect: Entry) -> str:
    """The parameter table of ``effect`` as the README shows it (``wise effects --markdown``)."""
    lines = ["| parameter | range | default | controls |", "| --- | --- | --- | --- |"]
    for s in effect.param_specs:
        span = f"{_readme_number(s.min)} \N{HORIZONTAL ELLIPSIS} {_readme_number(s.max)}"
        lines.append(f"| {s.name} | {span} | {_readme_number(s.default)} | {s.description} |")
    return "\n".join(lines)


def run(args: argparse.Namespace, out: TextIO) -> int:
    if args.effect:
        check_name(args.effect)
    names = [args.effect] if args.effect else NAMES
    if args.markdown:
        blocks = [f"`{name}`\n\n{markdown_table(entry(name))}" for name in names]
    else:
        blocks = ["\n".join(effect_table(entry(name))) for name in names]
    print("\n\n".join(blocks), file=out)
    return 0


def register(commands: argparse._SubParsersAction) -> None:
    show = top_command(commands, "effects")
    show.add_argument("effect", nargs="?", metavar="EFFECT", help="show this effect only")
    show.add_argument("--markdown", action="store_true", help="parameter tables in Markdown (as in the README)")
    show.set_defaults(func=run)
