"""Argument types shared by every command: numbers are checked where they are parsed.

Each type is a callable for ``argparse``'s ``type=``; a bad value raises
``argparse.ArgumentTypeError``, which the parser turns into one ``wise: error:`` line naming
the option, and exit code 2. Limits that bound the work a command can be asked to do (the
largest working size, the most iterations) are named here and documented in the README.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Callable

from wise.threads import MAX_THREADS

MAX_SEED = 2**63 - 1
"""Largest seed: torch's generators take a signed 64-bit integer."""
MAX_WORKING_SIZE = 4096
"""Largest short side (pixels) that ``optimize``, ``transfer`` and ``bench recover`` work at."""
MAX_CELL_SIZE = 2048
"""Largest short side of a ``gallery`` cell."""
MIN_WORKING_SIZE = 16
MAX_ITERATIONS = 100_000
MAX_TRIALS = 10_000
MAX_KERNEL_SIZE = 32
"""Most filter samples per side for ``--kernel-size``; more only costs time."""
MAX_PIXEL_LIMIT = 10_000_000_000
"""Largest value ``--max-pixels`` accepts (10 gigapixels)."""


def _number(text: str, kind: Callable[[str], float | int], noun: str) -> float | int:
    try:
        return kind(text.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {noun}") from None


def finite_float(minimum: float | None = None, maximum: float | None = None, above: bool = False, below: bool = False):
    """A finite real number, at least ``minimum`` (above it when ``above``) and at most ``maximum``
    (below it when ``below``)."""

    def parse(text: str) -> float:
        value = float(_number(text, float, "a number"))
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if minimum is not None and (value <= minimum if above else value < minimum):
            relation = "above" if above else "at least"
            raise argparse.ArgumentTypeError(f"must be {relation} {minimum:g}, got {text}")
        if maximum is not None and (value >= maximum if below else value > maximum):
            relation = "below" if below else "at most"
            raise argparse.ArgumentTypeError(f"must be {relation} {maximum:g}, got {text}")
        return value

    return parse


@dataclass(frozen=True)
class WholeNumber:
    """An integer from ``minimum`` to ``maximum``; "1e3" and "2.0" are refused as not whole numbers."""

    minimum: int
    maximum: int

    def __call__(self, text: str) -> int:
        value = int(_number(text, int, "a whole number"))
        if not self.minimum <= value <= self.maximum:
            raise argparse.ArgumentTypeError(f"must be from {self.minimum:,} to {self.maximum:,}, got {text}")
        return value


whole_number = WholeNumber


positive_rate = finite_float(0.0, above=True)
"""A learning rate: finite and above 0."""
weight = finite_float(0.0)
"""A loss weight: finite and at least 0."""
seed = whole_number(0, MAX_SEED)
working_size = whole_number(MIN_WORKING_SIZE, MAX_WORKING_SIZE)
cell_size = whole_number(MIN_WORKING_SIZE, MAX_CELL_SIZE)
iterations = whole_number(1, MAX_ITERATIONS)
trials = whole_number(1, MAX_TRIALS)
kernel_size = whole_number(1, MAX_KERNEL_SIZE)
quality = whole_number(1, 100)
port = whole_number(1, 65535)
thread_count = whole_number(1, MAX_THREADS)
pixel_limit = whole_number(1, MAX_PIXEL_LIMIT)
training_seed = whole_number(0, 2**32 - 1)
"""A training run's seed (Lightning seeds every generator from a 32-bit value)."""
batch = whole_number(1, 4096)
examples = whole_number(1, 10_000_000)
processes = whole_number(1, 4096)
share = finite_float(0.0, 1.0)
open_share = finite_float(0.0, 1.0, above=True, below=True)
"""A share of two parts that both get something: above 0 and below 1."""
positive_seconds = finite_float(0.0, 3600.0, above=True)
