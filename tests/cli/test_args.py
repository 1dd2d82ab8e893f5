"""The shared argument types: finite numbers, ranges, whole numbers."""

from __future__ import annotations

import argparse

import pytest

from wise.cli import args


@pytest.mark.parametrize("text", ["inf", "-inf", "nan", "NaN", "1e999", "x", ""])
def test_finite_float_refuses(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError):
        args.finite_float()(text)


def test_finite_float_bounds() -> None:
    assert args.positive_rate("0.5") == 0.5
    with pytest.raises(argparse.ArgumentTypeError, match="above 0"):
        args.positive_rate("0")
    assert args.weight("0") == 0.0
    with pytest.raises(argparse.ArgumentTypeError, match="at least 0"):
        args.weight("-0.1")
    with pytest.raises(argparse.ArgumentTypeError, match="at most 2"):
        args.finite_float(0.0, 2.0)("3")


@pytest.mark.parametrize("text", ["1.5", "1e3", "two", "", "0x10"])
def test_whole_number_refuses_non_integers(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="not a whole number"):
        args.iterations(text)


def test_seed_range() -> None:
    assert args.seed(str(2**63 - 1)) == 2**63 - 1
    for text in (str(2**63), "-1", "1" + "0" * 30):
        with pytest.raises(argparse.ArgumentTypeError, match="from 0 to"):
            args.seed(text)


def test_sizes_have_a_documented_maximum() -> None:
    assert args.working_size(str(args.MAX_WORKING_SIZE)) == args.MAX_WORKING_SIZE
    with pytest.raises(argparse.ArgumentTypeError, match="4,096"):
        args.working_size(str(args.MAX_WORKING_SIZE + 1))
